"""Session files of a Workspace: submit, load, save, fenced update and replica install, each
read-validate-modify-atomic-write under the session's lock, with its state hint and
SESSIONS.md entry kept in step (mixed into :class:`~phyagentos.protocol.Workspace`)."""

from __future__ import annotations

import logging
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from phyagentos.errors import DocumentError, LeaseError, ProtocolError, SessionExistsError

from ..codec import Document, read_document, write_document
from ..runs import inside_workspace
from ..schemas import Attempt, SessionRecord, utc_now_iso
from .parts import WorkspaceParts
from .states import SESSION_ID, TERMINAL, ts_key

log = logging.getLogger(__name__)


# Fields fixed when a session is submitted; rewriting them would detach the
# session file from the goal graph node and run it belongs to.
_IDENTITY_FIELDS = ("session_id", "run_id", "node", "created_at")


def _deep_copy(record: SessionRecord) -> SessionRecord:
    """An independent copy of ``record`` (a pickle round trip: the same result as
    ``model_copy(deep=True)`` in a tenth of the time)."""
    return pickle.loads(pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL))


def _one_line(value: Any) -> str:
    # Values interpolated into prose must not start new lines (a line starting
    # with ``` would open a Markdown fence).
    return " ".join(str(value).split())


def _first_difference(old: list[Any], new: list[Any]) -> int | None:
    for index, item in enumerate(old):
        if index >= len(new) or new[index] != item:
            return index
    return None


def _check_attempt_fill_in(session_id: str, old: Attempt, new: Attempt, index: int) -> None:
    """The latest attempt may only gain information: set fields stay as they were."""
    for name in Attempt.model_fields:
        before, after = getattr(old, name), getattr(new, name)
        if name == "timings":
            changed = [k for k, v in before.items() if after.get(k) != v]
        else:
            changed = [name] if before is not None and before != after else []
        if changed:
            raise ProtocolError(
                f"session {session_id!r}: field 'attempts' is append-only; attempts[{index}].{name} "
                f"was {before!r} and cannot be rewritten (only unset fields of the latest attempt "
                "may be filled in)"
            )


def _check_append_only(old: SessionRecord, new: SessionRecord) -> None:
    sid = old.session_id
    for name in _IDENTITY_FIELDS:
        if getattr(old, name) != getattr(new, name):
            raise ProtocolError(
                f"session {sid!r}: field {name!r} cannot change after submit "
                f"(stored {getattr(old, name)!r}, new {getattr(new, name)!r})"
            )
    index = _first_difference(old.transitions, new.transitions)
    if index is not None:
        raise ProtocolError(
            f"session {sid!r}: field 'transitions' is append-only; stored transitions[{index}] "
            "was removed or rewritten"
        )
    frozen = old.attempts[:-1]
    index = _first_difference(frozen, new.attempts)
    if index is not None or len(new.attempts) < len(old.attempts):
        where = index if index is not None else len(new.attempts)
        raise ProtocolError(
            f"session {sid!r}: field 'attempts' is append-only; stored attempts[{where}] "
            "was removed or rewritten"
        )
    if old.attempts:
        last = len(old.attempts) - 1
        _check_attempt_fill_in(sid, old.attempts[last], new.attempts[last], last)


def _session_prose(record: SessionRecord) -> str:
    return (
        f"# Session {record.session_id}\n\n"
        f"Skill `{_one_line(record.skill)}` on target `{_one_line(record.target)}` for goal node "
        f"`{_one_line(record.node)}` (run `{_one_line(record.run_id)}`).\n"
        "This file is the source of truth for the session: the runtime rewrites the YAML block\n"
        "on every transition (transitions and attempts are append-only). Text outside the\n"
        "block is yours and is kept.\n\n"
    )


