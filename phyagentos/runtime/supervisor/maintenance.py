"""Periodic maintenance of a WatchdogSupervisor: expired leases taken over, queue timeouts,
cancels of pending sessions, and the reconcile of the state hints with the session files."""

from __future__ import annotations

import logging
import time

from phyagentos.errors import LifecycleError, ProtocolError
from phyagentos.protocol import LEASED_STATES, ErrorInfo, SessionRecord, is_expired
from phyagentos.protocol import errorcodes as ec
from phyagentos.protocol.lifecycle import SessionLifecycle

logger = logging.getLogger(__name__)


class Maintenance:
    """Expired leases, queue timeouts, reconcile.

    Mixed into :class:`~phyagentos.runtime.supervisor.WatchdogSupervisor`.
    """

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
