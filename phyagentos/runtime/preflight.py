"""Compatibility preflight: can this session run on this target with this runtime?

Runs before any target access. Reads only protocol documents (TARGETS.md,
SKILLRUNTIME.md), the skill manifest and tree, and the static description of the
target driver (its class attributes), so a rejected session never constructs or
touches a target. Every problem becomes a :class:`RejectionItem`
``{code, field, expected, found, fix}``; all of them are reported, not just the first.

On success it returns an :class:`AdapterPlan` (which runtime, target adapter and
ordered action bridges carry the skill's actions to the target) and a
:class:`TargetToolManifest` (the target operations this session may invoke).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from typing import Mapping

from phyagentos.errors import SkillError
from phyagentos.protocol import RejectionItem, SessionRecord, SkillRuntimeDoc, TargetsDoc

from .skills import SkillRegistry
from .trees import TreeLibrary

__all__ = ["AdapterPlan", "TargetToolManifest", "PreflightResult", "run_preflight", "tree_tools"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class AdapterPlan:
    """How actions flow from the skill runtime to the target.

    Attributes:
        skill_runtime: runtime name from SKILLRUNTIME.md (e.g. ``builtin``).
        policy_adapter: adapter for a policy model; ``None`` for the builtin runtime.
        target_adapter: target driver that encodes actions natively (e.g. ``mujoco_franka``).
        action_bridges: ordered conversions between runtime and target action forms.
        action_form: the runtime's action form the target receives (e.g. ``joint_trajectory``).
    """

    skill_runtime: str
    policy_adapter: str | None
    target_adapter: str
    action_bridges: tuple[str, ...]
    action_form: str

    def to_dict(self) -> dict:
        d = asdict(self)
        d["action_bridges"] = list(self.action_bridges)
        return d


@dataclass(frozen=True)
class TargetToolManifest:
    """The target operations a session may invoke, and nothing else."""

    target: str
    operations: tuple[str, ...]

    def to_dict(self) -> dict:
        return {"target": self.target, "operations": list(self.operations)}


@dataclass(frozen=True)
class PreflightResult:
    """``ok`` with a plan and manifest, or the full list of rejection items."""

    plan: AdapterPlan | None = None
    manifest: TargetToolManifest | None = None
    rejections: tuple[RejectionItem, ...] = field(default_factory=tuple)

    @property
    def ok(self) -> bool:
        return not self.rejections


def tree_tools(root) -> set[str]:
    """Union of the target tools (``TOOLS`` class attribute) the tree's primitives use."""
    tools: set[str] = set()
    for node in root.iterate():
        tools |= set(getattr(node, "TOOLS", ()))
    return tools


def run_preflight(
    session: SessionRecord,
    *,
    targets: TargetsDoc,
    runtimes: SkillRuntimeDoc,
    skills: SkillRegistry,
    trees: TreeLibrary,
    drivers: Mapping[str, type],
) -> PreflightResult:
    """Check every requirement of ``session``; never touches a target.

    Args:
        session: the claimed session.
        targets, runtimes: the workspace's TARGETS.md and SKILLRUNTIME.md data.
        skills, trees: skill manifests and the tree library.
        drivers: target driver name -> target class; classes declare ``KIND``,
            ``TOOLS`` and ``ACTION_FORMS`` as class attributes.

    Returns:
        A :class:`PreflightResult`; ``rejections`` lists every missing item.
    """
    items: list[RejectionItem] = []

    def reject(code: str, field_: str, expected: str, found: str, fix: str) -> None:
        items.append(RejectionItem(code=code, field=field_, expected=expected, found=found, fix=fix))

    target = next((t for t in targets.targets if t.name == session.target), None)
    runtime = next((r for r in runtimes.runtimes if r.name == session.skill_runtime), None)
    manifest = skills.get(session.skill) if session.skill in skills else None

    if target is None:
        reject("preflight.target_unknown", "target", f"one of {[t.name for t in targets.targets]}", session.target,
               "add the target to TARGETS.md or fix the session's target")
    elif not target.enabled:
        reject("preflight.target_disabled", f"targets.{target.name}.enabled", "true", "false",
               "enable the target in TARGETS.md once it is safe to use")
    if runtime is None:
        reject("preflight.runtime_unknown", "skill_runtime", f"one of {[r.name for r in runtimes.runtimes]}",
               session.skill_runtime, "declare the runtime in SKILLRUNTIME.md")
    if manifest is None:
        reject("preflight.skill_unknown", "skill", f"one of {skills.names()}", session.skill, "add skills/<name>.yaml")
    if target is not None and runtime is not None and target.kind not in runtime.target_kinds:
        reject("preflight.runtime_target_kind", "target.kind", f"one of {runtime.target_kinds}", target.kind,
               f"pick a runtime that supports {target.kind} targets")
    driver = drivers.get(target.driver) if target is not None else None
    if target is not None and driver is None:
        reject("preflight.driver_unknown", f"targets.{target.name}.driver", f"one of {sorted(drivers)}", target.driver,
               "install or register the target driver")

    root = None
    if manifest is not None:
        if runtime is not None and manifest.runtime != runtime.name:
            reject("preflight.skill_runtime_mismatch", "skill_runtime", manifest.runtime, runtime.name,
                   f"run skill {manifest.name!r} on runtime {manifest.runtime!r}")
        for problem in manifest.check_params(session.parameters):
            reject("preflight.skill_params", "parameters", f"parameters of skill {manifest.name!r}", problem,
                   f"see {manifest.path}")
        if target is not None:
            for cap in manifest.capabilities:
                if cap not in target.capabilities:
                    reject("preflight.capability_missing", f"targets.{target.name}.capabilities", cap,
                           ", ".join(target.capabilities) or "none", "choose a target that declares this capability")
            for obs in manifest.observations:
                if obs not in target.observations:
                    reject("preflight.observation_missing", f"targets.{target.name}.observations", obs,
                           ", ".join(target.observations) or "none", "choose a target that provides this observation")
        try:
            root = trees.build(manifest.tree, session.parameters)
        except SkillError as exc:
            reject("preflight.tree_invalid", f"skills.{manifest.name}.tree", "a tree that builds", str(exc), "fix the tree file")

    if runtime is not None and driver is not None and target is not None:
        forms = set(getattr(driver, "ACTION_FORMS", ()))
        usable = [f for f in runtime.action_forms if f in forms]
        if not usable:
            reject("preflight.action_form", f"targets.{target.name}.driver", f"one of {runtime.action_forms}",
                   ", ".join(sorted(forms)) or "none", "add an action bridge or choose a compatible target")
    if root is not None and driver is not None:
        needed = tree_tools(root)
        offered = set(getattr(driver, "TOOLS", ()))
        for tool in sorted(needed - offered):
            reject("preflight.tool_missing", f"targets.{session.target}.tools", tool, ", ".join(sorted(offered)),
                   "use a target that exposes this operation")

    if items:
        logger.info("session %s rejected in preflight: %s", session.session_id, [i.code for i in items])
        return PreflightResult(rejections=tuple(items))
    assert target is not None and runtime is not None and root is not None
    forms = [f for f in runtime.action_forms if f in set(getattr(driver, "ACTION_FORMS", ()))]
    plan = AdapterPlan(
        skill_runtime=runtime.name,
        policy_adapter=None,
        target_adapter=target.driver,
        action_bridges=(),  # builtin primitives emit the target's native joint order and units
        action_form=forms[0],
    )
    manifest_out = TargetToolManifest(target=target.name, operations=tuple(sorted(tree_tools(root))))
    return PreflightResult(plan=plan, manifest=manifest_out)
