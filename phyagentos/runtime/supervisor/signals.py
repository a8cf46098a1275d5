"""RUNTIME_SIGNAL.md for a WatchdogSupervisor: pause and resume, e-stop and its clearing,
cancels of pending, waiting and in-flight sessions (it uses the supervisor's workspace,
config, runner and in-flight session)."""

from __future__ import annotations

import logging
import time

from phyagentos.errors import ProtocolError
from phyagentos.protocol import ErrorInfo, SessionRecord, SignalAck, file_identity
from phyagentos.protocol import errorcodes as ec
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now

from ..worker import RunnerDied
from .inflight import InflightSession

logger = logging.getLogger(__name__)


class SignalHandling:
    """Acting on RUNTIME_SIGNAL.md. Mixed into :class:`~phyagentos.runtime.supervisor.WatchdogSupervisor`."""

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

    def _begin_cancel(self, inf: InflightSession, code: str, reason: str, *, grace: float) -> None:
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
