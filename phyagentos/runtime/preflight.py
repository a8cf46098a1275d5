"""RuntimeCompatibilityPreflight: can this session run on this target with this runtime?

Runs before any target access. Reads only protocol documents (TARGETS.md,
SKILLRUNTIME.md, ``safety.yaml``), the skill manifest (and its tree), the static
description of the target driver and its TargetAdapter (class attributes), and, for
a policy skill, the policy server's metadata (the endpoint is actually contacted,
with a timeout). A rejected session never constructs or touches a target. Every
problem becomes a :class:`RejectionItem` ``{code, field, expected, found, fix}``; all
of them are reported, not just the first.

Checks:

- the target, runtime and skill exist and agree (kind, runtime name, parameters,
  capabilities, observation modalities);
- behaviour-tree skills: the tree builds and its primitives' tools exist;
- policy skills: the policy declaration parses (adapter, inputs with dtypes and
  shapes, action representation and dimension), the endpoint answers the openpi
  handshake and its metadata agrees with the declaration, the target has a
  TargetAdapter, the declared control rate matches the scene's, the action bridges
  type-check from the policy's action spec (units, frame, joint order, gripper,
  padding, rate) to the target's, and the command rate and chunk duration fit
  ``safety.yaml``;
- permitted operations: the operations the session needs must be allowed by the
  target's tool policy (TARGETS.md ``constraints.tool_policy: {allow: [...], deny: [...]}``;
  a ``real_robot`` without an explicit allow-list gets only read-only operations), and
  operations that bypass the safety layers (:data:`NEVER_EXPOSED`) are never granted.

On success it returns an :class:`AdapterPlan` (runtime, policy adapter, target adapter,
ordered action bridges, action form, and for policies the resolved policy declaration
and the target's action spec) and a :class:`TargetToolManifest` (the operations this
session may invoke, nothing else).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from phyagentos.errors import PolicyError, SkillError
from phyagentos.protocol import RejectionItem, SessionRecord, SkillRuntimeDoc, TargetsDoc
from phyagentos.protocol.schemas import SafetyConfig
from phyagentos.targets.contract import capabilities_of

from .bridges import ActionSpec, BridgeChain
from .skills import SkillRegistry
from .trees import TreeLibrary

__all__ = [
    "AdapterPlan",
    "TargetToolManifest",
    "PreflightResult",
    "NEVER_EXPOSED",
    "READ_ONLY_OPERATIONS",
    "run_preflight",
    "tree_tools",
    "permitted_operations",
]

logger = logging.getLogger(__name__)

#: Operations no session is ever granted: they would bypass the bridges, the guard or
#: the target's own limits (raw SDK access, writing limits, disabling safety, clearing
#: an e-stop from inside a session).
NEVER_EXPOSED = frozenset({"raw_sdk", "set_ctrl", "disable_safety", "set_safety_limits", "clear_estop",
                           "load_state", "save_state"})
#: What a real robot without an explicit allow-list may do: look, not move.
READ_ONLY_OPERATIONS = ("observe", "query_state", "snapshot", "render")


@dataclass(frozen=True)
class AdapterPlan:
    """How actions flow from the skill runtime to the target.

    Attributes:
        skill_runtime: runtime name from SKILLRUNTIME.md (``builtin`` or ``policy``).
        policy_adapter: adapter for a policy model (``openpi``); ``None`` for the builtin runtime.
        target_adapter: adapter that encodes actions natively (e.g. ``mujoco_franka``).
        action_bridges: ordered bridge declarations ``{bridge, **params}`` between the
            runtime's and the target's action forms (empty: native actions).
        action_form: the action form the target receives (e.g. ``joint_trajectory``,
            ``joint_position_chunk``).
        policy: policy skills only: endpoint, settings, inputs, action spec, the
            server's metadata summary.
        target_action: policy skills only: the target's native action spec.
    """

    skill_runtime: str
    policy_adapter: str | None
    target_adapter: str
    action_bridges: tuple[Mapping[str, Any], ...]
    action_form: str
    policy: Mapping[str, Any] | None = None
    target_action: Mapping[str, Any] | None = None
    agent: Mapping[str, Any] | None = None  # agent-directed skills: {operations} granted to the model

    def to_dict(self) -> dict:
        d = {"skill_runtime": self.skill_runtime, "policy_adapter": self.policy_adapter,
             "target_adapter": self.target_adapter, "action_bridges": [dict(b) for b in self.action_bridges],
             "action_form": self.action_form}
        if self.policy is not None:
            d["policy"] = _plain(self.policy)
            d["target_action"] = _plain(self.target_action)
        if self.agent is not None:
            d["agent"] = _plain(self.agent)
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


def _plain(x: Any) -> Any:
    """Plain dicts/lists/scalars (YAML source maps and tuples included) for the session file."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if hasattr(x, "item") and callable(x.item):
        return x.item()
    return x


