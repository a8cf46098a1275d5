"""The State-as-a-File workspace: protocol documents, session files, evidence.

Layout (see docs/ARCHITECTURE.md)::

    ws/SESSIONS.md ... RUNTIME_SIGNAL.md safety.yaml
    ws/sessions/<id>.md                    one document per active session (the source of truth)
    ws/sessions/.index/<id>~<state>        state hints of active sessions (session_index.py)
    ws/sessions/archive/YYYY-MM-DD/<id>.md terminal sessions, moved out of the way (archive.py)
    ws/runs/<run_id>/                      submitted goal graphs (runs.py)
    ws/evidence/<id>/                      evidence bundles
    ws/targets/<target>/                   simulated target state
    ws/log/                                archive-YYYY-MM.jsonl, LOG.md entries that aged out
    ws/.locks/                             lock files (flock, file_lock.py)

Every write is read-validate-modify-atomic-write under a file lock, so
concurrent processes never lose each other's updates and a malformed file is
reported (``DocumentError``) and never overwritten.

Cost does not grow with history: a transition writes one session file, renames
one hint and rewrites the bounded SESSIONS.md; queries over active sessions scan
``sessions/.index/``; a run's finished sessions are found through its archive
catalogue. Only :meth:`Workspace.list_sessions` without a run filter reads the
whole archive.
"""

from __future__ import annotations

import functools
import getpass
import json
import logging
import os
import pickle
import re
import socket
import threading
import time
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterable
from datetime import datetime
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from phyagentos import resources
from phyagentos.errors import DocumentError, LeaseError, PhyAgentOSError, ProtocolError, format_choices
from phyagentos.yamlsource import load_yaml

from .archive import SessionArchive
from .atomic import atomic_write_bytes, atomic_write_text, batched_durability, file_identity
from .codec import (
    PARSE_CACHE,
    Document,
    _fence_needed,
    _plain,
    _read_text,
    dump_yaml,
    parse_document,
    parse_yaml,
    read_document,
    write_document,
)
from .file_lock import WorkspaceLock, workspace_lock
from .runs import RunRegistry, inside_workspace
from .schemas import (
    DOCUMENTS,
    SAFETY_FILE,
    SAFETY_VIOLATIONS,
    SESSION_ID_PATTERN,
    SESSION_STATES,
    TERMINAL_STATES,
    Attempt,
    LogDoc,
    LogEntry,
    RunRecord,
    RuntimeSignalDoc,
    SafetyConfig,
    SessionIndexEntry,
    SessionRecord,
    SessionsIndex,
    Signal,
    SignalAck,
    VersionedModel,
    utc_now_iso,
)
from .session_index import SessionIdentity, StateIndex
from .signals import SIGNAL_KINDS, new_signal_id

__all__ = ["Workspace", "templates_dir", "LEASED_STATES", "WAITING_STATES"]

log = logging.getLogger(__name__)

# sessions/.index and sessions/archive appear with the first session that needs them.
_SUBDIRS = ("sessions", "evidence", "targets", ".locks")
_TERMINAL = frozenset(TERMINAL_STATES)
#: States in which a supervisor holds the session's lease.
LEASED_STATES: tuple[str, ...] = ("claimed", "preflight_checking", "running", "finalizing", "cancelling")
#: Active states in which a session waits for someone (a supervisor or the Agent).
WAITING_STATES: tuple[str, ...] = ("pending", "awaiting_verification", "verifying", "awaiting_replan")
_SESSION_ID = re.compile(SESSION_ID_PATTERN)
# Fields fixed when a session is submitted; rewriting them would detach the
# session file from the goal graph node and run it belongs to.
_IDENTITY_FIELDS = ("session_id", "run_id", "node", "created_at")


#: Parsed terminal sessions a Workspace keeps (see ``_load_archived``).
_ARCHIVE_CACHE_SIZE = 4096


def _deep_copy(record: SessionRecord) -> SessionRecord:
    """An independent copy of ``record`` (a pickle round trip: the same result as
    ``model_copy(deep=True)`` in a tenth of the time)."""
    return pickle.loads(pickle.dumps(record, protocol=pickle.HIGHEST_PROTOCOL))


