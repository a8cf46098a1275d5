"""Claims for a WatchdogSupervisor: the oldest claimable pending session (dependencies met,
target free and reserved by the runner, its world not held by another run), an in-flight
marker left by a crash resolved first, and the claim made durable with the start of its
preflight."""

from __future__ import annotations

import logging
import re
import time
from pathlib import Path

from phyagentos.errors import DocumentError, ProtocolError, SupervisorError
from phyagentos.protocol import LEASED_STATES, SESSION_ID_PATTERN, SessionRecord, is_expired, new_lease
from phyagentos.protocol.lifecycle import SessionLifecycle

from ..worker import RunnerDied
from .inflight import InflightSession

logger = logging.getLogger(__name__)

_TARGET_NAME = re.compile(SESSION_ID_PATTERN)  # TARGETS.md names follow the session-id pattern


class Claiming:
    """Claiming pending sessions. Mixed into :class:`~phyagentos.runtime.supervisor.WatchdogSupervisor`."""

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
        inf = InflightSession(session_id=session_id, target=rec.target, token=lease.token, phase="preflight",
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
