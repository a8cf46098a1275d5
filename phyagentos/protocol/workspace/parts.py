"""What the parts of a :class:`~phyagentos.protocol.Workspace` share: its state and, for the
type checker only, the methods one part calls on another (each defined once, in its part)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    from ..archive import SessionArchive
    from ..codec import Document
    from ..file_lock import WorkspaceLock
    from ..runs import RunRegistry
    from ..schemas import SessionIndexEntry, SessionRecord, SessionsIndex, VersionedModel
    from ..session_index import StateIndex

__all__ = ["WorkspaceParts"]


class WorkspaceParts:
    """The base of the Workspace's parts: the state :class:`~phyagentos.protocol.Workspace`
    sets up in ``__init__`` (annotations only) and its limits."""

    #: LOG.md keeps this many most recent entries; older ones go to log/archive-YYYY-MM.jsonl.
    LOG_MAX_ENTRIES: ClassVar[int] = 200
    #: SESSIONS.md lists every leased session, at most this many waiting ones (pending,
    #: awaiting verification or replan; most recently updated first) ...
    INDEX_MAX_WAITING: ClassVar[int] = 10
    #: ... and this many most recent terminal ones; ``counts`` has the exact totals.
    INDEX_MAX_TERMINAL: ClassVar[int] = 10
    #: RUNTIME_SIGNAL.md keeps at most this many signals; older handled ones go to
    #: log/signals-YYYY-MM.jsonl (the latest pause/resume and estop/clear_estop always stay).
    SIGNAL_MAX: ClassVar[int] = 100

    root: Path
    runs: RunRegistry
    defer_index: bool
    on_session_write: Callable[[SessionRecord], None] | None
    malformed: dict[str, str]
    _states: StateIndex
    _session_archive: SessionArchive
    _index_pending: dict[str, SessionIndexEntry]
    _index_flush_failure: str | None
    _locks_real: str | None

    if TYPE_CHECKING:  # defined by the parts; declared here so each part type-checks alone
        @property
        def sessions_dir(self) -> Path: ...
        @property
        def log_dir(self) -> Path: ...
        def path(self, name: str) -> Path: ...
        def _doc(self, name: str) -> tuple[str, str, type[VersionedModel]]: ...
        def _lock(self, key: str) -> WorkspaceLock: ...
        def session_lock(self, session_id: str) -> WorkspaceLock: ...
        def read(self, name: str) -> Document[Any]: ...
        def update(self, name: str, fn: Callable[[Any], Any], *, durable: bool = True) -> Document[Any]: ...
        @staticmethod
        def _check_session_id(session_id: str) -> None: ...
        def session_path(self, session_id: str) -> Path: ...
        def find_session_path(self, session_id: str) -> Path | None: ...
        def load_session(self, session_id: str) -> SessionRecord: ...
        def _index_upsert(self, record: SessionRecord) -> None: ...
        def rebuild_index(self) -> Document[SessionsIndex]: ...
