"""The State-as-a-File workspace: protocol documents, session files, evidence.

Layout (see docs/ARCHITECTURE.md)::

    ws/SESSIONS.md ... RUNTIME_SIGNAL.md safety.yaml
    ws/sessions/<id>.md     one document per session (the source of truth)
    ws/evidence/<id>/       evidence bundles
    ws/targets/<target>/    simulated target state
    ws/log/                 archive-YYYY-MM.jsonl, LOG.md entries that aged out
    ws/.locks/              filelock files

Every write is read-validate-modify-atomic-write under a file lock, so
concurrent processes never lose each other's updates and a malformed file is
reported (``DocumentError``) and never overwritten.
"""

from __future__ import annotations

import json
import logging
import os
import re
from collections.abc import Callable, Iterable
from datetime import datetime
from pathlib import Path
from typing import Any

from filelock import FileLock
from pydantic import ValidationError

from phyagentos.errors import DocumentError, ProtocolError, format_choices

from phyagentos import resources

from .atomic import atomic_write_bytes
from .codec import Document, read_document, read_yaml, write_document
from .schemas import (
    DOCUMENTS,
    SAFETY_FILE,
    SESSION_ID_PATTERN,
    SESSION_STATES,
    TERMINAL_STATES,
    Attempt,
    LogEntry,
    SafetyConfig,
    SessionIndexEntry,
    SessionRecord,
    SessionsIndex,
    VersionedModel,
    utc_now_iso,
)

__all__ = ["Workspace", "templates_dir"]

log = logging.getLogger(__name__)

_SUBDIRS = ("sessions", "evidence", "targets", ".locks")
_SESSION_ID = re.compile(SESSION_ID_PATTERN)
# Fields fixed when a session is submitted; rewriting them would detach the
# session file from the goal graph node and run it belongs to.
_IDENTITY_FIELDS = ("session_id", "run_id", "node", "created_at")


def templates_dir() -> Path:
    """The directory holding the document templates copied by :meth:`Workspace.create`.

    ``protocol/`` at the project root (:func:`phyagentos.resources.templates_dir`,
    overridable with ``PHYAGENTOS_HOME``).

    Raises:
        ProtocolError: the templates are not there.
    """
    candidate = resources.templates_dir()
    if not (candidate / DOCUMENTS["SESSIONS"][0]).is_file():
        raise ProtocolError(f"protocol templates not found in {candidate} (set PHYAGENTOS_HOME to the project root)")
    return candidate


def _ts_key(timestamp: str) -> datetime:
    return datetime.fromisoformat(timestamp[:-1] + "+00:00" if timestamp.endswith("Z") else timestamp)


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


