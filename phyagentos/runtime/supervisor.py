"""WatchdogSupervisor: the Runtime plane's single entry point for sessions.

It supervises rather than controls. It claims a pending session atomically with a
lease, has its runner process (:mod:`phyagentos.runtime.worker`) run compatibility
preflight and then the session, watches the runner's heartbeats and the session's
deadlines, renews the lease while the runner is healthy, acts on RUNTIME_SIGNAL.md,
and writes every transition of the session file itself (the runner never does).
It never judges success: that is the Agent plane's SessionVerifier.

One session at a time per supervisor; run several supervisors (``phyagentos watch``
processes) on one workspace for parallelism. What keeps them safe together:

- **Claims** happen under the session's file lock and only from ``pending``, and
  carry a lease ``{owner, token, expires_at}``; every later write presents the token
  (:meth:`Workspace.update_session`), so a supervisor that lost its lease can never
  overwrite the one that took the session over.
- **Targets**: a session is claimed only after the runner holds the target's
  actuation lock (:mod:`phyagentos.runtime.target_lock`), so a target runs one
  session at a time, and ``inflight.yaml`` tells the next holder which session
  ended abnormally on it. The runner's preflight (read-only; it writes that marker)
  runs while the claim is written, and the session is prepared while ``start`` is
  written; nothing moves before ``go``, sent once ``start`` is durable. A claim that
  fails clears the marker its preflight wrote; one left by a crash names a session
  that is not leased, which the next holder's preflight replaces.
- **Crashes**: a session whose lease expired is taken over. If it had not started
  actuating it goes back to ``pending``. If it was actuating (``running``,
  ``finalizing``) it is never re-run: a fresh runner restores the target's last
  checkpoint, halts it, persists the halted state and writes a terminal snapshot,
  and the session goes to ``awaiting_verification`` with attempt outcome
  ``unknown`` (``outcome_unknown``), for the verifier to judge from that fresh
  observation before anything moves again.
- **Runner failures**: a runner that dies, goes silent (``heartbeat.*``), overruns
  its execution deadline or ignores a cancel is killed (SIGKILL) and the target put
  in a safe state the same way; the session ends attributed (docs/ERRORS.md).
- **Timeouts**: queue (pending too long after submit), preflight and execution,
  each enforced here whatever the runner does.
- **Signals**: cancel, pause/resume, e-stop/clear_estop from RUNTIME_SIGNAL.md.
- **Wake-ups**: inotify on ``sessions/``, ``sessions/.index/`` and RUNTIME_SIGNAL.md,
  plus the runner's pipe, with a bounded polling fallback; idle, it sleeps.

Use :meth:`serve` for the long-running process (``phyagentos watch``) and
:meth:`run_once` to process what is claimable now and return (``phyagentos run``).
"""

from __future__ import annotations

import json
import logging
import os
import re
import select
import socket
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from phyagentos.errors import DocumentError, LeaseError, LifecycleError, PhyAgentOSError, ProtocolError, SupervisorError
from phyagentos.protocol import (
    LEASED_STATES,
    SESSION_ID_PATTERN,
    Attempt,
    ErrorInfo,
    LogEntry,
    RejectionItem,
    SessionRecord,
    SignalAck,
    SignalState,
    Workspace,
    WorkspaceWatcher,
    file_identity,
    is_expired,
    new_lease,
    renewed,
)
from phyagentos.protocol import (
    errorcodes as ec,
)
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now

from .session_basis import runtime_basis
from .worker import RunnerDied, RunnerProcess
from .worker import park_runner as _park_runner
from .worker import take_runner as _take_runner

__all__ = ["WatchdogSupervisor", "SupervisorConfig", "PRESENCE_DIR", "read_presence"]

logger = logging.getLogger(__name__)

_TARGET_NAME = re.compile(SESSION_ID_PATTERN)  # TARGETS.md names follow the session-id pattern

#: A session whose preflight killed the runner this many times is aborted, not retried.
_MAX_PREFLIGHT_DEATHS = 5

#: Each serving supervisor keeps ``<workspace>/.supervisors/<pid>-<tag>.json`` up to date
#: (owner, pid, runner pid, paused, e-stopped, current session), for ``phyagentos status``.
PRESENCE_DIR = ".supervisors"