def tree_tools(root) -> set[str]:
    """Union of the target tools (``TOOLS`` class attribute) the tree's primitives use."""
    tools: set[str] = set()
    for node in root.iterate():
        tools |= set(getattr(node, "TOOLS", ()))
    return tools


def permitted_operations(target_kind: str, constraints: Mapping[str, Any], offered: set[str]) -> tuple[set[str], list[str]]:
    """The operations the target's tool policy allows, and problems with the policy itself.

    ``offered`` is what the driver and its adapters can do. The policy
    (``constraints.tool_policy``) may narrow it with ``allow`` / ``deny``; without an
    allow-list a ``real_robot`` is limited to :data:`READ_ONLY_OPERATIONS`.
    :data:`NEVER_EXPOSED` is removed in every case; ``halt`` is always allowed.
    """
    problems: list[str] = []
    policy = constraints.get("tool_policy") or {}
    if not isinstance(policy, Mapping):
        return set(), [f"tool_policy must be a mapping with allow/deny lists, got {policy!r}"]
    allow = policy.get("allow")
    deny = set(policy.get("deny") or ())
    if allow is None:
        allowed = set(offered) if target_kind != "real_robot" else set(READ_ONLY_OPERATIONS) & set(offered)
    else:
        allowed = set(allow) & set(offered)
        for op in sorted(set(allow) & NEVER_EXPOSED):
            problems.append(f"tool_policy allows {op!r}, which is never exposed")
    # Stopping is never withheld, whatever the policy says.
    return (allowed - deny - NEVER_EXPOSED) | ({"halt"} & set(offered)), problems