class Workspace:
    """A workspace directory; construct with :meth:`create` or :meth:`open`."""

    #: LOG.md keeps this many most recent entries; older ones go to log/archive-YYYY-MM.jsonl.
    LOG_MAX_ENTRIES = 200
    #: SESSIONS.md lists every non-terminal session plus this many most recent terminal ones.
    INDEX_MAX_TERMINAL = 100

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)

    def __repr__(self) -> str:
        return f"Workspace({str(self.root)!r})"

    # -- construction -----------------------------------------------------

    @classmethod
    def create(
        cls, root: str | os.PathLike[str], *, templates: str | os.PathLike[str] | None = None
    ) -> Workspace:
        """Create (or complete) a workspace at ``root`` and validate it.

        Creates the directories, copies every missing document and
        ``safety.yaml`` from ``templates`` (default :func:`templates_dir`),
        never overwriting an existing file, then validates all documents.

        Raises:
            DocumentError: an existing document is malformed (it is left untouched).
            ProtocolError: a template is missing.
            OSError: the directories cannot be created.
        """
        ws = cls(root)
        ws.root.mkdir(parents=True, exist_ok=True)
        for sub in _SUBDIRS:
            (ws.root / sub).mkdir(exist_ok=True)
        source = Path(templates) if templates is not None else templates_dir()
        for key, filename in [*((k, f) for k, (f, _) in DOCUMENTS.items()), ("SAFETY", SAFETY_FILE)]:
            template = source / filename
            if not template.is_file():
                raise ProtocolError(f"template {filename} missing from {source}")
            # Under the document's lock so a concurrent writer's file is never
            # replaced by the template between the existence check and the write.
            with ws._lock(key):
                if not (ws.root / filename).exists():
                    atomic_write_bytes(ws.root / filename, template.read_bytes())
                    log.info("created %s from template", ws.root / filename)
        ws.validate()
        return ws

    @classmethod
    def open(cls, root: str | os.PathLike[str]) -> Workspace:
        """Open an existing workspace (nothing is created or validated).

        Raises:
            ProtocolError: ``root`` is not a directory holding a SESSIONS.md.
        """
        ws = cls(root)
        if not (ws.root / DOCUMENTS["SESSIONS"][0]).is_file():
            raise ProtocolError(
                f"no workspace at {ws.root} (no {DOCUMENTS['SESSIONS'][0]}); "
                "create one with Workspace.create"
            )
        return ws

    def validate(self) -> None:
        """Parse and validate every document and ``safety.yaml``.

        Raises:
            DocumentError: the first malformed document, with path and line.
            ProtocolError: a document is missing.
        """
        for key in DOCUMENTS:
            self.read(key)
        self.read_safety()

    # -- paths and locks --------------------------------------------------

    @property
    def sessions_dir(self) -> Path:
        return self.root / "sessions"

    @property
    def locks_dir(self) -> Path:
        return self.root / ".locks"

    @property
    def log_dir(self) -> Path:
        return self.root / "log"

    def _doc(self, name: str) -> tuple[str, str, type[VersionedModel]]:
        key = name[:-3] if name.endswith(".md") else name
        if key not in DOCUMENTS:
            raise ProtocolError(f"unknown document {name!r}; valid: {format_choices(DOCUMENTS)}")
        filename, model = DOCUMENTS[key]
        return key, filename, model

    def path(self, name: str) -> Path:
        """Path of document ``name`` (a ``DOCUMENTS`` key such as ``'TASK'``, or ``'TASK.md'``).

        Raises:
            ProtocolError: unknown document name (the message lists valid ones).
        """
        return self.root / self._doc(name)[1]

    def _lock(self, key: str) -> FileLock:
        self.locks_dir.mkdir(parents=True, exist_ok=True)
        # is_singleton: one lock object per file in this process, so nested
        # acquisitions (e.g. a caller holding session_lock around save_session)
        # are re-entrant instead of deadlocking.
        return FileLock(self.locks_dir / f"{key}.lock", is_singleton=True)

    def session_lock(self, session_id: str) -> FileLock:
        """The inter-process lock guarding ``sessions/<session_id>.md`` (re-entrant in-process).

        Raises:
            ProtocolError: ``session_id`` is not a valid session id.
        """
        self._check_session_id(session_id)
        return self._lock(f"session-{session_id}")

    # -- documents --------------------------------------------------------

    def read(self, name: str) -> Document[Any]:
        """Read and validate document ``name``.

        Raises:
            DocumentError: the document is malformed.
            ProtocolError: unknown name, or the file is missing.
        """
        _, filename, model = self._doc(name)
        path = self.root / filename
        try:
            return read_document(path, model)
        except FileNotFoundError:
            raise ProtocolError(
                f"{filename} missing from workspace {self.root}; Workspace.create restores it"
            ) from None

    def update(self, name: str, fn: Callable[[Any], Any]) -> Document[Any]:
        """Apply ``fn`` to document ``name`` under its lock and write it back atomically.

        ``fn`` receives the validated model and either mutates it (returning
        None) or returns a replacement of the same model type. A ``revision``
        field, if the model has one, becomes the stored revision + 1. Prose is
        preserved. Returns the document as written.

        Raises:
            DocumentError: the stored document is malformed (nothing is written),
                or ``fn`` left the data invalid.
            ProtocolError: unknown name, missing file, or ``fn`` returned another type.
            Exception: whatever ``fn`` raises (nothing is written).
        """
        key, _, model = self._doc(name)
        with self._lock(key):
            doc = self.read(key)
            revision = getattr(doc.data, "revision", None)
            result = fn(doc.data)
            if result is not None:
                if not isinstance(result, model):
                    raise ProtocolError(
                        f"update of {key}: fn returned {type(result).__name__}, "
                        f"expected {model.__name__} or None"
                    )
                doc.data = result
            if revision is not None:
                # Counted from the stored document, even if fn built a new one.
                doc.data.revision = revision + 1
            write_document(doc)
            return doc

    def read_safety(self) -> SafetyConfig:
        """Read and validate ``safety.yaml``.

        Raises:
            DocumentError: the file is malformed.
            ProtocolError: the file is missing.
        """
        path = self.root / SAFETY_FILE
        try:
            return read_yaml(path, SafetyConfig)
        except FileNotFoundError:
            raise ProtocolError(
                f"{SAFETY_FILE} missing from workspace {self.root}; Workspace.create restores it"
            ) from None

    # -- sessions ---------------------------------------------------------

    @staticmethod
    def _check_session_id(session_id: str) -> None:
        if not isinstance(session_id, str) or not _SESSION_ID.match(session_id):
            raise ProtocolError(
                f"invalid session id {session_id!r}: expected letters, digits, '.', '_' or '-' "
                "(1-128 characters, not starting with '.', '_' or '-')"
            )

    def session_path(self, session_id: str) -> Path:
        """Path of ``sessions/<session_id>.md``.

        Raises:
            ProtocolError: invalid session id.
        """
        self._check_session_id(session_id)
        return self.sessions_dir / f"{session_id}.md"

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
        ``pending`` and its id unused. Returns the validated record as written.

        Raises:
            ProtocolError: not pending, duplicate id, invalid id or invalid data.
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
            if path.exists():
                raise ProtocolError(f"session {sid!r} already exists ({path})")
            write_document(Document(prefix=_session_prose(record), data=record, path=path))
            self._index_upsert(record)
        log.info("submitted session %s (%s on %s)", sid, record.skill, record.target)
        return record

    def load_session(self, session_id: str) -> SessionRecord:
        """Read and validate ``sessions/<session_id>.md``.

        Raises:
            ProtocolError: unknown or invalid session id.
            DocumentError: the session file is malformed or names another session.
        """
        return self._load_session_doc(session_id).data

    def _load_session_doc(self, session_id: str) -> Document[SessionRecord]:
        path = self.session_path(session_id)
        try:
            doc = read_document(path, SessionRecord)
        except FileNotFoundError:
            raise ProtocolError(f"unknown session {session_id!r} (no {path})") from None
        if doc.data.session_id != session_id:
            raise DocumentError(
                f"file is named for session {session_id!r} but holds session_id "
                f"{doc.data.session_id!r}",
                path=path,
            )
        return doc

    def save_session(self, record: SessionRecord) -> SessionRecord:
        """Write an updated session record; returns it with ``updated_at`` set to now.

        Under the session lock: the stored record's ``transitions`` must be a
        prefix of the new ones, and its ``attempts`` too, except that the latest
        stored attempt may have unset fields filled in (e.g. ``ended_at``,
        ``verdict``) and new ``timings`` keys added. ``session_id``, ``run_id``,
        ``node`` and ``created_at`` cannot change. Prose in the file is kept.
        SESSIONS.md is refreshed while the session lock is still held, so the
        index never goes back to an older state of this session.

        Raises:
            ProtocolError: unknown session (use :meth:`submit_session`), an
                append-only or identity violation (naming session and field),
                or invalid data.
            DocumentError: the stored session file or SESSIONS.md is malformed.
        """
        sid = record.session_id
        with self.session_lock(sid):
            stored = self._load_session_doc(sid)
            record = self._revalidate(record)
            _check_append_only(stored.data, record)
            record = record.model_copy(update={"updated_at": utc_now_iso()})
            stored.data = record
            write_document(stored)
            self._index_upsert(record)
        return record

    def list_sessions(self, states: Iterable[str] | None = None) -> list[SessionRecord]:
        """All session records (optionally only those in ``states``), oldest first.

        Reads the per-session files, not the index.

        Raises:
            ProtocolError: an unknown state name (the message lists valid ones).
            DocumentError: a session file is malformed.
        """
        wanted = None
        if states is not None:
            wanted = set([states] if isinstance(states, str) else states)
            unknown = wanted - set(SESSION_STATES)
            if unknown:
                raise ProtocolError(
                    f"unknown session state(s) {format_choices(unknown)}; "
                    f"valid: {format_choices(SESSION_STATES)}"
                )
        records = []
        for path in sorted(self.sessions_dir.glob("*.md")):
            record = self._load_session_doc(path.stem).data
            if wanted is None or record.state in wanted:
                records.append(record)
        records.sort(key=lambda r: (_ts_key(r.created_at), r.session_id))
        return records

    def evidence_dir(self, session_id: str) -> Path:
        """``evidence/<session_id>/``, created if missing.

        Raises:
            ProtocolError: invalid session id.
        """
        self._check_session_id(session_id)
        path = self.root / "evidence" / session_id
        path.mkdir(parents=True, exist_ok=True)
        return path

    # -- SESSIONS.md index ------------------------------------------------

    def _trim_index(self, entries: list[SessionIndexEntry]) -> list[SessionIndexEntry]:
        newest_first = sorted(entries, key=lambda e: (_ts_key(e.updated_at), e.session_id), reverse=True)
        active = [e for e in newest_first if e.state not in TERMINAL_STATES]
        terminal = [e for e in newest_first if e.state in TERMINAL_STATES]
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
        )

    def _index_upsert(self, record: SessionRecord) -> None:
        entry = self._index_entry(record)

        def apply(index: SessionsIndex) -> None:
            others = [e for e in index.sessions if e.session_id != record.session_id]
            index.sessions = self._trim_index([*others, entry])

        self.update("SESSIONS", apply)

    def rebuild_index(self) -> Document[SessionsIndex]:
        """Regenerate SESSIONS.md from the session files (the source of truth).

        Raises:
            DocumentError: a session file or SESSIONS.md is malformed.
        """
        entries = [self._index_entry(r) for r in self.list_sessions()]

        def apply(index: SessionsIndex) -> None:
            index.sessions = self._trim_index(entries)

        return self.update("SESSIONS", apply)

    # -- LOG.md -----------------------------------------------------------

    def append_log(self, entry: LogEntry) -> None:
        """Append ``entry`` to LOG.md, moving entries beyond the newest
        :attr:`LOG_MAX_ENTRIES` to ``log/archive-YYYY-MM.jsonl`` (month of each
        entry's ``at``, one JSON object per line).

        Archived lines are written and fsynced before LOG.md is replaced, so a
        crash can duplicate an archived entry but never lose one.

        Raises:
            DocumentError: LOG.md is malformed (nothing is written).
            ProtocolError: LOG.md is missing.
            OSError: the archive cannot be written (LOG.md is left unchanged).
        """
        if not isinstance(entry, LogEntry):
            raise ProtocolError(f"append_log needs a LogEntry, got {type(entry).__name__}")

        def apply(doc: Any) -> None:
            doc.entries.append(entry)
            overflow = len(doc.entries) - self.LOG_MAX_ENTRIES
            if overflow > 0:
                self._archive(doc.entries[:overflow])
                del doc.entries[:overflow]

        self.update("LOG", apply)

    def _archive(self, entries: list[LogEntry]) -> None:
        by_month: dict[str, list[str]] = {}
        for item in entries:
            month = _ts_key(item.at).strftime("%Y-%m")
            line = json.dumps(item.model_dump(mode="json"), ensure_ascii=False)
            by_month.setdefault(month, []).append(line + "\n")
        self.log_dir.mkdir(parents=True, exist_ok=True)
        for month, lines in sorted(by_month.items()):
            with open(self.log_dir / f"archive-{month}.jsonl", "a", encoding="utf-8", newline="") as handle:
                handle.writelines(lines)
                handle.flush()
                os.fsync(handle.fileno())
        log.debug("archived %d log entries", len(entries))

