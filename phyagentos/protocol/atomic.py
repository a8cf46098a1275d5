"""Crash-safe file replacement.

A reader of a protocol file sees either the old content or the new one, never a
torn write: the data goes to a temporary file in the same directory (so
``os.replace`` is an atomic rename on one filesystem), is fsynced, renamed over
the target, and the directory is fsynced so the rename itself survives a crash.

Each fsync costs a journal commit (about 10 ms on the shared VM this project is
measured on). A producer that writes several files before announcing them (the
runner writes a whole evidence bundle before it reports ``done``) wraps the writes in
:func:`batched_durability`: every rename still happens at once (readers and a
process that crashes see exactly what they would have seen), but the fsyncs of the
files and their directories happen together when the block ends, concurrently, so
the filesystem commits them as one group. Nothing written inside the block may be
announced as durable before the block has ended.
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Iterator, Sequence

__all__ = ["append_lines_durably", "atomic_write_bytes", "atomic_write_text", "batched_durability", "file_identity", "fsync_paths"]

log = logging.getLogger(__name__)


def _default_mode() -> int:
    # mkstemp creates 0600 files; new protocol files should get the usual
    # 0666 & ~umask instead. Reading the umask means setting it, so do it once.
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


_DEFAULT_MODE = _default_mode()


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # e.g. Windows cannot open directories; the rename is still atomic
        return
    try:
        os.fsync(fd)
    except OSError:  # some filesystems refuse fsync on directories
        log.debug("fsync of directory %s not supported", directory)
    finally:
        os.close(fd)


_BATCH = threading.local()
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _fsync_path(path: str) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:  # replaced or removed since: its successor was synced (or is gone)
        return
    try:
        os.fsync(fd)
    except OSError as exc:
        if os.path.isdir(path):  # some filesystems refuse fsync on directories
            log.debug("fsync of directory %s not supported: %s", path, exc)
            return
        raise
    finally:
        os.close(fd)


def fsync_paths(files: Sequence[str], directories: Sequence[str] = ()) -> None:
    """fsync ``files``, then ``directories``, each group concurrently (one journal commit
    instead of one per file on ext4/xfs). Missing files are skipped.

    Raises:
        OSError: an fsync failed (e.g. an I/O error).
    """
    global _POOL
    for group in (list(dict.fromkeys(files)), list(dict.fromkeys(directories))):
        if len(group) <= 1:
            for p in group:
                _fsync_path(p)
            continue
        with _POOL_LOCK:
            if _POOL is None:
                _POOL = ThreadPoolExecutor(max_workers=8, thread_name_prefix="fsync")
        for future in [_POOL.submit(_fsync_path, p) for p in group]:
            future.result()


@contextlib.contextmanager
def batched_durability() -> Iterator[None]:
    """Defer the fsyncs of this thread's durable atomic writes to the end of the block.

    On exit (also on an exception) every file written durably inside the block, and
    its directory, is fsynced once (:func:`fsync_paths`). Nested blocks join the
    outermost one. Raises OSError on exit if an fsync failed.
    """
    if getattr(_BATCH, "files", None) is not None:
        yield
        return
    _BATCH.files = {}
    try:
        yield
    finally:
        files, _BATCH.files = _BATCH.files, None
        fsync_paths(list(files), sorted({os.path.dirname(f) for f in files}))


def file_identity(path: str | os.PathLike[str]) -> tuple[int, int, int] | None:
    """``(inode, modification time in ns, size in bytes)`` of the file at ``path``, or
    ``None`` if there is none. Every atomic write replaces a file by a new inode, so an
    equal identity means the content a reader parsed from it is still the file's (what
    the caches of parsed protocol files, evidence bundles and signals are keyed by).

    Raises:
        OSError: the file exists but cannot be examined (e.g. permissions).
    """
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes, *, durable: bool = True) -> None:
    """Replace the file at ``path`` with ``data`` atomically and durably.

    The parent directory must exist. An existing file keeps its permission bits;
    a new one gets ``0666 & ~umask``. On any failure the temporary file is
    removed and the original file (if any) is left untouched.

    ``durable=False`` skips both fsyncs: readers still never see a torn file, but
    after a power cut the file may be the previous version. Only for views that
    are regenerated from a source of truth (e.g. SESSIONS.md).

    Raises:
        OSError: the directory is missing or not writable, or the disk is full.
        TypeError: ``data`` is not bytes-like.
    """
    target = Path(path)
    directory = target.parent
    batch = getattr(_BATCH, "files", None) if durable else None
    if batch is not None:
        batch[os.path.abspath(target)] = None
        durable = False  # synced when the batch ends
    try:
        mode = target.stat().st_mode & 0o7777
    except FileNotFoundError:
        mode = _DEFAULT_MODE
    fd, tmp_name = tempfile.mkstemp(dir=directory, prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            if durable:
                os.fsync(handle.fileno())
        os.chmod(tmp_name, mode)
        os.replace(tmp_name, target)
    except BaseException:
        try:
            os.unlink(tmp_name)
        except FileNotFoundError:
            pass
        raise
    if durable:
        _fsync_dir(directory)


def atomic_write_text(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8",
                      durable: bool = True) -> None:
    """Replace the file at ``path`` with ``text`` atomically (see :func:`atomic_write_bytes`).

    The text is written exactly as given: no newline translation, so a document
    read with ``newline=""`` and written back is byte-for-byte identical.

    Raises:
        OSError: as for :func:`atomic_write_bytes`.
        UnicodeEncodeError: ``text`` cannot be encoded (e.g. lone surrogates in UTF-8).
    """
    atomic_write_bytes(path, text.encode(encoding), durable=durable)


def append_lines_durably(path: str | os.PathLike[str], lines: Sequence[str]) -> None:
    """Append ``lines`` (each ending in a newline) to the text file ``path`` (created if
    needed, parent folders too) and fsync it before returning: the archives' append-only
    writes (JSON lines per month), which are never rewritten in place."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    with open(target, "a", encoding="utf-8", newline="") as handle:
        handle.writelines(lines)
        handle.flush()
        os.fsync(handle.fileno())
