"""The in-flight session of a WatchdogSupervisor, from preflight to its evidence: the
runner's replies, heartbeats, the preflight and execution deadlines, lease renewal, and
the session file's writes at each step."""

from __future__ import annotations

import logging
import time

from phyagentos.protocol import Attempt, ErrorInfo, RejectionItem, SessionRecord, renewed
from phyagentos.protocol import errorcodes as ec
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now

from ..session_basis import runtime_basis
from ..worker import RunnerDied
from .inflight import InflightSession

logger = logging.getLogger(__name__)


class Execution:
    """Servicing the in-flight session. Mixed into :class:`~phyagentos.runtime.supervisor.WatchdogSupervisor`."""

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
            inf.fire("runner_lost")
        if now >= inf.renew_at and self._inflight is inf:
            self._renew(inf, now)
        return acted

    def _watch_running(self, inf: InflightSession, now: float) -> int:
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

    def _execution_deadline_moved(self, inf: InflightSession, now: float) -> bool:
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

    def _renew(self, inf: InflightSession, now: float) -> None:
        healthy = True
        if inf.phase == "running" and self._runner is not None and inf.go_at is not None:
            healthy = now - max(self._runner.heartbeats.array[0], inf.go_at) < inf.limits.heartbeat_timeout_s
        if not healthy:
            return  # _watch_running ends it; an unhealthy runner does not keep its lease alive

        def fn(rec: SessionRecord):
            rec.lease = renewed(rec.lease, ttl_s=self.config.lease_s)

        if self._update(inf, fn) is not None:
            inf.renew_at = now + self.config.lease_s / 3

    def _on_message(self, inf: InflightSession, kind: str, payload: dict) -> int:
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
                inf.fire("runner_lost")
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

    def _on_preflight(self, inf: InflightSession, payload: dict) -> int:
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
        inf.fire("start")
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

    def _on_done(self, inf: InflightSession, payload: dict) -> int:
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

    def _finish_without_actuation(self, inf: InflightSession, event: str, code: str, message: str) -> int:
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

    def _release_to_pending(self, inf: InflightSession, why: str) -> int:
        def fn(rec: SessionRecord):
            SessionLifecycle(rec).fire("release", reason=why)
            rec.lease = None

        self._update(inf, fn)
        self.stats["released"] += 1
        self._end_inflight(inf, clear_marker=True)
        return 1

    def _end_inflight(self, inf: InflightSession, *, clear_marker: bool) -> None:
        self._unreserve(inf.target, session_id=inf.session_id, clear=clear_marker)
        if self._inflight is inf:
            self._inflight = None
