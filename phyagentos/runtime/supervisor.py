"""WatchdogSupervisor: the Runtime plane's single entry point for sessions.

It supervises rather than controls: it claims a pending session (atomically,
under the session's file lock, recording a lease), runs compatibility preflight,
hands the session to a :class:`SessionRunner`, renews the lease from the runner's
heartbeat, and writes results back. It never runs the observation-action loop
itself and never judges success (that is the Agent plane's SessionVerifier).
"""

from __future__ import annotations

import logging
import os
import socket
import time
import uuid
from dataclasses import dataclass, field

from phyagentos.protocol import Lease, LogEntry, SessionRecord, Workspace
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now

from .builtin_runtime import BuiltinSkillRuntime
from .preflight import run_preflight
from .runner import SessionRunner
from .target_pool import DRIVERS, TargetPool
from phyagentos.primitives.context import CancelToken

__all__ = ["WatchdogSupervisor"]

logger = logging.getLogger(__name__)


@dataclass
class WatchdogSupervisor:
    """Claims, preflights, runs and writes back sessions of one workspace.

    Attributes:
        workspace: the protocol workspace.
        runtime: the BuiltinSkillRuntime (skills and trees).
        owner: identity written into leases (default ``host:pid:random``).
        lease_s: lease duration in seconds, renewed on every runner heartbeat.
    """

    workspace: Workspace
    runtime: BuiltinSkillRuntime
    owner: str = field(default_factory=lambda: f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}")
    lease_s: float = 30.0
    targets: TargetPool | None = None

    def __post_init__(self) -> None:
        if self.targets is None:
            self.targets = TargetPool(self.workspace.root / "targets")

    # -- claiming --------------------------------------------------------

    def _dependencies_met(self, rec: SessionRecord, by_node: dict[str, list[SessionRecord]]) -> bool:
        return all(any(s.state == "succeeded" for s in by_node.get(dep, [])) for dep in rec.depends_on)

    def claimable(self) -> list[str]:
        """Ids of pending sessions whose dependency nodes have a succeeded session in the same run."""
        sessions = self.workspace.list_sessions()
        by_run_node: dict[tuple[str, str], list[SessionRecord]] = {}
        for s in sessions:
            by_run_node.setdefault((s.run_id, s.node), []).append(s)
        out = []
        for s in sessions:
            if s.state != "pending":
                continue
            by_node = {node: recs for (run, node), recs in by_run_node.items() if run == s.run_id}
            if self._dependencies_met(s, by_node):
                out.append(s.session_id)
        return sorted(out, key=lambda sid: next(s.created_at for s in sessions if s.session_id == sid))

    def claim(self, session_id: str) -> SessionLifecycle | None:
        """Atomically claim ``session_id``; ``None`` if someone else got it first."""
        with self.workspace.session_lock(session_id):
            rec = self.workspace.load_session(session_id)
            if rec.state != "pending":
                return None
            rec.lease = Lease(owner=self.owner, token=uuid.uuid4().hex, expires_at=time.time() + self.lease_s)
            lifecycle = SessionLifecycle(rec, persist=self.workspace.save_session)
            lifecycle.fire("claim", reason=f"by {self.owner}")
        self.workspace.append_log(LogEntry(at=utc_now(), session_id=session_id, node=rec.node, event="claimed",
                                           state=rec.state, message=f"owner {self.owner}"))
        return lifecycle

    # -- processing ------------------------------------------------------

    def process(self, lifecycle: SessionLifecycle) -> None:
        """Preflight and run one claimed session, leaving it for verification."""
        rec = lifecycle.record
        lifecycle.fire("preflight")
        result = run_preflight(
            rec,
            targets=self.workspace.read("TARGETS").data,
            runtimes=self.workspace.read("SKILLRUNTIME").data,
            skills=self.runtime.skills,
            trees=self.runtime.trees,
            drivers=DRIVERS,
        )
        if not result.ok:
            rec.rejection = list(result.rejections)
            lifecycle.fire("reject", reason=", ".join(sorted({i.code for i in result.rejections})))
            self._log(rec, "rejected", "; ".join(f"{i.code} {i.field}: expected {i.expected}, found {i.found}" for i in result.rejections))
            return
        rec.adapter_plan = result.plan.to_dict()
        rec.tool_manifest = result.manifest.to_dict()
        cancel = CancelToken()

        def heartbeat() -> None:
            # Renewing on every tick would fsync every 100 ms; renew at a third of the lease.
            if rec.lease is not None and rec.lease.expires_at - time.time() < self.lease_s * 2 / 3:
                rec.lease = Lease(owner=rec.lease.owner, token=rec.lease.token, expires_at=time.time() + self.lease_s)
                self.workspace.save_session(rec)

        runner = SessionRunner(self.workspace, lifecycle, self.runtime, self.targets, owner=self.owner, cancel=cancel,
                               heartbeat=heartbeat)
        outcome = runner.run()
        rec.lease = None
        self.workspace.save_session(rec)
        self._log(rec, f"runtime_{outcome.status}", outcome.message)

    def run_once(self) -> int:
        """Claim and process every currently claimable session; returns how many ran."""
        n = 0
        for session_id in self.claimable():
            lifecycle = self.claim(session_id)
            if lifecycle is None:
                continue
            self.process(lifecycle)
            n += 1
        return n

    def close(self) -> None:
        self.targets.close()

    def _log(self, rec: SessionRecord, event: str, message: str) -> None:
        self.workspace.append_log(LogEntry(at=utc_now(), session_id=rec.session_id, node=rec.node, event=event,
                                           state=rec.state, message=message))
