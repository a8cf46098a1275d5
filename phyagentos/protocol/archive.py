"""The session archive: terminal sessions leave ``sessions/`` so the active set stays small.

Layout::

    sessions/archive/YYYY-MM-DD/<id>.md     the session file, moved unchanged (UTC day it ended)
    sessions/archive/runs/<run>.log         one line per archived session of a run:
                                            "<YYYY-MM-DD>/<id> TAB <state> TAB <node>"

A session is archived by renaming its file (atomic; the content was already written
in ``sessions/<id>.md``), after its catalogue line is appended and fsynced. So at
every instant the session's latest content is in exactly one of the two places, and
a catalogue line may name a file that has not moved yet (readers look in both).
Each catalogue line is written with one ``write`` on an ``O_APPEND`` descriptor and
starts with a newline, so concurrent appenders never interleave and a line torn by a
power cut cannot swallow the next one; malformed lines are skipped.

Finding an archived session by id alone costs one ``stat`` per archived *day*; ids
found once are cached. Listing a run's sessions reads that run's catalogue only, and
a :class:`SessionArchive` that read it before reads only the bytes appended since.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from .atomic import _fsync_dir
from .schemas import SESSION_ID_PATTERN, TERMINAL_STATES

__all__ = ["SessionArchive", "ArchivedEntry"]

log = logging.getLogger(__name__)

_DAY = re.compile(r"^\d{4}-\d{2}-\d{2}$")
_SID = re.compile(SESSION_ID_PATTERN)
_TERMINAL = frozenset(TERMINAL_STATES)


@dataclass(frozen=True)
class ArchivedEntry:
    """One catalogue line: where an archived session lives and how it ended."""

    session_id: str
    state: str
    node: str
    relpath: str  # "<YYYY-MM-DD>/<id>.md" relative to sessions/archive/


def _read_all(fd: int) -> bytes:
    chunks = []
    while chunk := os.read(fd, 1 << 16):
        chunks.append(chunk)
    return b"".join(chunks)


def _parse_line(line: bytes, entries: dict[str, ArchivedEntry]) -> None:
    """Add one catalogue line to ``entries`` (a malformed or torn line adds nothing)."""
    try:
        parts = line.decode("utf-8").split("\t")
    except UnicodeDecodeError:
        return
    if len(parts) != 3:
        return
    rel, state, node = parts
    day, _, name = rel.partition("/")
    if not _DAY.match(day) or not _SID.match(name) or state not in _TERMINAL:
        return
    entries[name] = ArchivedEntry(session_id=name, state=state, node=node, relpath=f"{rel}.md")


def _catalogue_name(run_id: str) -> str:
    # Run ids are free text in the schema; only file-name-safe ones are used verbatim.
    if _SID.match(run_id):
        return f"{run_id}.log"
    return "h-" + hashlib.sha256(run_id.encode("utf-8")).hexdigest()[:24] + ".log"


class SessionArchive:
    """``sessions/archive/`` (see the module docstring).

    Args:
        sessions_dir: the workspace's ``sessions/`` directory.
    """

    def __init__(self, sessions_dir: str | os.PathLike[str]) -> None:
        self.root = Path(sessions_dir) / "archive"
        self.catalogue_dir = self.root / "runs"
        self._found: dict[str, Path] = {}
        # run id -> (catalogue inode, byte offset of its last line, entries of the lines before it)
        self._read: dict[str, tuple[int, int, dict[str, ArchivedEntry]]] = {}
        self._read_lock = threading.Lock()

    def day_dirs(self) -> list[Path]:
        """Archived days, newest first."""
        try:
            names = [n for n in os.listdir(self.root) if _DAY.match(n)]
        except FileNotFoundError:
            return []
        return [self.root / n for n in sorted(names, reverse=True)]

    def find(self, session_id: str) -> Path | None:
        """Path of the archived file of ``session_id``, or None if it is not archived."""
        path = self._found.get(session_id)
        if path is not None and path.is_file():
            return path
        for day in self.day_dirs():
            candidate = day / f"{session_id}.md"
            if candidate.is_file():
                self._found[session_id] = candidate
                return candidate
        return None

    def archive(self, active_path: Path, *, session_id: str, run_id: str, state: str, node: str,
                ended: datetime | None = None) -> Path:
        """Move ``active_path`` into the archive; returns the new path.

        Order: catalogue line (fsynced) -> rename -> fsync of both directories.

        Raises:
            OSError: the archive cannot be written (the file stays where it was).
        """
        ended = ended or datetime.now(timezone.utc)
        day = ended.strftime("%Y-%m-%d")
        day_dir = self.root / day
        day_dir.mkdir(parents=True, exist_ok=True)
        self._append(run_id, f"{day}/{session_id}\t{state}\t{' '.join(node.split())}")
        dest = day_dir / f"{session_id}.md"
        os.rename(active_path, dest)
        _fsync_dir(day_dir)
        _fsync_dir(active_path.parent)
        self._found[session_id] = dest
        return dest

    def _append(self, run_id: str, line: str) -> None:
        self.catalogue_dir.mkdir(parents=True, exist_ok=True)
        path = self.catalogue_dir / _catalogue_name(run_id)
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
        try:
            os.write(fd, ("\n" + line).encode("utf-8"))
            os.fsync(fd)
        finally:
            os.close(fd)

    def run_entries(self, run_id: str) -> list[ArchivedEntry]:
        """The archived sessions of ``run_id`` (catalogue order; later lines win per id).

        The catalogue only grows (lines are appended, each starting with a newline), so
        the lines before the last one are parsed once per :class:`SessionArchive` and
        kept; a call reads the bytes from the last line on (the last line itself every
        time: an append may still be tearing it). Another file in its place (a new inode,
        or a shorter file) is read whole again.
        """
        path = os.path.join(self.catalogue_dir, _catalogue_name(run_id))
        try:
            fd = os.open(path, os.O_RDONLY)
        except FileNotFoundError:
            return []
        try:
            st = os.fstat(fd)
            with self._read_lock:
                ino, offset, kept = self._read.get(run_id, (st.st_ino, 0, {}))
                if ino != st.st_ino or offset > st.st_size:
                    offset, kept = 0, {}
                os.lseek(fd, offset, os.SEEK_SET)
                tail = _read_all(fd)
                *complete, last = tail.split(b"\n")
                if complete:
                    kept = dict(kept)  # copied on write: a reader copies it outside the lock
                    for line in complete:
                        _parse_line(line, kept)
                    offset += sum(len(line) + 1 for line in complete)
                self._read[run_id] = (st.st_ino, offset, kept)
        finally:
            os.close(fd)
        entries = dict(kept)
        _parse_line(last, entries)
        return list(entries.values())

    def path_of(self, entry: ArchivedEntry) -> Path:
        return self.root / entry.relpath

    def iter_files(self) -> Iterator[Path]:
        """Every archived session file (a full scan: proportional to the history)."""
        for day in self.day_dirs():
            yield from sorted(day.glob("*.md"))

    def newest_files(self, n: int) -> list[Path]:
        """The ``n`` most recently archived files (by modification time), newest first."""
        if n <= 0:
            return []
        found: list[tuple[int, Path]] = []
        for day in self.day_dirs():
            with os.scandir(day) as it:
                for item in it:
                    if item.name.endswith(".md") and not item.name.startswith("."):
                        found.append((item.stat().st_mtime_ns, Path(item.path)))
            if len(found) >= n:
                break  # older days only hold older files
        found.sort(key=lambda t: t[0], reverse=True)
        return [p for _, p in found[:n]]