def run_preflight(
    session: SessionRecord,
    *,
    targets: TargetsDoc,
    runtimes: SkillRuntimeDoc,
    skills: SkillRegistry,
    trees: TreeLibrary,
    drivers: Mapping[str, type],
    safety: SafetyConfig | None = None,
    probe: Callable[..., dict] | None = None,
    root: Any = None,
) -> PreflightResult:
    """Check every requirement of ``session``; never touches a target.

    Args:
        session: the claimed session.
        targets, runtimes: the workspace's TARGETS.md and SKILLRUNTIME.md data.
        skills, trees: skill manifests and the tree library.
        drivers: target driver name -> target class; classes declare ``KIND``,
            ``TOOLS`` and ``ACTION_FORMS`` as class attributes.
        safety: the workspace's ``safety.yaml`` (defaults when ``None``).
        probe: ``probe(uri, timeout_s=...) -> metadata`` contacting a policy endpoint
            (default :func:`phyagentos.policy.client.probe_endpoint`).
        root: the workspace root (mesh objects of the session's scene are read from it).

    Returns:
        A :class:`PreflightResult`; ``rejections`` lists every missing item.
    """
    items: list[RejectionItem] = []
    safety = safety if safety is not None else SafetyConfig()

    def reject(code: str, field_: str, expected: str, found: str, fix: str) -> None:
        items.append(RejectionItem(code=code, field=field_, expected=str(expected), found=str(found), fix=fix))

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

    if manifest is not None and manifest.runtime == "policy":
        plan, needed = _policy_checks(session, manifest, target, runtime, driver, safety, probe, reject,
                                         root)
    elif manifest is not None and manifest.runtime == "agent":
        plan, needed = _agent_checks(target, runtime, driver, reject)
    else:
        plan, needed = _tree_checks(session, manifest, target, runtime, driver, trees, reject)

    if target is not None and driver is not None and needed is not None:
        offered = set(driver.TOOLS) | _adapter_operations(target.driver)
        allowed, policy_problems = permitted_operations(target.kind, target.constraints, offered)
        for problem in policy_problems:
            reject("preflight.tool_policy", f"targets.{target.name}.constraints.tool_policy", "no never-exposed operation",
                   problem, f"remove it; never exposed: {sorted(NEVER_EXPOSED)}")
        for op in sorted(needed):
            if op in NEVER_EXPOSED:
                reject("preflight.operation_forbidden", f"skills.{session.skill}", "operations within the safety boundary",
                       op, "this operation is never exposed to a session")
            elif op not in offered:
                reject("preflight.tool_missing", f"targets.{session.target}.tools", op, ", ".join(sorted(offered)),
                       "use a target that exposes this operation")
            elif op not in allowed:
                reject("preflight.operation_not_permitted", f"targets.{session.target}.constraints.tool_policy", op,
                       ", ".join(sorted(allowed)) or "none",
                       "allow the operation in the target's tool policy (an operator decision)")

    if items:
        logger.info("session %s rejected in preflight: %s", session.session_id, [i.code for i in items])
        return PreflightResult(rejections=tuple(items))
    assert target is not None and plan is not None and needed is not None
    return PreflightResult(plan=plan, manifest=TargetToolManifest(target=target.name, operations=tuple(sorted(needed))))


def _adapter_operations(driver_name: str) -> set[str]:
    from .target_adapters import TARGET_ADAPTERS  # noqa: PLC0415

    adapter = TARGET_ADAPTERS.get(driver_name)
    return set(adapter.OPERATIONS) | {"render"} if adapter is not None else set()


def _agent_checks(target, runtime, driver, reject):
    """Agent-directed skills: the operations the model may choose from, and a shared action form."""
    from .agent_runtime import AGENT_OPERATIONS  # noqa: PLC0415

    if runtime is None or driver is None or target is None:
        return None, set(AGENT_OPERATIONS)
    offered = set(capabilities_of(driver).action_forms)
    forms = [f for f in runtime.action_forms if f in offered]
    if not forms:
        reject("preflight.action_form", f"targets.{target.name}.driver", f"one of {runtime.action_forms}",
               ", ".join(sorted(offered)) or "none", "choose a target with a compatible action form")
        return None, set(AGENT_OPERATIONS)
    ops = sorted(AGENT_OPERATIONS)
    plan = AdapterPlan(skill_runtime=runtime.name, policy_adapter=None, target_adapter=target.driver,
                       action_bridges=(), action_form=forms[0], agent={"operations": ops})
    return plan, set(ops)


def _tree_checks(session, manifest, target, runtime, driver, trees, reject):
    """Behaviour-tree skills: the tree builds, its tools exist, an action form is shared."""
    root = None
    if manifest is not None:
        try:
            root = trees.build(manifest.tree, session.parameters)
        except SkillError as exc:
            reject("preflight.tree_invalid", f"skills.{manifest.name}.tree", "a tree that builds", str(exc), "fix the tree file")
    forms: list[str] = []
    if runtime is not None and driver is not None and target is not None:
        offered = set(capabilities_of(driver).action_forms)
        forms = [f for f in runtime.action_forms if f in offered]
        if not forms:
            reject("preflight.action_form", f"targets.{target.name}.driver", f"one of {runtime.action_forms}",
                   ", ".join(sorted(offered)) or "none", "add an action bridge or choose a compatible target")
    if root is None or target is None or runtime is None or not forms:
        return None, (tree_tools(root) if root is not None else None)
    plan = AdapterPlan(skill_runtime=runtime.name, policy_adapter=None, target_adapter=target.driver,
                       # builtin primitives emit the target's native joint order and units
                       action_bridges=(), action_form=forms[0])
    return plan, tree_tools(root)