class SessionStore(WorkspaceParts):
    """Session files: submit, load, save, fenced update, replicas.

    Mixed into :class:`~phyagentos.protocol.Workspace`.
    """

    @staticmethod
    def _check_session_id(session_id: str) -> None:
        if not isinstance(session_id, str) or not SESSION_ID.match(session_id):
            raise ProtocolError(
                f"invalid session id {session_id!r}: expected letters, digits, '.', '_' or '-' "
                "(1-128 characters, not starting with '.', '_' or '-')"
            )

    def session_path(self, session_id: str) -> Path:
        """Path of ``sessions/<session_id>.md``, where a session lives while it is active
        (terminal sessions move to ``sessions/archive/``; see :meth:`find_session_path`).

        Raises:
            ProtocolError: invalid session id.
        """
        self._check_session_id(session_id)
        return self.sessions_dir / f"{session_id}.md"

    def find_session_path(self, session_id: str) -> Path | None:
        """Where the file of ``session_id`` is now (active or archived), or None if unknown.

        Raises:
            ProtocolError: invalid session id.
        """
        path = self.session_path(session_id)
        if path.is_file():
            return path
        return self._session_archive.find(session_id)

    @staticmethod
    def _revalidate(record: SessionRecord) -> SessionRecord:
        # Catches invalid values assigned after construction (pydantic does not
        # validate assignment by default).
        try:
            return SessionRecord.model_validate(record.model_dump(mode="python", warnings=False))
        except ValidationError as exc:
            first = exc.errors()[0]
            where = ".".join(str(p) for p in first["loc"])
            raise ProtocolError(
                f"session {record.session_id!r}: invalid {where}: {first['msg']}"
            ) from None

    def submit_session(self, record: SessionRecord) -> SessionRecord:
        """Create ``sessions/<id>.md`` for a new session and add it to SESSIONS.md.

        This is the only way to create a session. The record must be in state
        ``pending`` and its id unused (also by archived sessions). Returns the
        validated record as written.

        Raises:
            SessionExistsError: the id is taken (a :class:`ProtocolError`).
            ProtocolError: not pending, invalid id or invalid data.
            DocumentError: SESSIONS.md is malformed (the session file is written first).
        """
        record = self._revalidate(record)
        sid = record.session_id
        if record.state != "pending":
            raise ProtocolError(
                f"session {sid!r}: submit_session needs state 'pending', found {record.state!r}"
            )
        path = self.session_path(sid)
        self.sessions_dir.mkdir(parents=True, exist_ok=True)
        with self.session_lock(sid):
            existing = self.find_session_path(sid)
            if existing is not None:
                raise SessionExistsError(f"session {sid!r} already exists ({existing})", session_id=sid,
                                         path=existing)
            # The hint first: a session file without a hint would be invisible to claimers.
            self._states.create(record)
            try:
                write_document(Document(prefix=_session_prose(record), data=record, path=path), validated=True)
            except BaseException:
                self._states.remove(sid, record.state)
                raise
            self._index_upsert(record)
            if self.on_session_write is not None:
                self.on_session_write(record)
        log.info("submitted session %s (%s on %s)", sid, record.skill, record.target)
        return record

    def install_replica(self, record: SessionRecord, *, durable: bool = True) -> bool:
        """Install ``record``, replicated from the workspace that is the authority for it
        (phyagentos/fleet), unless the local copy is as new or newer; True if written.

        The rule (docs/fleet.md): a replica takes an incoming record whose ``transitions``
        extend the local ones (the local list is a prefix), with more transitions or, as
        many, a later ``updated_at``. A record that does not extend the local one is
        refused (False, logged). The state hint, the archive and SESSIONS.md follow as for
        a local write; :attr:`on_session_write` is not called (a replica is not echoed).
        ``durable=False`` skips the fsyncs (a replica's authority keeps the durable copy).

        Raises:
            ProtocolError: invalid session id or data.
            DocumentError: the local session file is malformed.
        """
        record = self._revalidate(record)
        sid = record.session_id
        self.sessions_dir.mkdir(parents=True, exist_ok=True)
        with self.session_lock(sid):
            path = self.find_session_path(sid)
            if path is None:
                stored = Document(prefix=_session_prose(record), data=record, path=self.session_path(sid))
                old_state = None
            else:
                stored = self._load_session_doc(sid)
                old = stored.data
                n_old, n_new = len(old.transitions), len(record.transitions)
                if record.transitions[:n_old] != old.transitions or n_new < n_old or (
                        n_new == n_old and ts_key(record.updated_at) <= ts_key(old.updated_at)):
                    if record.transitions[:n_old] != old.transitions and old.transitions[:n_new] != record.transitions:
                        log.warning("replica of session %s refused: its transitions do not extend the local ones", sid)
                    return False
                old_state = old.state
            stored.data = record
            write_document(stored, validated=True, durable=durable)
            active = stored.path == self.session_path(sid)
            if active and record.state in TERMINAL and stored.path is not None:
                try:
                    stored.path = self._session_archive.archive(
                        stored.path, session_id=sid, run_id=record.run_id, state=record.state, node=record.node)
                except OSError:
                    log.exception("session %s: could not archive; reconcile() retries", sid)
                self._states.remove(sid, old_state)
            elif active:
                if old_state is None:
                    self._states.create(record)
                else:
                    self._states.move(record, old_state)
            self._index_upsert(record)
        return True

    def load_session(self, session_id: str) -> SessionRecord:
        """Read and validate the session's file (active or archived).

        Raises:
            ProtocolError: unknown or invalid session id.
            DocumentError: the session file is malformed or names another session.
        """
        return self._load_session_doc(session_id).data

    def _load_session_doc(self, session_id: str) -> Document[SessionRecord]:
        path = self.session_path(session_id)
        try:
            doc = read_document(inside_workspace(path, self.root), SessionRecord)
        except FileNotFoundError:
            archived = self._session_archive.find(session_id)
            if archived is None:
                raise ProtocolError(f"unknown session {session_id!r} (no {path})") from None
            try:
                doc = read_document(archived, SessionRecord)
            except FileNotFoundError:  # pragma: no cover - archived files are never removed
                raise ProtocolError(f"unknown session {session_id!r} (no {path})") from None
        if doc.data.session_id != session_id:
            raise DocumentError(
                f"file is named for session {session_id!r} but holds session_id "
                f"{doc.data.session_id!r}",
                path=doc.path,
            )
        return doc

    def save_session(self, record: SessionRecord) -> SessionRecord:
        """Write an updated session record; returns it with ``updated_at`` set to now.

        Under the session lock: the stored record's ``transitions`` must be a
        prefix of the new ones, and its ``attempts`` too, except that the latest
        stored attempt may have unset fields filled in (e.g. ``ended_at``,
        ``verdict``) and new ``timings`` keys added. ``session_id``, ``run_id``,
        ``node`` and ``created_at`` cannot change. Prose in the file is kept.
        The state hint and SESSIONS.md are refreshed while the session lock is
        still held, so neither ever goes back to an older state of this session.
        A session that reaches a terminal state is moved to ``sessions/archive/``.

        Raises:
            ProtocolError: unknown session (use :meth:`submit_session`), an
                append-only or identity violation (naming session and field),
                or invalid data.
            DocumentError: the stored session file or SESSIONS.md is malformed.
        """
        with self.session_lock(record.session_id):
            return self._write_session(self._load_session_doc(record.session_id), record)

    def update_session(self, session_id: str, fn: Callable[[SessionRecord], Any], *,
                       token: str | None = None) -> SessionRecord:
        """Read-modify-write ``session_id`` under its lock; returns the record as written.

        ``fn`` mutates the freshly loaded record (e.g. fires lifecycle events with
        ``persist=None``); if it returns ``False`` nothing is written. With ``token``
        this is a *fenced* write: it fails unless the stored lease still carries that
        token, so a supervisor whose lease was taken over can never overwrite its
        successor.

        Raises:
            LeaseError: ``token`` given and the stored lease is gone or has another token.
            ProtocolError, DocumentError: as for :meth:`save_session`.
            Exception: whatever ``fn`` raises (nothing is written).
        """
        with self.session_lock(session_id):
            doc = self._load_session_doc(session_id)
            record = _deep_copy(doc.data)
            if token is not None and (record.lease is None or record.lease.token != token):
                holder = f"{record.lease.owner!r}" if record.lease else "nobody"
                raise LeaseError(
                    f"session {session_id!r}: lease token no longer current (held by {holder}, state "
                    f"{record.state!r}); another supervisor took the session over"
                )
            if fn(record) is False:
                stored = doc.data
                if (doc.path == self.session_path(session_id) and stored.state not in TERMINAL
                        and not self._states.has(session_id, stored.state)):
                    self._states.create(stored)  # a writer died between file and hint: repair
                return stored
            return self._write_session(doc, record)

    def _write_session(self, stored: Document[SessionRecord], record: SessionRecord) -> SessionRecord:
        # Caller holds the session lock; ``stored`` was loaded under it.
        old = stored.data
        record = self._revalidate(record)
        _check_append_only(old, record)
        record = record.model_copy(update={"updated_at": utc_now_iso()})
        stored.data = record
        write_document(stored, validated=True)
        active = stored.path == self.session_path(record.session_id)
        if active and record.state in TERMINAL and stored.path is not None:
            try:
                stored.path = self._session_archive.archive(
                    stored.path, session_id=record.session_id, run_id=record.run_id,
                    state=record.state, node=record.node)
            except OSError:
                log.exception("session %s: could not archive; reconcile() retries", record.session_id)
            self._states.remove(record.session_id, old.state)
        elif active:
            self._states.move(record, old.state)
        self._index_upsert(record)
        if self.on_session_write is not None:
            self.on_session_write(record)
        return record

