"""WatchdogSupervisor: its state, main loop, runner plumbing and fenced session writes.

What it does with them is in the mix-ins: :mod:`.claims`, :mod:`.execution`,
:mod:`.recovery`, :mod:`.signals`, :mod:`.maintenance`; the in-flight session's phase
machine is :mod:`.inflight`. The package docstring says how the pieces keep several
supervisors of one workspace safe together.
"""

from __future__ import annotations

import json
import logging
import os
import select
import socket
import time
import uuid
from pathlib import Path
from typing import Any, Callable

from phyagentos.errors import LeaseError, PhyAgentOSError, ProtocolError, SupervisorError
from phyagentos.protocol import LogEntry, SessionRecord, SignalState, Workspace, WorkspaceWatcher
from phyagentos.protocol.lifecycle import utc_now

from ..worker import RunnerDied, RunnerProcess
from ..worker import park_runner as _park_runner
from ..worker import take_runner as _take_runner
from .claims import Claiming
from .config import SupervisorConfig
from .execution import Execution
from .inflight import InflightSession
from .maintenance import Maintenance
from .presence import PRESENCE_DIR
from .recovery import Recovery
from .signals import SignalHandling

__all__ = ["WatchdogSupervisor"]

logger = logging.getLogger(__name__)


class WatchdogSupervisor(Claiming, Execution, Recovery, SignalHandling, Maintenance):
    """Claims, preflights, runs, supervises and writes back the sessions of one workspace.

    Args:
        workspace: the protocol workspace.
        runtime: optional BuiltinSkillRuntime whose skill and tree directories the
            runner uses (default: the project's ``skills/`` and ``trees/``).
        owner: identity written into leases (default ``host:pid:random``).
        lease_s: shorthand for ``config.lease_s``.
        config: see :class:`SupervisorConfig`.

    The runner process starts at construction (in the background).
    """

    def __init__(self, workspace: Workspace, runtime: Any = None, *, owner: str | None = None,
                 lease_s: float | None = None, config: SupervisorConfig | None = None) -> None:
        from phyagentos.resources import skill_dirs, tree_dirs  # noqa: PLC0415

        config = config or SupervisorConfig()
        if lease_s is not None:
            config = SupervisorConfig(**{**config.__dict__, "lease_s": lease_s})
        self.workspace = workspace
        self.config = config
        self.owner = owner or f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}"
        if runtime is not None:
            self._dirs = (str(runtime.skills.directory), str(runtime.trees.directory))
        else:
            self._dirs = (skill_dirs(), tree_dirs())  # the search path, PHYAGENTOS_SKILLS_PATH included
        self.watcher = WorkspaceWatcher(workspace.root, dirs=("sessions", "sessions/.index"),
                                        files=("RUNTIME_SIGNAL.md",), inotify=config.inotify)
        self._runner: RunnerProcess | None = _take_runner(*self._dirs)
        self._inflight: InflightSession | None = None
        self._signals = SignalState()
        self._seen_signals: set[str] = set()
        self._signal_stat: tuple | None = None
        self._signals_initialised = False
        self._succeeded: set[tuple[str, str]] = set()
        self._archive = None  # the SessionArchive whose catalogue reads _deps_met continues
        self._next_maintenance = 0.0
        self._next_reconcile = time.monotonic() + config.reconcile_interval_s
        self._queued: dict[str, str] = {}  # session id -> run holding its target's world
        self._set_aside: set[str] = set()  # sessions whose file no longer validates
        self._stopping = False
        self._stop_deadline: float | None = None
        self._closed = False
        #: ``gate(session_id, identity) -> bool`` asked before a pending session is claimed;
        #: False leaves it pending (the fleet's edge refuses submits it cannot confirm are
        #: current, phyagentos/fleet/edge.py). None: every session may be claimed.
        self.claim_gate: Callable[[str, Any], bool] | None = None
        #: Counters for status displays and tests.
        self.stats: dict[str, int] = {"claimed": 0, "completed": 0, "recovered": 0, "taken_over": 0,
                                      "released": 0, "runner_kills": 0}

    # -- public state ----------------------------------------------------

    @property
    def paused(self) -> bool:
        return self._signals.paused

    @property
    def estopped(self) -> bool:
        return self._signals.estopped

    @property
    def busy(self) -> bool:
        """True while a session is in flight."""
        return self._inflight is not None

    @property
    def runner_pid(self) -> int | None:
        return self._runner.pid if self._runner is not None and self._runner.alive() else None

    def request_stop(self, *, immediate: bool = False) -> None:
        """Stop claiming; let the in-flight session finish within ``drain_s`` (at once if
        ``immediate``), then cancel it. Safe to call from a signal handler."""
        now = time.monotonic()
        if not self._stopping:
            self._stopping = True
            self._stop_deadline = now if immediate else now + self.config.drain_s
        elif immediate:
            self._stop_deadline = now
        self.watcher.notify()

    @property
    def stopped(self) -> bool:
        """True once a stop was requested and nothing is in flight any more."""
        return self._stopping and self._inflight is None

    # -- main loop -------------------------------------------------------

    def serve(self) -> None:
        """Supervise until :meth:`request_stop` and the in-flight session is finished."""
        self.workspace.reconcile()
        logger.info("supervisor %s watching %s (%s)", self.owner, self.workspace.root, self.watcher.mode)
        last: tuple | None = None
        next_presence = 0.0
        self._write_presence()
        # SESSIONS.md (a view of the session files, never fsynced) is rewritten once the
        # session in flight runs or nothing is due, not by each write of the claim,
        # preflight and start on the path to the next session's first actuation.
        self.workspace.defer_index = True
        try:
            while not self.stopped:
                try:
                    acted = self.step()
                except (PhyAgentOSError, OSError) as exc:
                    # One bad document or session must not take the supervisor down with it.
                    logger.exception("supervisor %s: step failed: %s", self.owner, exc)
                    time.sleep(min(1.0, self.config.poll_interval_s))
                    acted = 0
                if self._views_due(acted):
                    self.workspace.flush_index_quietly()
                state = (self.runner_pid, self.paused, self.estopped, self._inflight and self._inflight.session_id)
                if state != last or time.monotonic() >= next_presence:
                    self._write_presence()
                    last, next_presence = state, time.monotonic() + self.config.lease_s / 3
        finally:
            self.workspace.defer_index = False
            self.workspace.flush_index_quietly()
            self._presence_path().unlink(missing_ok=True)

    def _views_due(self, acted: int) -> bool:
        """Whether ``serve`` rewrites the SESSIONS.md entries it deferred now: with
        nothing in flight, once the session in flight was started (``go`` is sent; the
        runner actuates in its own process), or when a step did nothing, but never
        between a claim and its start."""
        inf = self._inflight
        return inf is None or inf.phase == "running" or (not acted and inf.phase != "preflight")

    def _presence_path(self) -> Path:
        return self.workspace.root / PRESENCE_DIR / f"{os.getpid()}-{self.owner.rsplit(':', 1)[-1]}.json"

    def _write_presence(self) -> None:
        path = self._presence_path()
        path.parent.mkdir(exist_ok=True)
        data = {"owner": self.owner, "pid": os.getpid(), "runner_pid": self.runner_pid, "paused": self.paused,
                "estopped": self.estopped, "session": self._inflight.session_id if self._inflight else None,
                "watch": self.watcher.mode, "updated": time.time(), **self.stats}
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data), encoding="utf-8")
        os.replace(tmp, path)  # a status view: not fsynced

    def run_once(self) -> int:
        """Claim and process every session claimable now, each to the end of its runtime
        phase; returns how many were processed."""
        self._poll_signals()
        self._maintain()
        processed = 0
        while not self._stopping:
            if self._inflight is None and not self._claim_next():
                break
            while self._inflight is not None:
                self.step(timeout=self.config.poll_interval_s, claim=False)
            processed += 1
        return processed

    def step(self, timeout: float | None = None, *, claim: bool = True) -> int:
        """Wait for a wake-up (bounded), then do whatever is due; returns actions taken.

        Args:
            timeout: longest wait (default ``poll_interval_s``).
            claim: claim a new session if idle (``run_once`` drives claims itself).
        """
        wait = self._wait_budget(timeout)
        fds: list[Any] = [self.watcher]
        if self._runner is not None and self._runner.alive():
            fds.append(self._runner)
        if wait > 0:
            try:
                select.select(fds, [], [], wait)
            except (OSError, ValueError):  # a runner pipe closed under us
                pass
        self.watcher.clear()
        acted = self._poll_signals()
        acted += self._service_inflight()
        if time.monotonic() >= self._next_maintenance:
            acted += self._maintain()
        if claim and self._inflight is None and not self._stopping:
            acted += self._claim_next()
        return acted

    def _wait_budget(self, timeout: float | None) -> float:
        now = time.monotonic()
        budget = self.config.poll_interval_s if timeout is None else timeout
        marks = [self._next_maintenance]
        inf = self._inflight
        if inf is not None:
            marks += [m for m in (inf.deadline, inf.kill_at, inf.renew_at) if m]
            if inf.phase == "running":
                marks.append(now + min(1.0, inf.limits.heartbeat_timeout_s / 4))
            if inf.phase == "recover_wait":
                marks.append(now + 0.05)
        if self._stop_deadline is not None:
            marks.append(self._stop_deadline)
        return max(0.0, min([budget, *[m - now for m in marks]]))

    def close(self) -> None:
        """Stop watching and hand the runner back (killed if a session is still in flight)."""
        if self._closed:
            return
        self._closed = True
        self.watcher.close()
        if self._runner is not None:
            if self._inflight is not None:
                self._runner.kill()
            else:
                self._unreserve_all()
                _park_runner(self._runner)
            self._runner = None

    def __enter__(self) -> WatchdogSupervisor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- runner plumbing -------------------------------------------------

    def _ensure_runner(self) -> RunnerProcess:
        if self._runner is None or not self._runner.alive():
            if self._runner is not None:
                self._runner.kill()
            self._runner = RunnerProcess(skills_dir=self._dirs[0], trees_dir=self._dirs[1])
        return self._runner

    def _kill_runner(self, why: str) -> None:
        if self._runner is not None:
            logger.warning("supervisor %s: killing runner %s (%s)", self.owner, self._runner.pid, why)
            self._runner.kill()
            self.stats["runner_kills"] += 1
            self._runner = None

    def _request(self, kind: str, expect: tuple[str, ...], **payload: Any) -> tuple[str, dict]:
        runner = self._ensure_runner()
        msg = runner.request(kind, timeout=self.config.reply_timeout_s, expect=expect,
                             root=str(self.workspace.root), **payload)
        if msg[0] == "error":
            raise SupervisorError(f"runner job {kind!r} failed: {msg[1].get('message')}")
        return msg

    def _reserve(self, target: str) -> tuple[bool, dict | None]:
        """Have the runner take ``target``'s actuation lock: (reserved, in-flight marker)."""
        kind, payload = self._request("reserve", ("reserved", "busy"), target=target)
        if kind == "busy":
            return False, None
        self._runner.reserved.add((str(self.workspace.root), target))
        return True, payload.get("marker")

    def _unreserve(self, target: str, *, session_id: str | None = None, clear: bool = False) -> None:
        if self._runner is None or not self._runner.alive():
            return
        try:
            if clear:
                self._request("release", ("released",), target=target, session_id=session_id)
            else:
                self._request("unreserve", ("unreserved",), target=target)
        except (RunnerDied, SupervisorError) as exc:
            logger.warning("supervisor %s: could not release target %s: %s", self.owner, target, exc)
            return
        if self._runner is not None:
            self._runner.reserved.discard((str(self.workspace.root), target))

    def _unreserve_all(self) -> None:
        if self._runner is None:
            return
        for root, target in list(self._runner.reserved):
            if root == str(self.workspace.root):
                self._unreserve(target)

    # -- session writes --------------------------------------------------

    def _update(self, inf: InflightSession, fn) -> SessionRecord | None:
        """Fenced write; on a lost lease stop everything about this session."""
        try:
            return self.workspace.update_session(inf.session_id, fn, token=inf.token)
        except LeaseError as exc:
            logger.error("supervisor %s: %s; abandoning it", self.owner, exc)
            if inf.phase in ("running", "recovering") and self._runner is not None:
                self._kill_runner("lease lost: the session belongs to another supervisor now")
            self._inflight = None
            return None

    def _log(self, rec: SessionRecord, event: str, message: str) -> None:
        try:
            self.workspace.append_log(LogEntry(at=utc_now(), session_id=rec.session_id, node=rec.node, event=event,
                                               state=rec.state, message=message))
        except ProtocolError:
            logger.exception("could not append to LOG.md")
