"""Diagnosis: why an attempt failed, read from its evidence bundle into a fixed taxonomy.

Only evidence counts: the ground-truth snapshots before and after the session
(``initial.yaml``, ``terminal.yaml``), the trace the runtime recorded (what it perceived,
and on a simulated target the ground truth at that instant; which grasp it computed from
which perceived pose; what the gripper closed on), the runtime's outcome and the safety
and target events. The simulator's perturbation record (``perturbations.yaml``) is never
read: the cause is found from what was perceived versus what was there.

=====================  ============  =====================================================
cause                  category      evidence
=====================  ============  =====================================================
safety_intervention    safety        a ``safety.*`` event
timeout                timeout       runtime outcome ``timed_out``
precondition_unmet     execution     the skill needed the object in hand and it was not
perception_error       perception    the perceived pose the grasp (or place) used was more
                                     than :data:`PERCEPTION_TOL_M` off the ground truth at
                                     that observation (without ground truth in the trace:
                                     the initial snapshot, for the first observation)
object_moved           perception    perceived where it was, but the object ended more than
                                     :data:`MOVED_TOL_M` from there and was never grasped
object_slipped         execution     the gripper closed on the object, later it was gone
grasp_missed           execution     the gripper closed on nothing, perception was right
ik_unreachable         policy        ``ik.*`` error
planning_failed        policy        ``planning.*``, ``timing.*`` or ``motion.*`` error
collision              execution     a tracking error (``facts.variant``: ``planned`` for the
                                     planned transfer, ``cartesian`` for straight-line moves)
placement_off          execution     released, but not where the criteria ask
runtime_error          execution     the runtime raised (``target.error``, ...)
criteria_unmet         verifier      the runtime completed and nothing above explains it
=====================  ============  =====================================================

Categories follow the paper's error taxonomy (perception, policy, adapter, execution,
timeout, safety, verifier). Rules are applied in the order of the table.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from phyagentos.protocol import Diagnosis, SessionRecord

__all__ = ["CAUSES", "PERCEPTION_TOL_M", "MOVED_TOL_M", "diagnose", "subject_object"]

#: cause -> (category, one-line meaning)
CAUSES: dict[str, tuple[str, str]] = {
    "safety_intervention": ("safety", "a SafetyGuard intervention stopped the session"),
    "timeout": ("timeout", "the execution deadline passed"),
    "precondition_unmet": ("execution", "the session started without what it needs (the object in hand)"),
    "perception_error": ("perception", "the perceived object pose used for the motion was off"),
    "object_moved": ("perception", "the object moved after it was observed (stale observation)"),
    "object_slipped": ("execution", "the object slipped out of, or dropped from, the grasp"),
    "grasp_missed": ("execution", "the gripper closed on nothing although perception was right"),
    "ik_unreachable": ("policy", "no joint configuration reaches the required pose"),
    "planning_failed": ("policy", "no collision-free path or timing was found"),
    "collision": ("execution", "unexpected contact stopped a motion"),
    "placement_off": ("execution", "the object was released, but not where the criteria ask"),
    "runtime_error": ("execution", "the runtime raised an error"),
    "criteria_unmet": ("verifier", "the runtime completed, the criteria are not met, no finer cause found"),
}

#: Perceived-versus-true object position error (horizontal) above which perception is
#: blamed, m. Grasps of a 4 cm box tolerate about 2.5 cm (measured on the tabletop
#: scene: 3 cm along the fingers still grasps, 2.5 cm across them lands a finger on top).
PERCEPTION_TOL_M = 0.015
#: Horizontal displacement of an object during a session above which it "moved", m.
MOVED_TOL_M = 0.015


def _xy_dist(a: Sequence[float], b: Sequence[float]) -> float:
    a, b = (x["position"] if isinstance(x, dict) else x for x in (a, b))  # CONTRACT_9 observe entries
    return math.hypot(float(a[0]) - float(b[0]), float(a[1]) - float(b[1]))


def _entity(snapshot: Mapping, name: str) -> Mapping | None:
    return next((e for e in snapshot.get("entities", []) if e.get("name") == name), None)


def _holding(snapshot: Mapping, name: str) -> bool:
    return any(r.get("relation") == "holding" and r.get("object") == name for r in snapshot.get("relations", []))


def subject_object(session: SessionRecord) -> str | None:
    """The object a session manipulates: its ``object`` parameter, else the first
    object an acceptance criterion names."""
    obj = session.parameters.get("object")
    if isinstance(obj, str):
        return obj
    items = session.accept.items() if isinstance(session.accept, Mapping) else \
        [kv for d in session.accept for kv in d.items()]
    for _, args in items:
        if isinstance(args, str):
            return args
        if isinstance(args, Mapping) and isinstance(args.get("object"), str):
            return args["object"]
    return None


def _make(cause: str, summary: str, facts: dict, evidence: Sequence[str]) -> Diagnosis:
    return Diagnosis(cause=cause, category=CAUSES[cause][0], summary=summary,
                     facts={k: (round(v, 4) if isinstance(v, float) else v) for k, v in facts.items()},
                     evidence=list(evidence))


def diagnose(session: SessionRecord, evidence: Any) -> Diagnosis:
    """Diagnose an unsuccessful attempt of ``session`` from its :class:`EvidenceBundle`.

    Returns a :class:`~phyagentos.protocol.Diagnosis` whose ``facts`` hold the measured
    quantities (metres) and whose ``evidence`` lists the files consulted. Never raises
    on incomplete evidence: missing parts make rules not apply, down to
    ``criteria_unmet``.
    """
    refs = list(evidence.refs("initial", "terminal", "trace", "events"))
    outcome = evidence.outcome or {}
    code = str(outcome.get("error_code") or "")
    leaf = str(outcome.get("failed_primitive") or "")
    facts: dict[str, Any] = {"runtime_status": outcome.get("status"), "error_code": code or None,
                             "failed_primitive": leaf or None}

    safety = [str(e.get("code")) for e in evidence.events if str(e.get("code", "")).startswith("safety.")]
    if safety:
        return _make("safety_intervention", f"SafetyGuard intervened: {', '.join(sorted(set(safety)))}",
                     {**facts, "violations": sorted(set(safety))}, refs)
    if outcome.get("status") == "timed_out" or code.startswith("timeout."):
        return _make("timeout", "the execution deadline passed before the skill finished", facts, refs)

    obj = subject_object(session)
    facts["object"] = obj
    e0 = _entity(evidence.initial, obj) if obj else None
    eT = _entity(evidence.terminal, obj) if obj else None
    trace = list(evidence.trace)
    observations = [r for r in trace if r.get("kind") == "observe" and obj in (r.get("objects") or {})]
    grasps = [r for r in trace if r.get("kind") == "grasp_pose" and r.get("object") == obj]
    closes = [i for i, r in enumerate(trace) if r.get("kind") == "gripper" and r.get("command") == "close"]
    grasped = bool(closes) and trace[closes[-1]].get("grasped") == obj
    released_after = bool(closes) and any(r.get("kind") == "gripper" and r.get("command") == "open"
                                          for r in trace[closes[-1] + 1:])
    held_at_start = bool(obj) and _holding(evidence.initial, obj)
    held_at_end = eT is not None and _holding(evidence.terminal, obj)
    tcp = _entity(evidence.terminal, "tcp")
    if tcp is not None:
        facts["tcp_end_z_m"] = float(tcp["position"][2])  # how low the hand was left (recovery backs off)
    moved = None
    if e0 is not None and eT is not None:
        moved = _xy_dist(e0["position"], eT["position"])
        facts["object_moved_m"] = moved

    if code == "grasp.slipped" and not held_at_start and not closes:
        return _make("precondition_unmet", f"{obj} was not in the gripper when the session started", facts, refs)

    # Perception: the pose a motion was computed from versus where the object was when
    # it was observed (the simulator's ground truth in the trace; on a real robot, the
    # initial snapshot for the first observation). A held object's pose is perceived
    # too (placing uses it), so the same test applies.
    if observations:
        used_obs = observations[0]
        if grasps and "observed_position" in grasps[-1]:
            used = grasps[-1]["observed_position"]
            used_obs = next((o for o in reversed(observations) if _xy_dist(o["objects"][obj], used) < 1e-6),
                            observations[-1])
        perceived = used_obs["objects"][obj]
        truth = (used_obs.get("truth") or {}).get(obj)
        if truth is None and used_obs is observations[0] and e0 is not None:
            truth = e0["position"]
        if truth is not None:
            err = _xy_dist(perceived, truth)
            facts.update(perceived=list(perceived), true_at_observation=list(truth), perception_error_m=err)
            if err > PERCEPTION_TOL_M and not held_at_end:
                what = "the held " + obj if held_at_start else obj
                return _make("perception_error",
                             f"{what} was perceived {err * 100:.1f} cm from where it was "
                             f"(tolerance {PERCEPTION_TOL_M * 100:.1f} cm)", facts, refs)
            if not held_at_start and not grasped and eT is not None:
                after = _xy_dist(eT["position"], truth)
                facts["moved_after_observation_m"] = after
                if after > MOVED_TOL_M:
                    return _make("object_moved",
                                 f"{obj} was perceived where it was, then moved {after * 100:.1f} cm before the "
                                 f"gripper reached it", facts, refs)

    if code == "grasp.slipped" or (grasped and not held_at_end and not released_after and eT is not None):
        where = f"detected by {leaf}" if leaf else "found in the terminal snapshot"
        return _make("object_slipped", f"{obj} slipped out of the grasp ({where})", facts, refs)
    if code == "grasp.missed":
        return _make("grasp_missed", f"the gripper closed on nothing at {obj}'s perceived position", facts, refs)
    if code.startswith("ik."):
        return _make("ik_unreachable", f"{leaf or 'IK'}: {outcome.get('message', '')}".strip(), facts, refs)
    if code.startswith(("planning.", "timing.", "motion.")):
        return _make("planning_failed", f"{leaf or 'planning'}: {outcome.get('message', '')}".strip(), facts, refs)
    if code.startswith("execution."):
        # The planned transfer (the move_to subtree's "Execute" leaf) or a straight-line
        # move (approach, lift, lower ...): recovery differs.
        facts["variant"] = "planned" if leaf == "Execute" else "cartesian"
        return _make("collision", f"{leaf or 'execution'}: {outcome.get('message', '')}".strip(), facts, refs)
    if code:
        return _make("runtime_error", f"{code}: {outcome.get('message', '')}".strip(), facts, refs)
    if eT is not None and obj and not _holding(evidence.terminal, obj) and (held_at_start or (moved or 0.0) > MOVED_TOL_M):
        return _make("placement_off", f"{obj} was released where the criteria do not accept it", facts, refs)
    return _make("criteria_unmet", "the runtime completed but the acceptance criteria are not met", facts, refs)