#: LOG.md texts this process wrote, by path, with where their YAML body ends: the spliced
#: append (``Workspace._append_log_spliced``) edits only a text it knows the layout of.
_LOG_TEXTS: OrderedDict[str, tuple[str, int]] = OrderedDict()
_LOG_TEXTS_LOCK = threading.Lock()
_LOG_TEXTS_MAX = 64  # workspaces a process remembers its LOG.md text for


def _remember_log_text(path: Path, text: str, body_end: int) -> None:
    with _LOG_TEXTS_LOCK:
        _LOG_TEXTS[str(path)] = (text, body_end)
        _LOG_TEXTS.move_to_end(str(path))
        while len(_LOG_TEXTS) > _LOG_TEXTS_MAX:
            _LOG_TEXTS.popitem(last=False)


def _body_end(text: str, suffix: str) -> int:
    """Offset of the closing fence of a rendered document whose suffix is ``suffix``."""
    end = len(text) - len(suffix) - 1  # the newline after the closing fence
    start = end
    while start > 0 and text[start - 1] == "`":
        start -= 1
    return start


def templates_dir() -> Path:
    """The directory holding the document templates copied by :meth:`Workspace.create`.

    ``protocol/`` in the package data (:func:`phyagentos.resources.templates_dir`,
    overridable with ``PHYAGENTOS_HOME``).

    Raises:
        ProtocolError: the templates are not there.
    """
    candidate = resources.templates_dir()
    if not (candidate / DOCUMENTS["SESSIONS"][0]).is_file():
        raise ProtocolError(f"protocol templates not found in {candidate} "
                            "(PHYAGENTOS_HOME must name a folder holding protocol/, skills/, trees/)")
    return candidate


#: the session id of an archived log line (``_archive`` writes ``json.dumps`` of a LogEntry:
#: ids are plain, e.g. ``r20261123T070410-fb0c-h11-1``, so they need no JSON unescaping)
_LOG_SESSION_ID = re.compile(r'"session_id": "([^"\\]*)"')


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


@functools.lru_cache(maxsize=8)
def _missing_safety_keys(text: str) -> tuple[str, ...]:
    """The limits ``text`` (a ``safety.yaml`` that validated) does not write out; cached
    by the exact text, as every session's preflight and start read the same file."""
    raw = load_yaml(text, error=DocumentError) or {}
    missing = [name for name in SafetyConfig.model_fields if name not in raw]
    box = raw.get("workspace_box")
    if isinstance(box, dict):
        missing += [f"workspace_box.{k}" for k in ("min", "max") if k not in box]
    outcomes = raw.get("violation_outcomes")
    if isinstance(outcomes, dict):
        missing += [f"violation_outcomes.{code}" for code in SAFETY_VIOLATIONS if code not in outcomes]
    return tuple(missing)


def _check_complete_safety(path: Path, text: str) -> None:
    """Every limit of ``safety.yaml`` must be written out: a truncated or partial file
    would otherwise fall back to built-in defaults (e.g. a 30 s command duration for a
    configured 2 s).

    Raises:
        DocumentError: the missing keys, at the file's last line.
    """
    missing = list(_missing_safety_keys(text))
    if missing:
        raise DocumentError(
            f"{SAFETY_FILE} is incomplete: missing {format_choices(missing)}; every limit must be written out "
            f"(a missing limit is an error, never a default; {resources.templates_dir() / SAFETY_FILE} lists them all)",
            path=path, line=max(1, text.count("\n")))