def _policy_checks(session, manifest, target, runtime, driver, safety, probe, reject, root=None):
    """Policy skills: declaration, endpoint, observation contract, bridges, rates."""
    from phyagentos.policy.adapter import ADAPTERS, InputSpec  # noqa: PLC0415
    from phyagentos.policy.client import probe_endpoint  # noqa: PLC0415
    from phyagentos.targets.scene import SceneSpec  # noqa: PLC0415

    from .policy_runtime import PolicySettings  # noqa: PLC0415
    from .target_adapters import TARGET_ADAPTERS  # noqa: PLC0415
    from .target_pool import scene_for  # noqa: PLC0415

    decl = manifest.policy or {}
    where = f"skills.{manifest.name}.policy"
    ok = True

    adapter_name = decl.get("adapter")
    if adapter_name not in ADAPTERS:
        reject("preflight.policy_adapter", f"{where}.adapter", f"one of {sorted(ADAPTERS)}", adapter_name,
               "declare a known PolicyAdapter")
        ok = False
    inputs: dict[str, Any] = {}
    raw_inputs = decl.get("inputs")
    if not isinstance(raw_inputs, Mapping) or not raw_inputs:
        reject("preflight.observation_contract", f"{where}.inputs", "a mapping of model input keys", repr(raw_inputs),
               "declare the model's inputs (source, dtype, shape)")
        ok = False
    else:
        for key, d in raw_inputs.items():
            try:
                inputs[key] = InputSpec.from_dict(key, d)
            except ValueError as exc:
                reject("preflight.observation_contract", f"{where}.inputs.{key}", "source, dtype and shape", str(exc),
                       "fix the input declaration")
                ok = False

    runtime_params = dict(runtime.parameters) if runtime is not None else {}
    presets = dict(runtime.presets) if runtime is not None else {}
    settings = None
    try:
        settings = PolicySettings.resolve(runtime_params, session.parameters, decl.get("endpoint"), presets)
    except (ValueError, TypeError) as exc:
        reject("preflight.policy_settings", "parameters", "valid policy settings", str(exc),
               "fix the session parameters or SKILLRUNTIME.md's policy parameters")
        ok = False
    preset = presets.get(session.parameters.get("policy_preset")) or {}
    if preset.get("skill") not in (None, manifest.name):
        reject("preflight.policy_preset", "parameters.policy_preset", f"a preset for skill {manifest.name!r}",
               f"{session.parameters.get('policy_preset')!r} (for skill {preset.get('skill')!r})",
               f"run skill {preset.get('skill')!r} with this preset, or pick another preset")
        ok = False
    horizon_of_preset = preset.get("action_horizon")
    if settings is not None and isinstance(horizon_of_preset, int) and settings.chunk_mode == "buffered" \
            and settings.replan_every > horizon_of_preset:
        reject("preflight.policy_settings", "parameters.replan_every",
               f"at most the preset's action horizon ({horizon_of_preset} steps)", str(settings.replan_every),
               "execute fewer steps per chunk (openpi's LIBERO example replans every 5)")
        ok = False

    # The endpoint is contacted for real: handshake and metadata within the timeout.
    metadata: dict[str, Any] | None = None
    endpoint = (session.parameters.get("policy_endpoint") or decl.get("endpoint") or preset.get("endpoint")
                or runtime_params.get("endpoint"))
    if endpoint:
        timeout = min(float(runtime_params.get("probe_timeout_s", 2.0)), session.limits.preflight_timeout_s)
        try:
            metadata = (probe or probe_endpoint)(str(endpoint), timeout_s=timeout)
        except PolicyError as exc:
            reject("preflight.endpoint_unreachable", "policy_endpoint",
                   f"a policy server answering the openpi websocket handshake within {timeout} s", str(exc),
                   "start it (phyagentos policy serve --port N) or fix policy_endpoint")
            ok = False

    # Action representation: the declaration, cross-checked with the server's metadata.
    policy_spec = None
    declared = decl.get("action")
    served = metadata.get("action") if isinstance(metadata, Mapping) else None
    if declared is None and served is None:
        reject("preflight.action_underspecified", f"{where}.action", "the policy's action space, joint names, units, "
               "gripper convention and rate", "nothing (neither the skill nor the server declares it)",
               "declare policy.action in the skill")
        ok = False
    else:
        try:
            policy_spec = ActionSpec.from_dict(declared if declared is not None else served, where=f"{where}.action")
        except ValueError as exc:
            reject("preflight.action_spec", f"{where}.action", "a complete action declaration", str(exc),
                   "fix the action declaration")
            ok = False
        if policy_spec is not None and declared is not None and isinstance(served, Mapping):
            try:
                served_spec = ActionSpec.from_dict(served, where="policy server metadata.action")
            except ValueError as exc:
                reject("preflight.policy_metadata", "policy server metadata.action", "a complete action declaration",
                       str(exc), "fix the server's metadata")
                served_spec = None
            if served_spec is not None:
                for name in ("space", "joint_names", "units", "frame", "gripper", "rate_hz", "padding", "dim"):
                    have, want = getattr(served_spec, name), getattr(policy_spec, name)
                    if have != want:
                        reject("preflight.policy_action_mismatch", f"{where}.action.{name}", f"{want!r} (skill)",
                               f"{have!r} (policy server)", "make the skill's declaration match the served policy")
                        ok = False
    horizon = metadata.get("action_horizon") if isinstance(metadata, Mapping) else None
    if isinstance(metadata, Mapping):
        for key, spec in (metadata.get("inputs") or {}).items():
            mine = inputs.get(key)
            want = f"{spec.get('dtype')} {list(spec.get('shape') or [])}"
            if mine is None:
                reject("preflight.observation_contract", f"{where}.inputs.{key}", f"an input {key!r} ({want}) the "
                       "policy requires", "not declared", "declare it with a source from the observation contract")
                ok = False
            elif (mine.dtype, list(mine.shape or [])) != (spec.get("dtype"), list(spec.get("shape") or [])):
                reject("preflight.observation_contract", f"{where}.inputs.{key}", want, f"{mine.dtype} {list(mine.shape or [])}",
                       "declare the dtype and shape the policy expects")
                ok = False

    # Observation modalities and shapes the target can produce.
    if inputs and adapter_name in ADAPTERS:
        adapter = ADAPTERS[adapter_name](inputs)
        if target is not None:
            for modality in sorted(adapter.modalities()):
                if modality not in target.observations:
                    reject("preflight.observation_missing", f"targets.{target.name}.observations", modality,
                           ", ".join(target.observations) or "none",
                           "choose a target that provides this modality or a policy that does not need it")
                    ok = False
        for key, expected, found in adapter.problems():
            reject("preflight.observation_shape", f"{where}.inputs.{key}", expected, found, "fix the input's dtype/shape")
            ok = False

    # The target side: adapter, control rate, action spec.
    tadapter = TARGET_ADAPTERS.get(target.driver) if target is not None else None
    target_spec = None
    if target is not None and tadapter is None:
        reject("preflight.target_adapter_missing", f"targets.{target.name}.driver",
               f"a driver with a TargetAdapter ({sorted(TARGET_ADAPTERS)})", target.driver,
               "register a TargetAdapter for this driver")
        ok = False
    fixed_rate = getattr(tadapter, "FIXED_RATE_HZ", None) if tadapter is not None else None
    if target is not None and tadapter is not None and fixed_rate is not None:
        # The driver fixes this action form's rate (LIBERO's OSC at 20 Hz); TARGETS.md's
        # action block describes the builtin flow's joint servos on the same target.
        rate = float(fixed_rate)
        target_spec = tadapter.native_spec(rate)
        if rate > safety.max_command_rate_hz:
            reject("preflight.safety_rate", "safety.yaml max_command_rate_hz", f">= {rate:g} Hz (the target's control rate)",
                   f"{safety.max_command_rate_hz:g} Hz", "raise the limit in safety.yaml (an operator decision) or slow the target")
            ok = False
    elif target is not None and tadapter is not None:
        try:
            timestep = scene_for(session, target, root=root).timestep
        except Exception as exc:  # noqa: BLE001 - a scene that does not parse is a rejection, not a crash
            reject("preflight.scene", "scene", "a valid scene", str(exc), "fix the session's scene")
            timestep = SceneSpec().timestep
            ok = False
        rate = tadapter.control_rate_hz(timestep)
        declared_rate = target.action.get("control_rate_hz")
        if declared_rate is None or not math.isclose(float(declared_rate), rate, rel_tol=1e-6):
            reject("preflight.control_rate", f"targets.{target.name}.action.control_rate_hz", f"{rate:g} Hz (1 / scene timestep)",
                   f"{declared_rate}", "declare the rate the target really runs at")
            ok = False
        if target.action.get("space") not in (None, "joint_position"):
            reject("preflight.action_form", f"targets.{target.name}.action.space", "joint_position",
                   target.action.get("space"), "use a target adapter for this action space")
            ok = False
        target_spec = tadapter.native_spec(rate)
        if rate > safety.max_command_rate_hz:
            reject("preflight.safety_rate", "safety.yaml max_command_rate_hz", f">= {rate:g} Hz (the target's control rate)",
                   f"{safety.max_command_rate_hz:g} Hz", "raise the limit in safety.yaml (an operator decision) or slow the target")
            ok = False

    bridges = None
    raw_bridges = decl.get("bridges") or []
    try:
        bridges = BridgeChain.from_declarations(raw_bridges)
    except ValueError as exc:
        reject("preflight.action_bridge", f"{where}.bridges", "known bridges with valid parameters", str(exc),
               "fix the bridge declaration")
        ok = False
    if bridges is not None and policy_spec is not None and target_spec is not None:
        for m in bridges.check(policy_spec, target_spec):
            reject("preflight.action_bridge", f"{where}.{m.field}", m.expected, m.found, m.fix)
            ok = False
    if policy_spec is not None and settings is not None and isinstance(horizon, int) and horizon > 0:
        executed = settings.steps_per_chunk(horizon) / policy_spec.rate_hz
        if executed > safety.max_command_duration_s:
            reject("preflight.safety_duration", "chunk_mode", f"chunks of at most {safety.max_command_duration_s} s",
                   f"{executed:g} s per executed chunk", "execute fewer steps per chunk (chunk_mode, replan_every)")
            ok = False

    if not ok or target is None or runtime is None or settings is None or policy_spec is None or target_spec is None:
        needed = set(tadapter.OPERATIONS) if tadapter is not None else None
        return None, needed
    needed = set(tadapter.OPERATIONS) | ({"render"} if "rgb" in adapter.modalities() or "depth" in adapter.modalities() else set())
    policy = {
        "endpoint": settings.endpoint,
        "settings": {k: getattr(settings, k) for k in settings.__dataclass_fields__},
        "instruction": str(decl.get("instruction", "")),
        "inputs": {k: s.to_dict() for k, s in inputs.items()},
        "action": policy_spec.to_dict(),
        "action_horizon": horizon,
        "max_opening_m": target_spec.max_opening_m,
        "preset": settings.preset,
        "server": {k: metadata.get(k) for k in ("policy", "description") if k in metadata} if metadata else {},
    }
    plan = AdapterPlan(skill_runtime=runtime.name, policy_adapter=adapter_name, target_adapter=target.driver,
                       action_bridges=tuple(bridges.describe()), action_form=tadapter.ACTION_FORM,
                       policy=policy, target_action=target_spec.to_dict())
    return plan, needed
