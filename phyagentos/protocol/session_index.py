"""``sessions/.index/``: the state of every active session, readable without parsing it.

Each non-terminal session has one small file named ``<session_id>~<state>`` holding
its immutable identity as JSON (run, node, skill, target, submit time, queue limit,
dependencies). A transition renames the file, which is atomic, so one ``os.scandir``
answers "which sessions are pending / leased / waiting for the verifier" in time
proportional to the number of *active* sessions, never to the history.

The files are hints derived from ``sessions/<id>.md`` (the source of truth):

- on submit the hint is created *before* the session file, so a session is never
  invisible to claimers (a hint without a file is skipped, and removed by
  :meth:`Workspace.reconcile` once it is old);
- on a transition the hint is renamed *after* the session file is written, under the
  session lock; a crash in between leaves a stale state that the next reader of that
  session (or ``reconcile``) corrects.

Hints are not fsynced: after a power loss ``reconcile`` rebuilds them from the files.
"""

from __future__ import annotations

import json
import logging
import os
import secrets
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from .schemas import SESSION_STATES, SessionRecord

__all__ = ["SessionIdentity", "StateIndex", "SEPARATOR"]

log = logging.getLogger(__name__)

#: Not allowed in session ids (SESSION_ID_PATTERN), so ``<id>~<state>`` splits unambiguously.
SEPARATOR = "~"
_STATES = frozenset(SESSION_STATES)


def _unix(timestamp: str) -> float:
    return datetime.fromisoformat(timestamp[:-1] + "+00:00" if timestamp.endswith("Z") else timestamp).timestamp()


@dataclass(frozen=True)
class SessionIdentity:
    """The fields of a session fixed at submit, as stored in its hint file.

    Attributes:
        created_unix: submit time in unix seconds (for queue timeouts and FIFO order).
        queue_timeout_s: ``limits.queue_timeout_s`` (s).
        depends_on: goal-graph node ids that must have succeeded in the same run.
    """

    session_id: str
    run_id: str
    node: str
    skill: str
    target: str
    created_at: str
    created_unix: float
    queue_timeout_s: float
    depends_on: tuple[str, ...] = ()
    parent_session_id: str | None = None

    @classmethod
    def of(cls, record: SessionRecord) -> SessionIdentity:
        return cls(
            session_id=record.session_id,
            run_id=record.run_id,
            node=record.node,
            skill=record.skill,
            target=record.target,
            created_at=record.created_at,
            created_unix=_unix(record.created_at),
            queue_timeout_s=float(record.limits.queue_timeout_s),
            depends_on=tuple(record.depends_on),
            parent_session_id=record.parent_session_id,
        )

    def to_json(self) -> str:
        data = dict(self.__dict__)
        data["depends_on"] = list(self.depends_on)
        return json.dumps(data, separators=(",", ":"), ensure_ascii=False)

    @classmethod
    def from_json(cls, text: str) -> SessionIdentity:
        data = json.loads(text)
        data["depends_on"] = tuple(data.get("depends_on", ()))
        return cls(**data)


class StateIndex:
    """The hint directory ``sessions/.index/`` (see the module docstring).

    Args:
        directory: the ``.index`` directory (created on first write).
    """

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.directory = Path(directory)
        self._identities: dict[str, SessionIdentity] = {}

    def _path(self, session_id: str, state: str) -> Path:
        return self.directory / f"{session_id}{SEPARATOR}{state}"

    def entries(self) -> dict[str, str]:
        """``session_id -> state`` of every active session (one directory scan).

        If a crash left two hints for one session, the one naming the later
        lifecycle state (in ``SESSION_STATES`` order) wins; ``reconcile`` removes the other.
        """
        out: dict[str, str] = {}
        try:
            scan = os.scandir(self.directory)
        except FileNotFoundError:
            return out
        order = {s: i for i, s in enumerate(SESSION_STATES)}
        with scan:
            for item in scan:
                sid, sep, state = item.name.rpartition(SEPARATOR)
                if not sep or item.name.startswith(".") or state not in _STATES:
                    continue
                if sid not in out or order[state] > order[out[sid]]:
                    out[sid] = state
        return out

    def has(self, session_id: str, state: str) -> bool:
        """True if ``session_id``'s hint names ``state`` (one ``stat``)."""
        return self._path(session_id, state).exists()

    def hint_files(self, session_id: str) -> list[Path]:
        """Every hint file of ``session_id`` (normally one)."""
        prefix = session_id + SEPARATOR
        try:
            return [self.directory / n for n in os.listdir(self.directory)
                    if n.startswith(prefix) and n[len(prefix):] in _STATES]
        except FileNotFoundError:
            return []

    def identity(self, session_id: str, state: str | None = None) -> SessionIdentity | None:
        """The identity of an active session (cached; identities never change).

        Returns None if the session has no hint (e.g. it was archived meanwhile).
        """
        cached = self._identities.get(session_id)
        if cached is not None:
            return cached
        candidates = [self._path(session_id, state)] if state else []
        candidates += self.hint_files(session_id)
        for path in candidates:
            try:
                ident = SessionIdentity.from_json(path.read_text(encoding="utf-8"))
            except FileNotFoundError:
                continue
            except (ValueError, TypeError, KeyError):
                log.warning("unreadable session hint %s; Workspace.reconcile rewrites it", path)
                continue
            self._identities[session_id] = ident
            return ident
        return None

    def create(self, record: SessionRecord) -> Path:
        """Write the hint of ``record`` in its current state (replacing any other hint of it)."""
        self.directory.mkdir(parents=True, exist_ok=True)
        ident = SessionIdentity.of(record)
        final = self._path(record.session_id, record.state)
        tmp = self.directory / f".{record.session_id}.{secrets.token_hex(4)}.tmp"
        tmp.write_text(ident.to_json(), encoding="utf-8")
        os.replace(tmp, final)
        for other in self.hint_files(record.session_id):
            if other != final:
                other.unlink(missing_ok=True)
        self._identities[record.session_id] = ident
        return final

    def move(self, record: SessionRecord, old_state: str) -> None:
        """Rename the hint from ``old_state`` to ``record.state`` (recreating it if missing)."""
        if old_state == record.state:
            if not self._path(record.session_id, record.state).exists():
                self.create(record)
            return
        try:
            os.rename(self._path(record.session_id, old_state), self._path(record.session_id, record.state))
        except FileNotFoundError:
            self.create(record)

    def remove(self, session_id: str, state: str | None = None) -> None:
        """Drop the hint of ``session_id`` (it became terminal); with ``state`` known,
        without scanning the directory."""
        self._identities.pop(session_id, None)
        if state is not None:
            try:
                self._path(session_id, state).unlink()
                return
            except FileNotFoundError:
                pass
        for path in self.hint_files(session_id):
            path.unlink(missing_ok=True)
