"""Availability gate: can every episode of a benchmark run at all?

Checked before a single session is written (paper, Section 4.4):

- ``runtime``: the skills and trees load, and every skill runtime a node names
  (``builtin``, ``policy``) is declared in SKILLRUNTIME.md;
- ``goal_graph``: each task's goal graph validates against the skills and targets, and
  its acceptance criteria parse;
- ``target``: each target a task uses is listed in TARGETS.md, enabled, has a
  registered driver, and *builds*: the driver constructs it on the task's first
  episode scene, resets it and returns a snapshot;
- ``preflight``: every node passes compatibility preflight (AdapterPlan and
  TargetToolManifest produced) exactly as the WatchdogSupervisor will run it.

A failed check is a diagnostic naming the task, the subject and the fix; any failure
stops the run before compilation, so there is never a partial result with silently
missing episodes.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from typing import Any, Sequence

from phyagentos.errors import PhyAgentOSError

__all__ = ["GateCheck", "GateReport", "run_gate"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class GateCheck:
    """One gate check: ``ok`` or a diagnostic in ``detail``."""

    check: str
    subject: str
    ok: bool
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def line(self) -> str:
        return f"[{self.check}] {self.subject}: {self.detail}"


@dataclass(frozen=True)
class GateReport:
    """All checks of one gate run; :attr:`ok` only if every check passed."""

    checks: tuple[GateCheck, ...]

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.checks)

    @property
    def problems(self) -> tuple[str, ...]:
        return tuple(c.line() for c in self.checks if not c.ok)

    def to_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "checks": [c.to_dict() for c in self.checks]}


def run_gate(workspace, suite, first_scenes: dict[str, dict]) -> GateReport:
    """Run every check for ``suite`` against the bench ``workspace``.

    Args:
        workspace: the bench :class:`~phyagentos.protocol.Workspace` (TARGETS.md,
            SKILLRUNTIME.md are read from it).
        suite: the :class:`~phyagentos.bench.suite.Suite`.
        first_scenes: task id -> scene of its first episode (the scene targets are built on).

    Returns:
        The :class:`GateReport`; never raises for a failed check.
    """
    from dataclasses import replace  # noqa: PLC0415

    from phyagentos.agent.criteria import parse_criteria  # noqa: PLC0415
    from phyagentos.app.orchestrator import load_graph_for  # noqa: PLC0415
    from phyagentos.protocol import SessionRecord  # noqa: PLC0415
    from phyagentos.protocol.lifecycle import utc_now  # noqa: PLC0415
    from phyagentos.resources import skills_dir, trees_dir  # noqa: PLC0415
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: PLC0415
    from phyagentos.runtime.preflight import run_preflight  # noqa: PLC0415
    from phyagentos.runtime.target_pool import scene_for  # noqa: PLC0415
    from phyagentos.targets.registry import DRIVERS  # noqa: PLC0415

    checks: list[GateCheck] = []
    targets_doc = workspace.read("TARGETS").data
    runtimes_doc = workspace.read("SKILLRUNTIME").data
    declared = [r.name for r in runtimes_doc.runtimes]
    try:
        runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
        checks.append(GateCheck("runtime", "skills", True, f"{len(runtime.skills.names())} skills, trees load"))
    except PhyAgentOSError as exc:
        checks.append(GateCheck("runtime", "skills", False, f"skills/trees do not load: {exc}"))
        return GateReport(tuple(checks))
    runtimes_seen: set[str] = set()

    for task in suite.tasks:
        built: set[str] = set()
        scene = first_scenes[task.id]
        try:
            graph = load_graph_for(workspace, task.goal_graph, runtime)
            graph = replace(graph, scene=scene)
            if task.target is not None:
                known = {t.name for t in targets_doc.targets}
                if task.target not in known:
                    raise PhyAgentOSError(f"target override {task.target!r} is not in TARGETS.md "
                                          f"(listed: {sorted(known)})")
                graph = replace(graph, nodes=tuple(replace(n, target=task.target) for n in graph.nodes))
            for node in graph.nodes:
                parse_criteria(node.accept, where=f"{task.goal_graph}:{node.line} accept")
            checks.append(GateCheck("goal_graph", task.id, True, str(task.goal_graph)))
        except PhyAgentOSError as exc:
            checks.append(GateCheck("goal_graph", task.id, False, str(exc)))
            continue

        for name in dict.fromkeys(n.target for n in graph.nodes):
            spec = next((t for t in targets_doc.targets if t.name == name), None)
            subject = f"{task.id}/{name}"
            if spec is None:
                checks.append(GateCheck("target", subject, False, "not listed in TARGETS.md"))
                continue
            if not spec.enabled:
                checks.append(GateCheck("target", subject, False,
                                        "disabled in TARGETS.md (enabled: false); enable it once it is safe to use"))
                continue
            cls = DRIVERS.get(spec.driver)
            if cls is None:
                checks.append(GateCheck("target", subject, False,
                                        f"driver {spec.driver!r} is not registered (registered: {sorted(DRIVERS)})"))
                continue
            if name in built:
                continue  # one build per target and task (a task's nodes share its scene)
            try:
                probe_session = SessionRecord(session_id="gate-probe", run_id="gate", node="gate", skill="gate",
                                              target=name, scene=scene, created_at=utc_now(), updated_at=utc_now())
                target = cls(name, scene_for(probe_session, spec, root=workspace.root), seed=0)
                try:
                    target.reset(seed=0)
                    snap = target.snapshot()
                finally:
                    target.close()
                built.add(name)
                checks.append(GateCheck("target", subject, True,
                                        f"driver {spec.driver} built; {len(snap.get('entities', []))} entities observed"))
            except Exception as exc:  # noqa: BLE001 - any failure to build is a diagnostic
                checks.append(GateCheck("target", subject, False, f"driver {spec.driver} does not build: "
                                        f"{type(exc).__name__}: {exc}"))

        for node in graph.nodes:
            if node.runtime not in runtimes_seen:
                runtimes_seen.add(node.runtime)
                ok = node.runtime in declared
                checks.append(GateCheck("runtime", node.runtime, ok, "declared in SKILLRUNTIME.md" if ok else
                                        f"not declared in SKILLRUNTIME.md (declared: {declared})"))
            now = utc_now()
            probe = SessionRecord(session_id=f"gate-{task.id}-{node.id}", run_id="gate", node=node.id,
                                  skill=node.skill, skill_runtime=node.runtime, target=node.target,
                                  parameters=dict(node.params), accept=node.accept, scene=scene,
                                  created_at=now, updated_at=now)
            result = run_preflight(probe, targets=targets_doc, runtimes=runtimes_doc, skills=runtime.skills,
                                   trees=runtime.trees, drivers=DRIVERS)
            subject = f"{task.id}/{node.id}"
            if result.ok:
                checks.append(GateCheck("preflight", subject, True,
                                        f"adapter {result.plan.target_adapter}, tools {list(result.manifest.operations)}"))
            else:
                for item in result.rejections:
                    checks.append(GateCheck("preflight", subject, False,
                                            f"{item.code} {item.field}: expected {item.expected}, found {item.found}; "
                                            f"fix: {item.fix}"))
    report = GateReport(tuple(checks))
    logger.info("availability gate: %s (%d checks)", "passed" if report.ok else "FAILED", len(checks))
    return report


def gate_lines(report: GateReport) -> Sequence[str]:
    """Human lines, one per check."""
    return [("ok   " if c.ok else "FAIL ") + c.line() for c in report.checks]
