"""SessionRunner: owns one session's interaction with its target, tick by tick.

Started by the WatchdogSupervisor after preflight. It acquires the target in the
state the episode left it, snapshots the initial world, builds the skill's tree in
the BuiltinSkillRuntime, ticks it (checking the cancel token and the execution
deadline between ticks, beating the heartbeat after each), snapshots the terminal
world and writes the evidence bundle. It ends in ``awaiting_verification``: judging
the outcome is the SessionVerifier's job, never the controller's.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable

from phyagentos.errors import PhyAgentOSError
from phyagentos.primitives.context import CancelToken, SkillContext
from phyagentos.protocol import Attempt, dump_yaml, EnvironmentDoc, ErrorInfo, SessionRecord, Workspace
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now

from .builtin_runtime import BuiltinSkillRuntime, RunOutcome
from .target_pool import TargetPool

__all__ = ["SessionRunner", "write_environment"]

logger = logging.getLogger(__name__)


def write_environment(workspace: Workspace, snapshot: dict, *, target: str, session_id: str, evidence: list[str]) -> None:
    """Replace ENVIRONMENT.md's data with ``snapshot`` and bump its revision."""

    def apply(doc: EnvironmentDoc) -> EnvironmentDoc:
        return EnvironmentDoc(
            version=doc.version,
            revision=doc.revision + 1,
            target=target,
            session_id=session_id,
            captured_at=utc_now(),
            sim_time_s=snapshot.get("sim_time_s"),
            entities=snapshot.get("entities", []),
            relations=snapshot.get("relations", []),
            evidence=evidence,
        )

    workspace.update("ENVIRONMENT", apply)


@dataclass
class SessionRunner:
    """Runs one claimed, preflighted session to ``awaiting_verification``.

    Attributes:
        workspace: the protocol workspace.
        lifecycle: the session's statechart (state ``preflight_checking`` on entry).
        runtime: the BuiltinSkillRuntime that builds and ticks skill trees.
        targets: target pool carrying world state between sessions.
        owner: runner identity recorded in the attempt.
        cancel: cancellation token set by the supervisor.
        heartbeat: called after every tick (renews the lease).
    """

    workspace: Workspace
    lifecycle: SessionLifecycle
    runtime: BuiltinSkillRuntime
    targets: TargetPool
    owner: str
    cancel: CancelToken
    heartbeat: Callable[[], None] | None = None

    @property
    def record(self) -> SessionRecord:
        return self.lifecycle.record

    def run(self) -> RunOutcome:
        """Execute the session; returns the runtime outcome (not a verdict)."""
        rec = self.record
        spec = next(t for t in self.workspace.read("TARGETS").data.targets if t.name == rec.target)
        evidence_dir = self.workspace.evidence_dir(rec.session_id)
        rel = evidence_dir.relative_to(self.workspace.root).as_posix()
        rec.attempts.append(Attempt(number=len(rec.attempts) + 1, started_at=utc_now(), runner=self.owner))
        self.lifecycle.fire("start")
        started = time.perf_counter()
        target = None
        try:
            target = self.targets.acquire(rec, spec)
            initial = target.snapshot()
            atomic_write_text(evidence_dir / "initial.yaml", dump_yaml(initial))
            deadline = time.monotonic() + rec.limits.execution_timeout_s
            ctx = SkillContext(target=target, params=dict(rec.parameters), seed=rec.seed, cancel=self.cancel)
            ctx.on_observation = lambda snap: write_environment(
                self.workspace, snap, target=rec.target, session_id=rec.session_id, evidence=[f"{rel}/trace.jsonl"])
            outcome = self.runtime.run(rec.skill, ctx, deadline=deadline, heartbeat=self.heartbeat)
        except PhyAgentOSError as exc:
            logger.exception("session %s: runtime error", rec.session_id)
            outcome = RunOutcome(status="error", error_code="target.error", message=str(exc), ticks=0)
            ctx = None
            initial = None
        if outcome.status == "cancelled":
            self.lifecycle.fire("cancel", reason=self.cancel.reason)
        elif outcome.status == "timed_out":
            pass  # the deadline fires the transition after evidence is written
        else:
            self.lifecycle.fire("finish")
        terminal = target.snapshot() if target is not None else None
        if target is not None:
            if outcome.status in ("cancelled", "timed_out", "error"):
                target.halt()
            self.targets.release(rec, target)
        files = self._write_bundle(evidence_dir, rec, ctx, outcome, initial, terminal, time.perf_counter() - started)
        if terminal is not None:
            write_environment(self.workspace, terminal, target=rec.target, session_id=rec.session_id,
                              evidence=[f"{rel}/{files['terminal']}"])
        attempt = rec.attempts[-1]
        attempt.ended_at = utc_now()
        attempt.outcome = outcome.status
        attempt.evidence = rel
        attempt.timings = dict(ctx.profiler.totals) if ctx else {}
        if outcome.error_code:
            attempt.error = ErrorInfo(code=outcome.error_code, message=outcome.message)
        if outcome.status == "cancelled":
            self.lifecycle.fire("cancelled")
        elif outcome.status == "timed_out":
            self.lifecycle.fire("time_out", reason=outcome.message)
        else:
            # Completed, failed primitive or runtime error: the evidence decides.
            self.lifecycle.fire("submit")
        logger.info("session %s: runtime %s in %.2f s (%d ticks)", rec.session_id, outcome.status,
                    time.perf_counter() - started, outcome.ticks)
        return outcome

    def _write_bundle(self, directory, rec, ctx, outcome, initial, terminal, wall_s) -> dict:
        files = {"bundle": "bundle.yaml", "trace": "trace.jsonl", "events": "events.yaml"}
        if initial is not None:
            files["initial"] = "initial.yaml"
        if terminal is not None:
            files["terminal"] = "terminal.yaml"
            atomic_write_text(directory / "terminal.yaml", dump_yaml(terminal))
        events = list(ctx.events) if ctx else []
        atomic_write_text(directory / "events.yaml", dump_yaml(events))
        if ctx is not None:
            ctx.trace.write(directory / "trace.jsonl")
        else:
            (directory / "trace.jsonl").write_text("", encoding="utf-8")
        bundle = {
            "session_id": rec.session_id,
            "node": rec.node,
            "skill": rec.skill,
            "target": rec.target,
            "files": files,
            "outcome": {
                "status": outcome.status,
                "error_code": outcome.error_code,
                "failed_primitive": outcome.failed_primitive,
                "message": outcome.message,
                "ticks": outcome.ticks,
                "wall_time_s": round(wall_s, 4),
                "sim_time_s": terminal.get("sim_time_s") if terminal else None,
            },
            "timings_s": {k: round(v, 4) for k, v in (ctx.profiler.totals.items() if ctx else [])},
        }
        atomic_write_text(directory / "bundle.yaml", dump_yaml(bundle))
        return files