def read_presence(workspace_root: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """Presence records of the supervisors of a workspace, each with ``alive`` (its pid exists)."""
    out = []
    directory = os.path.join(os.fspath(workspace_root), PRESENCE_DIR)
    try:
        names = sorted(os.listdir(directory))
    except FileNotFoundError:
        return out
    for name in names:
        if not name.endswith(".json"):
            continue
        try:
            with open(os.path.join(directory, name), encoding="utf-8") as fh:
                data = json.load(fh)
        except (OSError, ValueError):
            continue
        try:
            os.kill(int(data.get("pid", -1)), 0)
            data["alive"] = True
        except (ProcessLookupError, ValueError, OverflowError):
            data["alive"] = False
        except PermissionError:
            data["alive"] = True
        out.append(data)
    return out


@dataclass(frozen=True)
class SupervisorConfig:
    """Tunables of a WatchdogSupervisor (all times in seconds).

    Attributes:
        lease_s: lease duration; renewed every ``lease_s / 3`` while the runner is healthy.
            A crashed supervisor's sessions are recovered about this long after it died.
        poll_interval_s: longest sleep between checks (bounds a missed wake-up).
        maintenance_interval_s: how often expired leases and queue timeouts are checked.
        cancel_grace_s: a runner must stop this long after a cancel or it is killed.
        estop_grace_s: as ``cancel_grace_s`` for an e-stop.
        execution_grace_s: the supervisor's execution deadline is the session's
            ``execution_timeout_s`` plus this (the runner enforces the exact one).
        checkpoint_interval_s: the runner persists the target state this often while running.
        reply_timeout_s: longest wait for a runner's reply to a quick job (includes its start-up).
        recover_timeout_s: longest wait for a safe-stop of a target.
        drain_s: on SIGINT/SIGTERM, in-flight sessions get this long to finish before
            they are cancelled.
        reconcile_interval_s: how often the state hints are reconciled with the session files.
        inotify: False forces the polling fallback (benchmarks compare both).
        targets: claim only sessions on these targets (None: any target).
    """

    lease_s: float = 10.0
    poll_interval_s: float = 1.0
    maintenance_interval_s: float = 1.0
    cancel_grace_s: float = 3.0
    estop_grace_s: float = 0.5
    execution_grace_s: float = 2.0
    checkpoint_interval_s: float = 0.25
    reply_timeout_s: float = 120.0
    recover_timeout_s: float = 120.0
    drain_s: float = 5.0
    reconcile_interval_s: float = 60.0
    inotify: bool = True
    targets: tuple[str, ...] | None = None


@dataclass
class _Inflight:
    """The session this supervisor is handling, and where it is in its runtime phase."""

    session_id: str
    target: str
    token: str
    phase: str  # preflight | running | recover_wait | recovering
    limits: Any
    started: float = field(default_factory=time.monotonic)
    deadline: float | None = None  # preflight or execution deadline (monotonic)
    go_at: float | None = None
    renew_at: float = 0.0
    cancel: tuple[str, str] | None = None  # (code, reason) requested by a signal
    kill_at: float | None = None
    kill_end: tuple[str, str, str] | None = None  # (status, code, message) after a forced stop
    end: tuple[str, str, str] | None = None  # (status, code, message) the recovery writes
    finished: bool = False
    recover_attempts: int = 0


# The pool of idle runner processes lives in worker.py (take_runner, park_runner).


class WatchdogSupervisor:
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
        self._inflight: _Inflight | None = None
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

    def _update(self, inf: _Inflight, fn) -> SessionRecord | None:
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

    # -- signals ---------------------------------------------------------

    def _poll_signals(self) -> int:
        key = file_identity(self.workspace.path("RUNTIME_SIGNAL"))
        if key is None:
            return 0
        if key == self._signal_stat:
            return 0
        self._signal_stat = key
        try:
            doc = self.workspace.read("RUNTIME_SIGNAL").data
        except ProtocolError:
            logger.exception("RUNTIME_SIGNAL.md unreadable; signals ignored until it is fixed")
            return 0
        replay = not self._signals_initialised
        self._signals_initialised = True
        acks: list[SignalAck] = []
        acted = 0
        for sig in doc.signals:
            if sig.id in self._seen_signals:
                continue
            self._seen_signals.add(sig.id)
            self._signals.apply(sig)
            result = self._act_on_signal(sig, replay=replay)
            if result:
                acted += 1
                acks.append(SignalAck(signal_id=sig.id, by=self.owner, at=utc_now(), result=result))
        if acks:
            try:
                self.workspace.ack_signals(acks)
            except ProtocolError:
                logger.exception("could not acknowledge signals")
        return acted

    def _act_on_signal(self, sig, *, replay: bool) -> str | None:
        """Act on one new signal; returns what was done (for the ack) or None."""
        inf = self._inflight
        if sig.kind in ("pause", "resume"):
            logger.warning("supervisor %s: %s (%s)", self.owner, "paused" if sig.kind == "pause" else "resumed", sig.reason)
            return None if replay else ("paused" if sig.kind == "pause" else "resumed")
        if sig.kind == "estop":
            logger.warning("supervisor %s: E-STOP (%s)", self.owner, sig.reason)
            if self._runner is not None and self._runner.alive():
                try:
                    self._runner.send("estop", reason=sig.reason or "e-stop", code=ec.CANCELLED_ESTOP)
                except RunnerDied:
                    pass
            if inf is not None and inf.phase == "running":
                self._begin_cancel(inf, ec.CANCELLED_ESTOP, f"e-stop {sig.id}: {sig.reason}".strip(": "),
                                   grace=self.config.estop_grace_s)
                return f"halted session {inf.session_id}"
            return None if replay else "e-stop engaged (nothing running)"
        if sig.kind == "clear_estop":
            if self._runner is not None and self._runner.alive():
                try:
                    self._runner.send("clear_estop")
                except RunnerDied:
                    pass
            return None if replay else "e-stop cleared"
        if sig.kind == "cancel":
            ids = [sig.session_id] if sig.session_id else [sid for sid, _, ident in self.workspace.active_sessions()
                                                               if self._signals.cancel_for(sid, ident.created_at)]
            done = [sid for sid in ids if sid and self._cancel_session(sid, reason=f"signal {sig.id}: {sig.reason}")]
            return f"cancelled {', '.join(done)}" if done else None
        return None

    def _cancel_session(self, session_id: str, *, reason: str) -> bool:
        inf = self._inflight
        if inf is not None and inf.session_id == session_id:
            if inf.phase == "preflight":
                inf.cancel = (ec.CANCELLED_OPERATOR, reason)
                return True
            if inf.phase == "running":
                self._begin_cancel(inf, ec.CANCELLED_OPERATOR, reason, grace=self.config.cancel_grace_s)
                return True
            if inf.end is not None and inf.end[0] == "unknown":
                inf.end = ("cancelled", ec.CANCELLED_OPERATOR, reason)
            return True
        error = ErrorInfo(code=ec.CANCELLED_OPERATOR, message=reason)
        did: list[bool] = []

        def fn(rec: SessionRecord):
            # Sessions nobody actuates: pending, or waiting for the verifier.
            if rec.state not in ("pending", "awaiting_verification"):
                return False
            lc = SessionLifecycle(rec)
            lc.fire("cancel", reason=reason)
            lc.fire("cancelled", reason=reason, error=error)
            rec.lease = None
            did.append(True)

        try:
            rec = self.workspace.update_session(session_id, fn)
        except ProtocolError:
            return False
        if did:
            self._log(rec, "cancelled", reason)
        return bool(did)

    def _begin_cancel(self, inf: _Inflight, code: str, reason: str, *, grace: float) -> None:
        """Ask the runner to stop; it is killed if it has not within ``grace`` s."""
        if inf.cancel is not None and inf.kill_at is not None:
            inf.kill_at = min(inf.kill_at, time.monotonic() + grace)
            return
        inf.cancel = (code, reason)
        if self._runner is not None and self._runner.alive():
            try:
                self._runner.send("cancel", reason=reason, code=code)
            except RunnerDied:
                pass
        rec = self._update(inf, lambda r: SessionLifecycle(r).fire("cancel", reason=f"{code}: {reason}")
                           if r.state in ("running", "finalizing") else False)
        if rec is None:
            return
        inf.kill_at = time.monotonic() + grace
        inf.kill_end = ("cancelled", code, reason)

    # -- claiming --------------------------------------------------------

    def _deps_met(self, ident) -> bool:
        missing = [d for d in ident.depends_on if (ident.run_id, d) not in self._succeeded]
        if not missing:
            return True
        # The run's archive catalogue names each finished session with its node and final
        # state (a line appended after the terminal record is durable): read it first (one
        # SessionArchive kept, so each read continues where the last stopped instead of
        # parsing the whole catalogue on every hand-off); parse the run's session files
        # only if it does not settle the question.
        from phyagentos.protocol.archive import SessionArchive  # noqa: PLC0415

        archive = self._archive
        if archive is None or archive.root != Path(self.workspace.sessions_dir) / "archive":
            archive = self._archive = SessionArchive(self.workspace.sessions_dir)
        for entry in archive.run_entries(ident.run_id):
            if entry.state == "succeeded":
                self._succeeded.add((ident.run_id, entry.node))
        if all((ident.run_id, d) in self._succeeded for d in ident.depends_on):
            return True
        for rec in self.workspace.list_sessions(states=["succeeded"], run_id=ident.run_id):
            self._succeeded.add((rec.run_id, rec.node))
        return all((ident.run_id, d) in self._succeeded for d in ident.depends_on)

    def _claim_next(self) -> int:
        """Claim the oldest claimable pending session and start its preflight; 1 if claimed."""
        if self._signals.paused or self._signals.estopped or self._stopping:
            return 0
        busy: set[str] = set()
        wanted = self.config.targets
        for sid, _, ident in self.workspace.active_sessions("pending"):
            if ident.target in busy or (wanted is not None and ident.target not in wanted):
                continue
            cancel = self._signals.cancel_for(sid, ident.created_at)
            if cancel is not None:
                self._cancel_session(sid, reason=f"signal {cancel.id}: {cancel.reason}")
                continue
            if not self._deps_met(ident):
                continue
            if self.claim_gate is not None and not self.claim_gate(sid, ident):
                continue
            if not _TARGET_NAME.match(ident.target):
                # Not a name any target can have: preflight rejects it without a lock.
                if self._claim(sid, ident):
                    return 1
                continue
            try:
                reserved, marker = self._reserve(ident.target)
            except (RunnerDied, SupervisorError) as exc:
                logger.error("supervisor %s: runner unavailable (%s)", self.owner, exc)
                self._kill_runner("did not answer a reservation")
                return 0
            if not reserved:
                busy.add(ident.target)
                continue
            if marker and marker.get("session_id") and marker.get("session_id") != sid:
                if self._resolve_marker(ident.target, marker):
                    return 1  # recovering the crashed session first; the claim waits
                if self._inflight is None and not self._marker_cleared(marker):
                    self._unreserve(ident.target)
                    busy.add(ident.target)
                    continue
            # A target's world belongs to one run at a time: another run's sessions queue.
            holder = self.workspace.runs.take_world(ident.target, ident.run_id)
            if holder is not None:
                self._unreserve(ident.target)
                if self._queued.get(sid) != holder:
                    self._queued[sid] = holder
                    logger.info("session %s of run %s waits: target %s holds the world of run %s until it "
                                "finishes", sid, ident.run_id, ident.target, holder)
                continue
            self._queued.pop(sid, None)
            if self._claim(sid, ident):
                return 1
            self._unreserve(ident.target)
        return 0

    def _marker_cleared(self, marker: dict) -> bool:
        """True if the session named by ``marker`` no longer needs its target."""
        try:
            rec = self.workspace.load_session(marker["session_id"])
        except ProtocolError:
            return True
        return rec.state not in LEASED_STATES or rec.lease is None or rec.lease.token != marker.get("token")

    def _resolve_marker(self, target: str, marker: dict) -> bool:
        """We hold ``target``; its marker names another session. Take that session over
        if its lease expired (returns True: we are now recovering it)."""
        sid = marker["session_id"]
        try:
            rec = self.workspace.load_session(sid)
        except ProtocolError:
            return False
        if rec.state in ("running", "finalizing", "cancelling") and is_expired(rec.lease):
            return self._take_over(sid, reserved_target=target)
        return False

    def _claim(self, session_id: str, ident) -> bool:
        lease = new_lease(self.owner, ttl_s=self.config.lease_s)
        sent: list[bool] = []  # [True] once the preflight is on its way, [False] if the runner is gone

        def preflight_now(rec: SessionRecord) -> None:
            # The preflight reads only fields the claim leaves as they are (``go`` checks
            # the runtime fields again by digest) and moves nothing, so the runner runs it
            # while the claim is made durable; its reply is read once the claim stands.
            # The record read under the session's lock goes with it: the runner need not
            # parse the file this write is replacing.
            try:
                self._runner.send("preflight", root=str(self.workspace.root), session_id=session_id,
                                  token=lease.token, owner=self.owner, record=rec)
                sent.append(True)
            except RunnerDied:
                sent.append(False)

        rec = self._claim_record(session_id, lease, on_claim=preflight_now)
        if rec is None:
            if sent == [True] and (str(self.workspace.root), ident.target) in self._runner.reserved:
                # the claim was not written: release the target and the marker its preflight left
                self._unreserve(ident.target, session_id=session_id, clear=True)
            return False
        self.stats["claimed"] += 1
        inf = _Inflight(session_id=session_id, target=rec.target, token=lease.token, phase="preflight",
                        limits=rec.limits)
        inf.renew_at = time.monotonic() + self.config.lease_s / 3
        self._inflight = inf
        inf.deadline = time.monotonic() + rec.limits.preflight_timeout_s
        if sent != [True]:
            self._on_runner_died(inf)
        return True

    def _claim_record(self, session_id: str, lease, *, on_claim) -> SessionRecord | None:
        """Make the claim (and the start of preflight) durable; the record, or None if
        the session could not be claimed (no longer pending, unreadable, not there, or
        the write failed: the file is then as it was). ``on_claim(record)`` is called
        once the session is read, pending, under its lock, with the claimed record before
        its write."""

        def fn(rec: SessionRecord):
            if rec.state != "pending":
                return False
            rec.lease = lease
            lc = SessionLifecycle(rec)
            lc.fire("claim", reason=f"by {self.owner}")
            # Preflight starts at once and touches no target: one durable write records both.
            lc.fire("preflight")
            on_claim(rec)

        try:
            rec = self.workspace.update_session(session_id, fn)
        except DocumentError as exc:  # a hand-edited session: set aside, everything else goes on
            if session_id not in self._set_aside:
                self._set_aside.add(session_id)
                logger.warning("supervisor %s: session %s set aside, its file no longer validates: %s",
                               self.owner, session_id, exc)
            return None
        except ProtocolError as exc:  # e.g. the hint is there, the file not yet
            logger.debug("claim of %s skipped: %s", session_id, exc)
            return None
        except OSError as exc:  # e.g. a full disk: the atomic write left the file as it was
            logger.error("supervisor %s: claim of %s not written: %s", self.owner, session_id, exc)
            return None
        if rec.state != "preflight_checking" or rec.lease is None or rec.lease.token != lease.token:
            return None
        return rec

    # -- the in-flight session ---------------------------------------------

    def _service_inflight(self) -> int:
        inf = self._inflight
        if inf is None:
            return 0
        acted = 0
        if inf.phase in ("preflight", "running", "recovering"):
            try:
                while self._inflight is inf:
                    msg = self._runner.poll(0) if self._runner is not None else None
                    if msg is None:
                        break
                    acted += self._on_message(inf, *msg)
            except RunnerDied:
                acted += self._on_runner_died(inf)
        if self._inflight is not inf:
            return acted
        now = time.monotonic()
        if inf.phase == "recover_wait":
            acted += self._start_recovery(inf)
            return acted
        if inf.phase == "preflight" and inf.deadline is not None and now > inf.deadline:
            self._kill_runner("preflight timeout")
            acted += self._finish_without_actuation(inf, "time_out", ec.TIMEOUT_PREFLIGHT,
                                                    f"preflight exceeded {inf.limits.preflight_timeout_s} s")
            return acted
        if inf.phase == "running":
            acted += self._watch_running(inf, now)
            if self._inflight is not inf:
                return acted
        if inf.phase == "recovering" and inf.deadline is not None and now > inf.deadline:
            self._kill_runner("safe stop did not finish in time")
            inf.phase = "recover_wait"
        if now >= inf.renew_at and self._inflight is inf:
            self._renew(inf, now)
        return acted

    def _watch_running(self, inf: _Inflight, now: float) -> int:
        if self._stopping and self._stop_deadline is not None and now >= self._stop_deadline and inf.cancel is None:
            self._begin_cancel(inf, ec.CANCELLED_SHUTDOWN, "supervisor stopping", grace=self.config.cancel_grace_s)
        if inf.kill_at is not None and now >= inf.kill_at:
            self._kill_runner(f"did not stop within the grace period ({inf.kill_end[1]})")
            return self._recover_after_kill(inf, inf.kill_end)
        hb = self._runner.heartbeats if self._runner is not None else None
        if hb is not None and inf.go_at is not None:
            timeout = inf.limits.heartbeat_timeout_s
            runner_age = now - max(hb.array[0], inf.go_at)
            stale = "runner" if runner_age > timeout else hb.stale(timeout, now)
            if stale is not None:
                code = {"runner": ec.HEARTBEAT_RUNNER, "target": ec.HEARTBEAT_TARGET,
                        "policy": ec.HEARTBEAT_POLICY}[stale]
                age = runner_age if stale == "runner" else hb.age(stale, now)
                self._kill_runner(f"{stale} heartbeat {age:.1f} s old")
                return self._recover_after_kill(inf, ("timed_out", code,
                                                      f"{stale} heartbeat {age:.1f} s old > heartbeat_timeout_s {timeout} s"))
        # Once the skill has finished, execution is over: the runner writes the evidence,
        # beating its heartbeat, and no execution deadline applies to that.
        expired = inf.deadline is not None and now > inf.deadline and inf.kill_at is None and not inf.finished
        if expired and self._execution_deadline_moved(inf, now):
            return 0
        if expired:
            logger.warning("session %s: execution deadline passed; stopping the runner", inf.session_id)
            inf.kill_end = ("timed_out", ec.TIMEOUT_EXECUTION,
                            f"execution exceeded {inf.limits.execution_timeout_s} s")
            inf.kill_at = now + self.config.cancel_grace_s
            try:
                self._runner.send("cancel", reason="execution timeout", code=ec.TIMEOUT_EXECUTION)
            except RunnerDied:
                pass
        return 0

    def _execution_deadline_moved(self, inf: _Inflight, now: float) -> bool:
        """Whether the execution deadline of a running session, passed at ``now``, moves
        to where the runner's own execution clock puts it instead of ending the session.

        The deadline set at ``start`` assumes execution began then. A runner sets a
        session up before its execution clock starts (it acquires and builds the target,
        perceives the scene): on a loaded machine that took several seconds, so a 1 s
        ``execution_timeout_s`` was cancelled while the runner was still setting up, was
        killed for not stopping between ticks it had not begun, and was recovered in a
        fresh runner (seconds to a minute). The runner shares its clock's start through
        the heartbeat array; until it does, the session is still being set up (a runner
        that hangs there goes silent and its heartbeat ends it), so the deadline is
        checked again shortly.
        """
        hb = self._runner.heartbeats if self._runner is not None else None
        if hb is None or inf.phase != "running" or inf.limits is None:
            return False
        started = hb.execution_started_at()
        if started is None:
            inf.deadline = now + min(0.25, inf.limits.heartbeat_timeout_s / 4)
            return True
        deadline = started + inf.limits.execution_timeout_s + self.config.execution_grace_s
        if deadline > now:
            inf.deadline = deadline
            return True
        return False

    def _renew(self, inf: _Inflight, now: float) -> None:
        healthy = True
        if inf.phase == "running" and self._runner is not None and inf.go_at is not None:
            healthy = now - max(self._runner.heartbeats.array[0], inf.go_at) < inf.limits.heartbeat_timeout_s
        if not healthy:
            return  # _watch_running ends it; an unhealthy runner does not keep its lease alive

        def fn(rec: SessionRecord):
            rec.lease = renewed(rec.lease, ttl_s=self.config.lease_s)

        if self._update(inf, fn) is not None:
            inf.renew_at = now + self.config.lease_s / 3

    def _on_message(self, inf: _Inflight, kind: str, payload: dict) -> int:
        if payload.get("session_id") not in (None, inf.session_id):
            return 0
        if kind == "error":
            logger.error("session %s: runner job %s failed: %s\n%s", inf.session_id, payload.get("job"),
                         payload.get("message"), payload.get("traceback", ""))
            if inf.phase == "preflight":
                self._kill_runner("preflight raised")
                return self._finish_without_actuation(inf, "abort", ec.RUNTIME_ERROR,
                                                      f"preflight raised: {payload.get('message')}")
            self._kill_runner(f"{payload.get('job')} raised")
            if inf.phase == "recovering":
                inf.phase = "recover_wait"
                return 0
            return self._recover_after_kill(inf, ("unknown", ec.RUNTIME_ERROR, str(payload.get("message"))))
        if kind == "preflight" and inf.phase == "preflight":
            return self._on_preflight(inf, payload)
        if kind == "finished" and inf.phase == "running":
            inf.finished = True
            # The runner stopped its skill (on its own, or on a cancel it was sent): it did
            # not ignore the cancel, so it is not killed for it while it writes the evidence
            # (its heartbeat still guards that); ``kill_end`` keeps how the session ends.
            inf.kill_at = None
            status = payload["status"]
            if status == "timed_out" or inf.cancel is not None:
                return 0  # time_out / cancelled are fired once the evidence is written
            if status != "cancelled":
                # ``finish`` is recorded with ``submit`` in one write once the evidence is
                # in (_on_done): running and finalizing recover alike (outcome_unknown).
                return 1
            reason = payload.get("message", "")
            return 1 if self._update(inf, lambda r: SessionLifecycle(r).fire("cancel", reason=reason)
                                     if r.state == "running" else False) else 0
        if kind == "done" and inf.phase == "running":
            return self._on_done(inf, payload)
        if kind == "recovered" and inf.phase == "recovering":
            return self._on_recovered(inf, payload)
        return 0

    def _on_preflight(self, inf: _Inflight, payload: dict) -> int:
        if not payload["ok"]:
            items = [RejectionItem(**r) for r in payload["rejections"]]
            codes = sorted({i.code for i in items})
            message = "; ".join(f"{i.code} {i.field}: expected {i.expected}, found {i.found}" for i in items)

            def reject(rec: SessionRecord):
                rec.rejection = items
                rec.lease = None
                SessionLifecycle(rec).fire("reject", reason=", ".join(codes),
                                           error=ErrorInfo(code=codes[0], message=message))

            rec = self._update(inf, reject)
            self._end_inflight(inf, clear_marker=False)
            if rec is not None:
                self._log(rec, "rejected", message)
            return 1
        if inf.cancel is not None:
            return self._finish_without_actuation(inf, "cancel", *inf.cancel)
        if self._signals.estopped or self._stopping:
            why = "e-stop engaged" if self._signals.estopped else "supervisor stopping"
            return self._release_to_pending(inf, why)
        attempt_runner = f"{self.owner}/runner:{self._runner.pid}"

        def start(rec: SessionRecord):
            rec.adapter_plan = payload["plan"]
            rec.tool_manifest = payload["manifest"]
            rec.attempts.append(Attempt(number=len(rec.attempts) + 1, started_at=utc_now(), runner=attempt_runner,
                                        timings={"preflight": round(payload.get("duration_s", 0.0), 6)}))
            rec.lease = renewed(rec.lease, ttl_s=self.config.lease_s)
            SessionLifecycle(rec).fire("start")

        rec = self._update(inf, start)
        if rec is None:
            return 0
        inf.phase = "running"
        now = time.monotonic()
        inf.go_at = now
        inf.renew_at = now + self.config.lease_s / 3
        inf.deadline = now + rec.limits.execution_timeout_s + self.config.execution_grace_s
        self._runner.heartbeats.reset()
        try:
            # The runner prepared the session after its preflight reply; the digest of the
            # fields just made durable tells it whether that preparation is of this session.
            self._runner.send("go", root=str(self.workspace.root), session_id=inf.session_id,
                              checkpoint_interval_s=self.config.checkpoint_interval_s, basis=runtime_basis(rec))
        except RunnerDied:
            return 1 + self._on_runner_died(inf)
        return 1

    def _attempt_fill(self, rec: SessionRecord, payload: dict, *, error: tuple[str, str] | None) -> None:
        attempt = rec.attempts[-1]
        attempt.ended_at = utc_now()
        attempt.outcome = payload["outcome"]
        attempt.evidence = payload["evidence"]
        timings = dict(payload.get("timings") or {})
        attempt.timings = {**attempt.timings, **{k: v for k, v in timings.items() if k not in attempt.timings}}
        code, message = error if error else (payload.get("error_code"), payload.get("message", ""))
        if code:
            attempt.error = ErrorInfo(code=code, message=message or "")

    def _on_done(self, inf: _Inflight, payload: dict) -> int:
        outcome = payload["outcome"]
        if inf.kill_end is not None and inf.kill_end[0] == "timed_out":
            error = inf.kill_end[1:]
        elif inf.cancel is not None:
            error = inf.cancel
        else:
            error = None

        def done(rec: SessionRecord):
            self._attempt_fill(rec, payload, error=error)
            lc = SessionLifecycle(rec)
            info = ErrorInfo(code=rec.attempts[-1].error.code, message=rec.attempts[-1].error.message) \
                if rec.attempts[-1].error else None
            if rec.state == "cancelling":
                lc.fire("cancelled", reason=info.message if info else "", error=info)
            elif outcome == "timed_out" or (inf.kill_end is not None and inf.kill_end[0] == "timed_out"):
                lc.fire("time_out", reason=payload.get("message", ""), error=info)
            elif outcome == "cancelled":
                if rec.state in ("running", "finalizing"):
                    lc.fire("cancel", reason=payload.get("message", ""))
                lc.fire("cancelled", reason=payload.get("message", ""), error=info)
            else:
                if rec.state == "running":
                    lc.fire("finish")
                lc.fire("submit")  # completed, failed or error: the evidence decides
            rec.lease = None

        rec = self._update(inf, done)
        self._end_inflight(inf, clear_marker=True)
        if rec is not None:
            self.stats["completed"] += 1
            if rec.state != "awaiting_verification":  # the verdict is logged by the Agent; endings here are ours
                self._log(rec, f"runtime_{outcome}", f"by {self.owner}: {payload.get('message') or outcome}"[:500])
        return 1

    def _finish_without_actuation(self, inf: _Inflight, event: str, code: str, message: str) -> int:
        """End a session that never started actuating (preflight timeout, cancel, error)."""
        error = ErrorInfo(code=code, message=message)

        def fn(rec: SessionRecord):
            lc = SessionLifecycle(rec)
            if event == "cancel":
                lc.fire("cancel", reason=message)
                lc.fire("cancelled", reason=message, error=error)
            else:
                lc.fire(event, reason=message, error=error)
            rec.lease = None

        rec = self._update(inf, fn)
        self._end_inflight(inf, clear_marker=True)
        if rec is not None:
            self._log(rec, rec.state, f"{code}: {message}")
        return 1

    def _release_to_pending(self, inf: _Inflight, why: str) -> int:
        def fn(rec: SessionRecord):
            SessionLifecycle(rec).fire("release", reason=why)
            rec.lease = None

        self._update(inf, fn)
        self.stats["released"] += 1
        self._end_inflight(inf, clear_marker=True)
        return 1

    def _end_inflight(self, inf: _Inflight, *, clear_marker: bool) -> None:
        self._unreserve(inf.target, session_id=inf.session_id, clear=clear_marker)
        if self._inflight is inf:
            self._inflight = None

    # -- failures and recovery ---------------------------------------------

    def _on_runner_died(self, inf: _Inflight) -> int:
        code = self._runner.process.exitcode if self._runner is not None else None
        self._kill_runner(f"runner died (exit code {code})")
        if inf.phase == "preflight":
            releases = sum(1 for t in self.workspace.load_session(inf.session_id).transitions
                           if t.event.startswith("release"))
            if releases >= _MAX_PREFLIGHT_DEATHS - 1:
                return self._finish_without_actuation(
                    inf, "abort", ec.RUNTIME_RUNNER_DIED,
                    f"the runner died during preflight {_MAX_PREFLIGHT_DEATHS} times")
            return self._release_to_pending(inf, "runner died during preflight")
        if inf.phase == "running":
            if inf.kill_end is not None:
                return self._recover_after_kill(inf, inf.kill_end)
            return self._recover_after_kill(inf, ("unknown", ec.RUNTIME_RUNNER_DIED,
                                                  f"runner process died (exit code {code}) while actuating"))
        if inf.phase == "recovering":
            inf.phase = "recover_wait"
        return 0

    def _recover_after_kill(self, inf: _Inflight, end: tuple[str, str, str]) -> int:
        inf.end = end
        inf.phase = "recover_wait"
        inf.kill_at = None
        return self._start_recovery(inf)

    def _take_over(self, session_id: str, *, reserved_target: str | None = None) -> bool:
        """Take over a session whose lease expired. Sessions that had not started actuating
        go back to pending; actuating ones are recovered (we become their owner)."""
        lease = new_lease(self.owner, ttl_s=self.config.lease_s)
        previous: dict[str, Any] = {}

        def fn(rec: SessionRecord):
            if rec.state not in LEASED_STATES or not is_expired(rec.lease):
                return False
            previous["owner"] = rec.lease.owner if rec.lease else None
            rec.lease = lease

        try:
            rec = self.workspace.update_session(session_id, fn)
        except ProtocolError:
            return False
        if rec.lease is None or rec.lease.token != lease.token:
            return False
        self.stats["taken_over"] += 1
        logger.warning("supervisor %s: took over session %s (%s) from %s after its lease expired", self.owner,
                       session_id, rec.state, previous.get("owner"))
        inf = _Inflight(session_id=session_id, target=rec.target, token=lease.token, phase="recover_wait",
                        limits=rec.limits)
        inf.renew_at = time.monotonic() + self.config.lease_s / 3
        if rec.state in ("claimed", "preflight_checking"):
            def release(r: SessionRecord):
                SessionLifecycle(r).fire("release", reason=f"lease of {previous.get('owner')} expired before actuation")
                r.lease = None

            self.workspace.update_session(session_id, release, token=lease.token)
            self.stats["released"] += 1
            self._log(rec, "released", f"lease of {previous.get('owner')} expired before actuation")
            return False
        message = f"lease of {previous.get('owner')} expired while the session was {rec.state}"
        if rec.state == "cancelling":
            inf.end = ("cancelled", ec.RUNTIME_LEASE_EXPIRED, message)
        else:
            inf.end = ("unknown", ec.RUNTIME_LEASE_EXPIRED, message)
        self._inflight = inf
        if reserved_target is not None and self._runner is not None:
            self._begin_recover_job(inf)
        else:
            self._start_recovery(inf)
        return True

    def _start_recovery(self, inf: _Inflight) -> int:
        """Reserve the target (retrying while busy), then ask a runner to safe-stop it."""
        inf.recover_attempts += 1
        try:
            reserved, _ = self._reserve(inf.target)
        except (RunnerDied, SupervisorError) as exc:
            logger.error("session %s: runner unavailable for recovery: %s", inf.session_id, exc)
            self._kill_runner("unavailable for recovery")
            return 0
        if not reserved:
            return 0  # the orphaned runner (or someone else) still holds it; retry soon
        self._begin_recover_job(inf)
        return 1

    def _begin_recover_job(self, inf: _Inflight) -> None:
        status, code, message = inf.end
        inf.phase = "recovering"
        inf.deadline = time.monotonic() + self.config.recover_timeout_s
        try:
            self._runner.send("recover", root=str(self.workspace.root), session_id=inf.session_id,
                              status=status, error_code=code, message=message)
        except RunnerDied:
            self._kill_runner("died before recovery")
            inf.phase = "recover_wait"

    def _on_recovered(self, inf: _Inflight, payload: dict) -> int:
        status, code, message = inf.end
        error = ErrorInfo(code=code, message=message)

        def fn(rec: SessionRecord):
            if rec.attempts and rec.attempts[-1].ended_at is None:
                self._attempt_fill(rec, payload, error=(code, message))
            lc = SessionLifecycle(rec)
            if status == "unknown" and rec.state in ("running", "finalizing"):
                lc.fire("outcome_unknown", reason=f"{code}: {message}")
            elif status == "timed_out":
                lc.fire("time_out", reason=message, error=error)
            else:  # cancelled (or unknown while cancelling: the cancel wins)
                if rec.state != "cancelling":
                    lc.fire("cancel", reason=message)
                lc.fire("cancelled", reason=message, error=error)
            rec.lease = None

        rec = self._update(inf, fn)
        self._end_inflight(inf, clear_marker=True)
        if rec is not None:
            self.stats["recovered"] += 1
            self._log(rec, f"recovered_{status}", f"{code}: {message}; target {inf.target} halted from its checkpoint")
        return 1

    # -- maintenance -------------------------------------------------------

    def _maintain(self) -> int:
        """Expired leases, queue timeouts, cancels of pending sessions; periodic reconcile."""
        now_mono = time.monotonic()
        self._next_maintenance = now_mono + self.config.maintenance_interval_s
        acted = 0
        now = time.time()
        mine = self._inflight.session_id if self._inflight is not None else None
        for sid, state, ident in self.workspace.active_sessions():
            if sid == mine:
                continue
            try:
                if state == "pending":
                    cancel = self._signals.cancel_for(sid, ident.created_at)
                    if cancel is not None:
                        acted += self._cancel_session(sid, reason=f"signal {cancel.id}: {cancel.reason}")
                    elif now > ident.created_unix + ident.queue_timeout_s:
                        acted += self._queue_timeout(sid, ident)
                elif state in LEASED_STATES:
                    rec = self.workspace.load_session(sid)
                    if rec.state not in LEASED_STATES or not is_expired(rec.lease, now=now):
                        continue
                    if rec.state in ("claimed", "preflight_checking"):
                        self._take_over(sid)
                        acted += 1
                    elif self._inflight is None and (self.config.targets is None or rec.target in self.config.targets):
                        acted += int(self._take_over(sid))
            except ProtocolError as exc:
                logger.debug("maintenance skipped %s: %s", sid, exc)
        if now_mono >= self._next_reconcile:
            self._next_reconcile = now_mono + self.config.reconcile_interval_s
            try:
                self.workspace.reconcile()
            except ProtocolError:
                logger.exception("reconcile failed")
        return acted

    def _queue_timeout(self, session_id: str, ident) -> int:
        waited = time.time() - ident.created_unix
        message = f"pending {waited:.1f} s > queue_timeout_s {ident.queue_timeout_s} s"
        error = ErrorInfo(code=ec.TIMEOUT_QUEUE, message=message)
        did: list[bool] = []

        def fn(rec: SessionRecord):
            if rec.state != "pending":
                return False
            SessionLifecycle(rec).fire("time_out", reason=message, error=error)
            did.append(True)

        try:
            rec = self.workspace.update_session(session_id, fn)
        except (ProtocolError, LifecycleError):
            return 0
        if did:
            self._log(rec, "timed_out", f"{ec.TIMEOUT_QUEUE}: {message}")
        return int(bool(did))
