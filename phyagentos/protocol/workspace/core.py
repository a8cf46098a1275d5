"""The Workspace: the documents, locks and paths of one State-as-a-File workspace.

Its session files, queries, SESSIONS.md view, signal board and log are the mix-ins
:mod:`.sessions`, :mod:`.queries`, :mod:`.index`, :mod:`.signal_board` and :mod:`.log`;
the package docstring describes the layout and the write discipline.
"""

from __future__ import annotations

import functools
import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from phyagentos import resources
from phyagentos.errors import DocumentError, ProtocolError, format_choices
from phyagentos.yamlsource import load_yaml

from ..archive import SessionArchive
from ..atomic import atomic_write_bytes, batched_durability
from ..codec import Document, _read_text, parse_yaml, read_document, write_document
from ..file_lock import WorkspaceLock, workspace_lock
from ..runs import RunRegistry, inside_workspace
from ..schemas import (
    DOCUMENTS,
    SAFETY_FILE,
    SAFETY_VIOLATIONS,
    RunRecord,
    SafetyConfig,
    SessionIndexEntry,
    SessionRecord,
    VersionedModel,
)
from ..session_index import StateIndex
from .index import IndexViews
from .log import WorkspaceLog
from .queries import SessionQueries
from .sessions import SessionStore
from .signal_board import SignalBoard

__all__ = ["Workspace", "templates_dir"]

log = logging.getLogger(__name__)

# sessions/.index and sessions/archive appear with the first session that needs them.
_SUBDIRS = ("sessions", "evidence", "targets", ".locks")


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


class Workspace(SessionStore, SessionQueries, IndexViews, SignalBoard, WorkspaceLog):
    """A workspace directory; construct with :meth:`create` or :meth:`open`."""

    # Limits (LOG_MAX_ENTRIES, INDEX_MAX_*, SIGNAL_MAX): :class:`.parts.WorkspaceParts`.

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
