"""Recovery for a WatchdogSupervisor: a runner that died or was killed, or a supervisor
whose lease expired, leaves a target that may have moved; a fresh runner restores its
last checkpoint and halts it, and the session ends ``outcome_unknown`` (or as its cancel
or timeout says) for the verifier to judge."""

from __future__ import annotations

import logging
import time
from typing import Any

from phyagentos.errors import ProtocolError, SupervisorError
from phyagentos.protocol import LEASED_STATES, ErrorInfo, SessionRecord, is_expired, new_lease
from phyagentos.protocol import errorcodes as ec
from phyagentos.protocol.lifecycle import SessionLifecycle

from ..worker import RunnerDied
from .inflight import InflightSession

logger = logging.getLogger(__name__)

#: A session whose preflight killed the runner this many times is aborted, not retried.
_MAX_PREFLIGHT_DEATHS = 5


class Recovery:
    """Safe-stopping targets after a runner was lost.

    Mixed into :class:`~phyagentos.runtime.supervisor.WatchdogSupervisor`.
    """

    def _on_runner_died(self, inf: InflightSession) -> int:
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
            inf.fire("runner_lost")
        return 0

    def _recover_after_kill(self, inf: InflightSession, end: tuple[str, str, str]) -> int:
        inf.end = end
        inf.fire("runner_lost")
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
        inf = InflightSession(session_id=session_id, target=rec.target, token=lease.token, phase="recover_wait",
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

    def _start_recovery(self, inf: InflightSession) -> int:
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

    def _begin_recover_job(self, inf: InflightSession) -> None:
        status, code, message = inf.end
        inf.fire("recover")
        inf.deadline = time.monotonic() + self.config.recover_timeout_s
        try:
            self._runner.send("recover", root=str(self.workspace.root), session_id=inf.session_id,
                              status=status, error_code=code, message=message)
        except RunnerDied:
            self._kill_runner("died before recovery")
            inf.fire("runner_lost")

    def _on_recovered(self, inf: InflightSession, payload: dict) -> int:
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
