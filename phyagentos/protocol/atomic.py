"""Crash-safe file replacement.

A reader of a protocol file sees either the old content or the new one, never a
torn write: the data goes to a temporary file in the same directory (so
``os.replace`` is an atomic rename on one filesystem), is fsynced, renamed over
the target, and the directory is fsynced so the rename itself survives a crash.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write_bytes", "atomic_write_text"]

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