class Workspace:
    """A workspace directory; construct with :meth:`create` or :meth:`open`."""

    #: LOG.md keeps this many most recent entries; older ones go to log/archive-YYYY-MM.jsonl.
    LOG_MAX_ENTRIES = 200
    #: SESSIONS.md lists every leased session, at most this many waiting ones (pending,
    #: awaiting verification or replan; most recently updated first) ...
    INDEX_MAX_WAITING = 10
    #: ... and this many most recent terminal ones; ``counts`` has the exact totals.
    INDEX_MAX_TERMINAL = 10
    #: RUNTIME_SIGNAL.md keeps at most this many signals; older handled ones go to
    #: log/signals-YYYY-MM.jsonl (the latest pause/resume and estop/clear_estop always stay).
    SIGNAL_MAX = 100

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)
        self._states = StateIndex(self.root / "sessions" / ".index")
        self._session_archive = SessionArchive(self.root / "sessions")
        self.runs = RunRegistry(self.root)
        #: ``True``: session writes through this object leave their SESSIONS.md entries in
        #: memory until :meth:`flush_index` (see there); ``False`` (default): each write
        #: rewrites SESSIONS.md before it returns
        self.defer_index = False
        self._index_pending: dict[str, SessionIndexEntry] = {}
        self._index_flush_failure: str | None = None  # the last failure flush_index_quietly logged
        self._locks_real: str | None = None  # realpath of locks_dir, once it exists
        #: Called with every session record this object writes (submit, save, update), after
        #: the write, under the session's lock; never for :meth:`install_replica`. The fleet's
        #: replication (phyagentos/fleet) sets it; it must be quick and must not raise.
        self.on_session_write: Callable[[SessionRecord], None] | None = None

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
        migrate = not (ws.root / "sessions" / ".index").is_dir() and any((ws.root / "sessions").glob("*.md"))
        for sub in _SUBDIRS:
            (ws.root / sub).mkdir(exist_ok=True)
        source = Path(templates) if templates is not None else templates_dir()
        with batched_durability():  # the templates are fsynced together, before validation
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
            # sensors.yaml (issue 9): optional in a template set, never overwritten
            if (source / "sensors.yaml").is_file() and not (ws.root / "sensors.yaml").exists():
                atomic_write_bytes(ws.root / "sensors.yaml", (source / "sensors.yaml").read_bytes())
        ws.validate()
        if migrate:  # a workspace written before sessions/.index existed
            ws.reconcile()
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

    def _lock(self, key: str) -> WorkspaceLock:
        # One lock object per file in this process (workspace_lock), so nested
        # acquisitions (e.g. a caller holding session_lock around save_session, or
        # another Workspace object of this directory) are re-entrant instead of waiting
        # for themselves; the directory is canonical for that reason.
        locks = self._locks_real
        if locks is None:
            self.locks_dir.mkdir(parents=True, exist_ok=True)
            locks = self._locks_real = os.path.realpath(self.locks_dir)
        return workspace_lock(f"{locks}/{key}.lock")

    def session_lock(self, session_id: str) -> WorkspaceLock:
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
            return read_document(inside_workspace(path, self.root), model)
        except FileNotFoundError:
            raise ProtocolError(
                f"{filename} missing from workspace {self.root}; Workspace.create restores it"
            ) from None

    def update(self, name: str, fn: Callable[[Any], Any], *, durable: bool = True) -> Document[Any]:
        """Apply ``fn`` to document ``name`` under its lock and write it back atomically.

        ``fn`` receives the validated model and either mutates it (returning
        None) or returns a replacement of the same model type. A ``revision``
        field, if the model has one, becomes the stored revision + 1. Prose is
        preserved. Returns the document as written. ``durable=False`` skips the
        fsyncs (for derived views only; see ``atomic_write_bytes``).

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
            write_document(doc, durable=durable)
            return doc

    def read_safety(self) -> SafetyConfig:
        """Read and validate ``safety.yaml``.

        Raises:
            DocumentError: the file is malformed.
            ProtocolError: the file is missing.
        """
        path = self.root / SAFETY_FILE
        try:
            text = _read_text(path)
        except FileNotFoundError:
            raise ProtocolError(
                f"{SAFETY_FILE} missing from workspace {self.root}; Workspace.create restores it"
            ) from None
        config = parse_yaml(text, SafetyConfig, path=path)
        _check_complete_safety(path, text)
        return config

    # -- sessions ---------------------------------------------------------

    @staticmethod
    def _check_session_id(session_id: str) -> None:
        if not isinstance(session_id, str) or not _SESSION_ID.match(session_id):
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
            existing = self.find_session_path(sid)
            if existing is not None:
                raise ProtocolError(f"session {sid!r} already exists ({existing})")
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
                        n_new == n_old and _ts_key(record.updated_at) <= _ts_key(old.updated_at)):
                    if record.transitions[:n_old] != old.transitions and old.transitions[:n_new] != record.transitions:
                        log.warning("replica of session %s refused: its transitions do not extend the local ones", sid)
                    return False
                old_state = old.state
            stored.data = record
            write_document(stored, validated=True, durable=durable)
            active = stored.path == self.session_path(sid)
            if active and record.state in _TERMINAL and stored.path is not None:
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
                if (doc.path == self.session_path(session_id) and stored.state not in _TERMINAL
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
        if active and record.state in _TERMINAL and stored.path is not None:
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
            if wanted is not None and hinted not in wanted and not (wanted & _TERMINAL):
                continue
            if run_id is not None:
                ident = self._states.identity(sid, hinted)
                if ident is None or ident.run_id != run_id:
                    continue
            try:
                record = self.load_session(sid)
            except ProtocolError as exc:
                if isinstance(exc, DocumentError):
                    raise
                continue  # hint written, file not yet (a submit in progress)
            if record.state != hinted and record.state not in _TERMINAL:
                self._repair_hint(sid)
            by_id[sid] = record
        if wanted is None or wanted & _TERMINAL:
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
        records.sort(key=lambda r: (_ts_key(r.created_at), r.session_id))
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
            if record.state in _TERMINAL:
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
            if not _SESSION_ID.match(sid):
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
                if record.state in _TERMINAL:
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
        return any(e.state not in _TERMINAL and hints.get(e.session_id) != e.state
                   and _ts_key(e.updated_at).timestamp() < cutoff for e in index.sessions)

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

    # -- SESSIONS.md index ------------------------------------------------

    def _trim_index(self, entries: list[SessionIndexEntry]) -> list[SessionIndexEntry]:
        newest_first = sorted(entries, key=lambda e: (_ts_key(e.updated_at), e.session_id), reverse=True)
        leased = [e for e in newest_first if e.state in LEASED_STATES]
        waiting = [e for e in newest_first if e.state not in LEASED_STATES and e.state not in _TERMINAL]
        terminal = [e for e in newest_first if e.state in _TERMINAL]
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
            if sid not in entries or _ts_key(entry.updated_at) >= _ts_key(entries[sid].updated_at):
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
                stored = {e.session_id: _ts_key(e.updated_at) for e in index.sessions}
                new = [e for e in entries
                       if _ts_key(e.updated_at) >= stored.get(e.session_id, _ts_key(e.updated_at))
                       and (e.state in _TERMINAL or hints.get(e.session_id) == e.state)]
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

    # -- runs -------------------------------------------------------------

    def register_run(self, record: RunRecord, graph_text: str) -> RunRecord:
        """Record a submitted goal graph (see :mod:`phyagentos.protocol.runs`).

        Raises:
            ProtocolError: duplicate or invalid run id.
        """
        return self.runs.register(record, graph_text)

    def run_lock(self, run_id: str) -> WorkspaceLock:
        """The lock an Agent process holds while it steps ``run_id`` (one agent per run at a time)."""
        self.runs.run_dir(run_id)  # validates the id
        return self._lock(f"run-{run_id}")

    # -- RUNTIME_SIGNAL.md ------------------------------------------------

    def send_signal(self, kind: str, *, session_id: str | None = None, reason: str = "",
                    issued_by: str | None = None, all_sessions: bool = False) -> Signal:
        """Append a signal to RUNTIME_SIGNAL.md: the one validated way to signal the runtime.

        Args:
            kind: one of ``cancel``, ``pause``, ``resume``, ``estop``, ``clear_estop``.
            session_id: the session a ``cancel`` addresses (must exist).
            all_sessions: a ``cancel`` without ``session_id`` must say so explicitly;
                it cancels every session submitted before the signal.
            issued_by: who sends it (default ``user@host``).

        Raises:
            ProtocolError: unknown kind, a cancel without a known session (or
                ``all_sessions``), or a session id on a workspace-wide signal.
        """
        if kind not in SIGNAL_KINDS:
            raise ProtocolError(f"unknown signal kind {kind!r}; valid: {format_choices(SIGNAL_KINDS)}")
        if kind == "cancel":
            if session_id is None and not all_sessions:
                raise ProtocolError("a cancel signal needs a session id (or all_sessions=True to cancel everything)")
            if session_id is not None:
                if self.find_session_path(session_id) is None:
                    raise ProtocolError(f"cannot cancel unknown session {session_id!r}")
        elif session_id is not None or all_sessions:
            raise ProtocolError(f"a {kind!r} signal applies to the whole runtime; it takes no session id")
        if issued_by is None:
            issued_by = f"{getpass.getuser()}@{socket.gethostname()}"
        signal = Signal(id=new_signal_id(), kind=kind, session_id=session_id, issued_by=issued_by,
                        issued_at=utc_now_iso(), reason=reason)

        def apply(doc: RuntimeSignalDoc) -> None:
            doc.signals.append(signal)
            self._compact_signals(doc)

        self.update("RUNTIME_SIGNAL", apply)
        log.info("signal %s %s%s", signal.id, kind, f" session {session_id}" if session_id else "")
        return signal

    def ack_signals(self, acks: Iterable[SignalAck]) -> None:
        """Append supervisors' acknowledgements to RUNTIME_SIGNAL.md (one write)."""
        acks = list(acks)
        if not acks:
            return

        def apply(doc: RuntimeSignalDoc) -> None:
            doc.handled.extend(acks)
            self._compact_signals(doc)

        self.update("RUNTIME_SIGNAL", apply)

    def _compact_signals(self, doc: RuntimeSignalDoc) -> None:
        """Move old, handled signals (and their acks) to log/signals-YYYY-MM.jsonl.

        Never moved: the latest pause/resume and estop/clear_estop (they are the
        current state) and cancels nobody has acknowledged yet.
        """
        overflow = len(doc.signals) - self.SIGNAL_MAX
        if overflow <= 0:
            return
        keep: set[str] = set()
        for group in (("pause", "resume"), ("estop", "clear_estop")):
            latest = [s for s in doc.signals if s.kind in group]
            if latest:
                keep.add(latest[-1].id)
        acked = {a.signal_id for a in doc.handled}
        movable = [s for s in doc.signals
                   if s.id not in keep and (s.kind != "cancel" or s.id in acked)][:overflow]
        if not movable:
            return
        moved = {s.id for s in movable}
        lines_by_month: dict[str, list[str]] = {}
        for sig in movable:
            record = {"signal": sig.model_dump(mode="json"),
                      "handled": [a.model_dump(mode="json") for a in doc.handled if a.signal_id == sig.id]}
            month = _ts_key(sig.issued_at).strftime("%Y-%m")
            lines_by_month.setdefault(month, []).append(json.dumps(record, ensure_ascii=False) + "\n")
        self.log_dir.mkdir(parents=True, exist_ok=True)
        for month, lines in sorted(lines_by_month.items()):
            with open(self.log_dir / f"signals-{month}.jsonl", "a", encoding="utf-8", newline="") as handle:
                handle.writelines(lines)
                handle.flush()
                os.fsync(handle.fileno())
        doc.signals = [s for s in doc.signals if s.id not in moved]
        doc.handled = [a for a in doc.handled if a.signal_id not in moved]

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
        _, filename, _ = self._doc("LOG")
        path = inside_workspace(self.root / filename, self.root)
        with self._lock("LOG"):
            try:
                text = _read_text(path)
            except FileNotFoundError:
                raise ProtocolError(f"{filename} missing from workspace {self.root}; "
                                    "Workspace.create restores it") from None
            doc = parse_document(text, LogDoc, path=path)
            if self._append_log_spliced(path, text, doc, entry):
                return
            doc.data.entries.append(entry)
            overflow = len(doc.data.entries) - self.LOG_MAX_ENTRIES
            if overflow > 0:
                self._archive(doc.data.entries[:overflow])
                del doc.data.entries[:overflow]
            write_document(doc)
            written = _read_text(path)  # what was just written, under the lock
            _remember_log_text(path, written, _body_end(written, doc.suffix))

    def log_entries_of(self, session_ids: Iterable[str], *, since: str) -> list[LogEntry]:
        """The log entries of ``session_ids``, oldest first: those in LOG.md and those aged out
        to ``log/archive-YYYY-MM.jsonl`` from the month of ``since`` (a UTC timestamp,
        ``2026-11-23T07:00:00Z``) on. An archived line that does not parse is skipped with
        a warning (the archive is append-only: a torn last line is a crash's, not data).

        Raises:
            DocumentError: LOG.md is malformed.
            ProtocolError: LOG.md is missing.
        """
        wanted = set(session_ids)
        if not wanted:
            return []
        current = [e for e in self.read("LOG").data.entries if e.session_id in wanted]
        first = f"archive-{_ts_key(since).strftime('%Y-%m')}.jsonl"
        archived: list[LogEntry] = []
        for archive in sorted(self.log_dir.glob("archive-*.jsonl")) if self.log_dir.is_dir() else []:
            if archive.name < first:
                continue
            with open(archive, encoding="utf-8") as handle:
                for number, line in enumerate(handle, 1):
                    found = _LOG_SESSION_ID.search(line)  # one look-up a line, however many sessions
                    if found is None or found.group(1) not in wanted:
                        continue
                    try:
                        archived.append(LogEntry.model_validate(json.loads(line)))
                    except (ValueError, ValidationError) as exc:
                        log.warning("%s:%d: log line skipped: %s", archive, number, exc)
        return archived + current

    def _append_log_spliced(self, path: Path, text: str, doc: Document[Any], entry: LogEntry) -> bool:
        """Append ``entry`` (and age out the oldest entry at the bound) by editing the text
        instead of rendering every entry again: LOG.md is rewritten on every transition
        and rendering 200 entries took ~15 ms. Only when ``text`` is exactly what this
        process last wrote (so its layout is the renderer's: one ``- `` line at column 0
        per entry, the entries last, a three-backtick fence), the entry's lines cannot
        touch the fence, no entry ends the YAML open-ended and at most one entry ages out; the result is then byte for byte
        what rendering the whole document gives (property test). Returns False to have
        the caller render the whole document instead."""
        with _LOG_TEXTS_LOCK:
            known = _LOG_TEXTS.get(str(path))
        if known is None or known[0] != text or not doc.data.entries or len(doc.data.entries) > self.LOG_MAX_ENTRIES:
            return False
        body_end = known[1]
        if text[body_end:body_end + 4] != "```\n":
            return False
        plain = entry.model_dump(mode="python", warnings=False)
        block = dump_yaml({"entries": [plain]})
        if not block.startswith("entries:\n- ") or _fence_needed(block) > 3 or not _plain(plain):
            return False
        item = block[len("entries:\n"):]
        prefix = doc.prefix if not doc.prefix or doc.prefix.endswith("\n") else doc.prefix + "\n"
        body_start = len(prefix) + len("```yaml\n")
        head, tail = text[:body_end], text[body_end:]
        if head.endswith("\n...\n") or item.endswith("\n...\n"):
            # libyaml ends a document with "..." once any scalar in it was open-ended (a
            # literal block keeping its final newlines): whether the whole log still needs
            # the marker depends on every entry, so such logs are rendered whole.
            return False
        entries = [*doc.data.entries, LogEntry.model_validate(plain)]
        if len(entries) > self.LOG_MAX_ENTRIES:
            first = head.find("\nentries:\n- ", body_start - 1)
            if first < 0:
                return False
            first += len("\nentries:\n")
            second = head.find("\n- ", first)
            second = len(head) if second < 0 else second + 1
            self._archive(entries[:1])
            head = head[:first] + head[second:]
            entries = entries[1:]
        new_text = head + item + tail
        atomic_write_text(path, new_text)
        PARSE_CACHE.put("document", LogDoc, new_text,
                        (prefix, doc.data.model_copy(update={"entries": entries}), doc.suffix))
        _remember_log_text(path, new_text, len(head) + len(item))
        return True

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

