"""Queries over the sessions of a Workspace (active ones from the state hints, a run's
finished ones from its archive catalogue) and the reconcile that repairs hints, views,
temp files and presence records a killed writer left (mixed into
:class:`~phyagentos.protocol.Workspace`)."""

from __future__ import annotations

import json
import logging
import os
import pickle
import socket
import time
from collections import Counter
from collections.abc import Iterable
from pathlib import Path

from phyagentos.errors import DocumentError, ProtocolError, format_choices

from ..atomic import file_identity
from ..codec import read_document
from ..schemas import SESSION_STATES, SessionRecord
from ..session_index import SessionIdentity
from .parts import WorkspaceParts
from .states import SESSION_ID, TERMINAL, ts_key

log = logging.getLogger(__name__)


#: Parsed terminal sessions a Workspace keeps (see ``_load_archived``).
_ARCHIVE_CACHE_SIZE = 4096


class SessionQueries(WorkspaceParts):
    """Queries over sessions and the reconcile of the hints. Mixed into :class:`~phyagentos.protocol.Workspace`."""

    def _validated_states(self, states: Iterable[str] | str | None) -> set[str] | None:
        if states is None:
            return None
        wanted = set([states] if isinstance(states, str) else states)
        unknown = wanted - set(SESSION_STATES)
        if unknown:
            raise ProtocolError(
                f"unknown session state(s) {format_choices(unknown)}; "
                f"valid: {format_choices(SESSION_STATES)}"
            )
        return wanted

    def active_sessions(self, states: Iterable[str] | str | None = None, *,
                        run_id: str | None = None) -> list[tuple[str, str, SessionIdentity]]:
        """``(session_id, state, identity)`` of active sessions, oldest submit first,
        without reading any session file (from ``sessions/.index/``).

        The state is a hint: confirm it by loading the session under its lock
        before acting on it.

        Raises:
            ProtocolError: an unknown state name.
        """
        wanted = self._validated_states(states)
        out = []
        for sid, state in self._states.entries().items():
            if wanted is not None and state not in wanted:
                continue
            ident = self._states.identity(sid, state)
            if ident is None or (run_id is not None and ident.run_id != run_id):
                continue
            out.append((sid, state, ident))
        out.sort(key=lambda t: (t[2].created_unix, t[0]))
        return out

    def list_sessions(self, states: Iterable[str] | str | None = None, *,
                      run_id: str | None = None, share_archived: bool = False) -> list[SessionRecord]:
        """Session records (optionally only those in ``states`` and of ``run_id``), oldest first.

        Cost: active sessions come from ``sessions/.index/``; terminal ones from the
        archive catalogue of ``run_id``. Without ``run_id``, asking for terminal
        states (or for all states) reads the whole archive.

        Every record is the caller's own copy unless ``share_archived``: then the
        records of archived sessions of ``run_id`` are this workspace's parsed records
        themselves (each still checked against its file's inode, modification time and
        size), which the caller must not modify. A coordinator lists its run on every
        step; copying each finished session every time (about 0.1 ms each) made a step's
        cost grow with the run's length.

        Raises:
            ProtocolError: an unknown state name (the message lists valid ones).
            DocumentError: a session file is malformed.
        """
        wanted = self._validated_states(states)
        by_id: dict[str, SessionRecord] = {}
        hint_states = self._states.entries()
        for sid, hinted in hint_states.items():
            if wanted is not None and hinted not in wanted and not (wanted & TERMINAL):
                continue
            known = True
            if run_id is not None:
                ident = self._states.identity(sid, hinted)
                if ident is not None and ident.run_id != run_id:
                    continue
                # None: the hint moved under us (a state change renames it between the
                # scan and this read; another process's session is not in this object's
                # cache). The session file decides below.
                known = ident is not None
            try:
                record = self.load_session(sid)
            except ProtocolError as exc:
                if isinstance(exc, DocumentError):
                    raise
                continue  # hint written, file not yet (a submit in progress)
            if not known and record.run_id != run_id:
                continue
            if record.state != hinted and record.state not in TERMINAL:
                self._repair_hint(sid)
            by_id[sid] = record
        if wanted is None or wanted & TERMINAL:
            if run_id is not None:
                for entry in self._session_archive.run_entries(run_id):
                    if entry.session_id in by_id or (wanted is not None and entry.state not in wanted):
                        continue
                    archived = self._load_archived(entry, share=share_archived)
                    if archived is not None:
                        by_id[archived.session_id] = archived
            else:
                for path in self._session_archive.iter_files():
                    if path.stem not in by_id:
                        by_id[path.stem] = read_document(path, SessionRecord).data
            # Terminal sessions whose move to the archive was interrupted.
            for path in self.sessions_dir.glob("*.md"):
                if path.stem not in by_id and path.stem not in hint_states:
                    record = read_document(path, SessionRecord).data
                    if run_id is None or record.run_id == run_id:
                        by_id[path.stem] = record
        records = [r for r in by_id.values() if wanted is None or r.state in wanted]
        records.sort(key=lambda r: (ts_key(r.created_at), r.session_id))
        return records

    def _load_archived(self, entry, *, share: bool = False) -> SessionRecord | None:
        # Terminal sessions do not change: a run's coordinator lists them on every step,
        # so parsed records are kept, keyed by the file's identity (inode, mtime, size),
        # and handed out as deep copies (unpickled), or themselves with ``share``.
        cache = self.__dict__.setdefault("_archived_cache", {})
        roots = self.__dict__.get("_archived_roots")
        if roots is None:  # strings: a listing joins a path per archived session
            roots = self.__dict__["_archived_roots"] = (str(self._session_archive.root), str(self.sessions_dir))
        for path in (os.path.join(roots[0], entry.relpath), os.path.join(roots[1], f"{entry.session_id}.md")):
            key = file_identity(path)
            if key is None:
                continue
            hit = cache.get(path)
            if hit is not None and hit[0] == key:
                if not share:
                    return pickle.loads(hit[2])
                if hit[1] is None:
                    hit[1] = pickle.loads(hit[2])
                return hit[1]
            try:
                record = read_document(Path(path), SessionRecord).data
            except FileNotFoundError:  # moved between the stat and the read
                continue
            if len(cache) >= _ARCHIVE_CACHE_SIZE:
                cache.clear()
            # [file identity, the shared record (made on the first shared listing), its
            # pickle]: a copy is one C-level unpickle (~10x faster than a pydantic deep copy)
            cache[path] = [key, record if share else None,
                                pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL)]
            return record
        log.warning("archive catalogue names session %s but its file is missing", entry.session_id)
        return None

    def _repair_hint(self, session_id: str) -> None:
        with self.session_lock(session_id):
            path = self.session_path(session_id)
            try:
                record = read_document(path, SessionRecord).data
            except FileNotFoundError:
                self._states.remove(session_id)
                return
            if record.state in TERMINAL:
                return  # reconcile() archives it
            self._states.create(record)

    def reconcile(self, *, stale_hint_s: float = 60.0) -> dict[str, int]:
        """Make hints and archive agree with the session files after a crash.

        Cost is proportional to the *active* sessions: every ``sessions/<id>.md`` is
        read once. Fixes: missing or stale hints, terminal sessions not yet archived,
        hints without a session file older than ``stale_hint_s`` (a younger one may be a
        submit in progress). Returns counts of each repair.

        Also removes temporary files of atomic writes interrupted more than
        ``stale_hint_s`` ago and presence files of supervisors whose process is gone.
        A session file that no longer validates is left untouched, set aside (its
        error in :attr:`malformed`, counted as ``malformed``) and the rest goes on.
        """
        fixed: Counter[str] = Counter()
        self.malformed: dict[str, str] = {}
        hints = self._states.entries()
        for path in sorted(self.sessions_dir.glob("*.md")):
            sid = path.stem
            if not SESSION_ID.match(sid):
                continue
            with self.session_lock(sid):
                try:
                    doc = read_document(path, SessionRecord)
                except FileNotFoundError:
                    continue
                except (DocumentError, OSError) as exc:
                    self.malformed[sid] = str(exc)
                    fixed["malformed"] += 1
                    log.warning("reconcile: session %s set aside, its file no longer validates: %s", sid, exc)
                    continue
                record = doc.data
                if record.state in TERMINAL:
                    self._session_archive.archive(path, session_id=sid, run_id=record.run_id, state=record.state,
                                          node=record.node)
                    self._states.remove(sid)
                    fixed["archived"] += 1
                elif hints.get(sid) != record.state or len(self._states.hint_files(sid)) != 1:
                    self._states.create(record)
                    fixed["hints"] += 1
        now = time.time()
        for sid in hints:
            if self.session_path(sid).is_file():
                continue
            for hint in self._states.hint_files(sid):
                try:
                    old = now - hint.stat().st_mtime > stale_hint_s
                except FileNotFoundError:
                    continue
                if old or self._session_archive.find(sid) is not None:
                    hint.unlink(missing_ok=True)
                    fixed["orphan_hints"] += 1
        fixed["temp_files"] += self._remove_stale_temp_files(stale_hint_s)
        fixed["dead_presence"] += self._remove_dead_presence()
        fixed["stale_index"] += self._index_is_stale(older_than_s=stale_hint_s)
        fixed = +fixed  # drop zero counts
        if fixed.keys() - {"malformed", "temp_files", "dead_presence"}:
            self.rebuild_index()
        if fixed:
            log.info("reconciled %s: %s", self.root, dict(fixed))
        return dict(fixed)

    def _index_is_stale(self, *, older_than_s: float) -> bool:
        """Whether SESSIONS.md shows a session in a state it left more than ``older_than_s``
        ago (its writer was killed before the view caught up, e.g. with entries deferred
        by :meth:`flush_index`'s callers). A malformed SESSIONS.md is left to its readers."""
        try:
            index = self.read("SESSIONS").data
        except (DocumentError, ProtocolError, OSError):
            return False
        hints = self._states.entries()
        cutoff = time.time() - older_than_s
        return any(e.state not in TERMINAL and hints.get(e.session_id) != e.state
                   and ts_key(e.updated_at).timestamp() < cutoff for e in index.sessions)

    def _remove_stale_temp_files(self, older_than_s: float) -> int:
        """Temp files ``.<name>.<random>.tmp`` (see :mod:`.atomic`) a killed writer left behind."""
        dirs = [self.root, self.sessions_dir, self.sessions_dir / ".index", self.runs.dir, self.runs.active_dir,
                self.runs.failed_dir, self.runs.owners_dir]
        for parent in (self.runs.dir, self.root / "targets"):
            try:
                dirs += [p for p in parent.iterdir() if p.is_dir() and not p.is_symlink()]
            except FileNotFoundError:
                pass
        now, removed = time.time(), 0
        for directory in dirs:
            try:
                entries = list(directory.glob(".*.tmp"))
            except OSError:
                continue
            for tmp in entries:
                try:
                    if tmp.is_file() and not tmp.is_symlink() and now - tmp.stat().st_mtime > older_than_s:
                        tmp.unlink()
                        removed += 1
                except FileNotFoundError:
                    continue
        return removed

    def _remove_dead_presence(self) -> int:
        """``.supervisors/*.json`` of this host's supervisors whose process is gone."""
        directory = self.root / ".supervisors"
        host, removed = socket.gethostname(), 0
        try:
            files = list(directory.glob("*.json"))
        except OSError:
            return 0
        for path in files:
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
                pid = int(data.get("pid", -1))
                if str(data.get("owner", "")).split(":", 1)[0] not in (host, ""):
                    continue  # another host's supervisor: its own reconcile decides
                os.kill(pid, 0)
            except ProcessLookupError:
                path.unlink(missing_ok=True)
                removed += 1
            except (OSError, ValueError, OverflowError, AttributeError):
                continue
        return removed

    def evidence_dir(self, session_id: str) -> Path:
        """``evidence/<session_id>/``, created if missing.

        Raises:
            ProtocolError: invalid session id.
        """
        self._check_session_id(session_id)
        path = self.root / "evidence" / session_id
        path.mkdir(parents=True, exist_ok=True)
        return path

