"""SESSIONS.md of a Workspace: the bounded view of the sessions, upserted per transition,
deferred on the hand-off path and flushed in one write (mixed into
:class:`~phyagentos.protocol.Workspace`)."""

from __future__ import annotations

import logging
from collections import Counter
from typing import TYPE_CHECKING

from phyagentos.errors import PhyAgentOSError, ProtocolError

from ..codec import Document, read_document
from ..schemas import SESSION_STATES, SessionIndexEntry, SessionRecord, SessionsIndex
from .parts import WorkspaceParts
from .states import LEASED_STATES, TERMINAL, ts_key

if TYPE_CHECKING:
    from .core import Workspace

log = logging.getLogger(__name__)


class IndexViews(WorkspaceParts):
    """SESSIONS.md, the bounded view of the sessions. Mixed into :class:`~phyagentos.protocol.Workspace`."""

    def _trim_index(self, entries: list[SessionIndexEntry]) -> list[SessionIndexEntry]:
        newest_first = sorted(entries, key=lambda e: (ts_key(e.updated_at), e.session_id), reverse=True)
        leased = [e for e in newest_first if e.state in LEASED_STATES]
        waiting = [e for e in newest_first if e.state not in LEASED_STATES and e.state not in TERMINAL]
        terminal = [e for e in newest_first if e.state in TERMINAL]
        keep = {e.session_id for e in leased + waiting[: self.INDEX_MAX_WAITING]}
        active = [e for e in newest_first if e.session_id in keep]
        return active + terminal[: self.INDEX_MAX_TERMINAL]

    @staticmethod
    def _index_entry(record: SessionRecord) -> SessionIndexEntry:
        return SessionIndexEntry(
            session_id=record.session_id,
            node=record.node,
            skill=record.skill,
            target=record.target,
            state=record.state,
            updated_at=record.updated_at,
            parent_session_id=record.parent_session_id,
            run_id=record.run_id,
            owner=record.lease.owner if record.lease is not None and record.state in LEASED_STATES else None,
        )

    def _index_upsert(self, record: SessionRecord) -> None:
        entry = self._index_entry(record)
        if self.defer_index:
            self._index_pending[record.session_id] = entry  # the latest write of a session wins
            return
        self._index_write([entry])

    @property
    def index_pending(self) -> bool:
        """Whether SESSIONS.md entries wait for :meth:`flush_index`."""
        return bool(self._index_pending)

    def flush_index(self) -> None:
        """Write the SESSIONS.md entries that session writes left pending (``defer_index``),
        all in one rewrite of the view.

        SESSIONS.md is a view of the session files, written atomically but never fsynced;
        a process on a latency-critical path (between a verdict and the next session's
        first actuation: ``drive_run``, and ``watch`` and ``agent`` in their serving
        loops) defers it to when it would otherwise wait. A
        process killed with entries pending leaves the view behind the session files,
        as a kill between a session write and its SESSIONS.md update always could;
        :meth:`reconcile` rebuilds such a view.

        Raises:
            DocumentError: SESSIONS.md is malformed (the entries stay pending).
        """
        entries: dict[str, SessionIndexEntry] = {}
        while self._index_pending:  # popitem is atomic: another thread may add meanwhile
            try:
                sid, entry = self._index_pending.popitem()
            except KeyError:
                break
            if sid not in entries or ts_key(entry.updated_at) >= ts_key(entries[sid].updated_at):
                entries[sid] = entry
        if not entries:
            return
        try:
            self._index_write(list(entries.values()), deferred=True)
        except BaseException:
            for sid, entry in entries.items():
                self._index_pending.setdefault(sid, entry)
            raise

    def flush_index_quietly(self) -> bool:
        """:meth:`flush_index` for a serving loop (``watch``, ``agent``, ``drive_run``): a
        failure is logged as a warning instead of raised, once until a flush succeeds
        again, and the entries stay pending for the next call. A malformed SESSIONS.md
        then stays byte for byte as it is (its readers report it with its line) while the
        session files, which are authoritative, go on; :meth:`reconcile` rebuilds the view.

        Returns:
            ``True`` when nothing is left pending.
        """
        try:
            self.flush_index()
        except (PhyAgentOSError, OSError) as exc:
            message = str(exc)
            if message != self._index_flush_failure:
                log.warning("SESSIONS.md of %s not brought up to date: %s", self.root, message)
                self._index_flush_failure = message
            return False
        self._index_flush_failure = None
        return True

    def share_index_deferral(self, other: Workspace) -> None:
        """Defer this object's SESSIONS.md entries into ``other``'s pending set (the
        Workspace objects of one process's threads on the same workspace, e.g. the agent's
        and the supervisor's in ``drive_run``): one :meth:`flush_index` of either writes
        the entries of both in one rewrite. Sets :attr:`defer_index`.

        Raises:
            ProtocolError: ``other`` belongs to another workspace directory.
        """
        if other.root.resolve() != self.root.resolve():
            raise ProtocolError(f"share_index_deferral: {other.root} is not the workspace {self.root}")
        other._index_pending.update(self._index_pending)
        self._index_pending = other._index_pending
        self.defer_index = True

    def _index_write(self, entries: list[SessionIndexEntry], *, deferred: bool = False) -> None:
        def apply(index: SessionsIndex) -> None:
            # Counted under the SESSIONS.md lock: every hint renamed before this write
            # is included, and any later rename is followed by its own upsert.
            hints = self._states.entries()
            counts = Counter(hints.values())
            new = entries
            if deferred:
                # Another writer (another Workspace object or process) may have moved a
                # session on since: an entry older than the stored one, or of a state the
                # session has left, is dropped (the later write has or makes its own).
                stored = {e.session_id: ts_key(e.updated_at) for e in index.sessions}
                new = [e for e in entries
                       if ts_key(e.updated_at) >= stored.get(e.session_id, ts_key(e.updated_at))
                       and (e.state in TERMINAL or hints.get(e.session_id) == e.state)]
            ids = {e.session_id for e in new}
            others = [e for e in index.sessions if e.session_id not in ids]
            index.sessions = self._trim_index([*others, *new])
            index.counts = {state: counts[state] for state in SESSION_STATES if counts[state]}

        # SESSIONS.md is a view of the session files: atomic, but not fsynced (after a
        # power cut ``reconcile`` regenerates it); the session file itself is durable.
        self.update("SESSIONS", apply, durable=False)

    def rebuild_index(self) -> Document[SessionsIndex]:
        """Regenerate SESSIONS.md from the session files (the source of truth):
        every active session plus the most recently archived ones.

        Raises:
            DocumentError: a session file or SESSIONS.md is malformed.
        """
        records = [read_document(p, SessionRecord).data for p in sorted(self.sessions_dir.glob("*.md"))]
        records += [read_document(p, SessionRecord).data
                    for p in self._session_archive.newest_files(self.INDEX_MAX_TERMINAL)]
        entries = {r.session_id: self._index_entry(r) for r in records}

        def apply(index: SessionsIndex) -> None:
            counts = Counter(self._states.entries().values())
            index.sessions = self._trim_index(list(entries.values()))
            index.counts = {state: counts[state] for state in SESSION_STATES if counts[state]}

        return self.update("SESSIONS", apply)

