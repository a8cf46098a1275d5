"""The held-object model: where a grasped object is when the cameras cannot see it.

A hand that carries an object hides it from the cameras, so a perceived snapshot after a
lift often has no confident sighting of it (issue 9: ``lifted`` and ``holding`` were judged
``unknown`` while the hand held the object). A robot still knows what it holds from its own
sensors. This model reads only the evidence bundle -- the trace's gripper commands and
``proprio`` samples (opening per finger, finger effort, wrist load, and the tcp pose from
forward kinematics of the measured joint positions), the perceived position the grasp
aimed at, and the perceived snapshots -- and decides:

the gripper closed on ``obj`` (a ``close`` command for it, ``closed_on_something``), the
fingers were then at the object's perceived position (horizontal distance between the tcp
and the perceived centre at most :data:`CAPTURE_RADIUS_M`; for a grasp by a part of the object
away from its centre, ``grasp_kind`` one of :data:`PART_GRASPS` (a container's rim, a mug's
handle, a lid's knob), between the tcp and the point on that part the grasp aimed at), the opening per finger stays
above the empty-closed width with a 2-sigma margin (``> CLOSED_OPENING_M + 2 *
OPENING_STD_M``) and is no wider than the perceived object (largest horizontal half
extent + :data:`WIDTH_MARGIN_M`), nothing opened the gripper and no slip shows (no
``slip`` entry, the opening did not close by more than 3 mm, the wrist load did not fall
below half its peak: :func:`phyagentos.agent.diagnosis.slip_seen`), and after the lift the
wrist carries a load that matches a carried mass (at least :data:`MIN_HELD_LOAD_N` plus 2
sigma of the load, at most :data:`MAX_CARRIED_LOAD_N`, the arm's payload; and when the
terminal snapshot is later than the trace's last load sample, its wrist force still
carries at least half of it). Then the object moves rigidly with the gripper: with
``T_c`` the tcp pose at the close (4x4, world frame) and ``p_c`` the perceived centre the
grasp aimed at, its centre at the end is ``T_end @ inv(T_c) @ p_c`` with a 1-sigma
uncertainty ``sqrt(sigma_obs^2 + HOLD_STD_M^2)``.

A closed gripper with the opening below the empty-closed band, a gripper opened after
the close, or a slip make the model say *not held*. Anything else it cannot decide
(no close for the object, no tcp pose in the trace, an opening inside the 2-sigma band,
a load too small to tell from the unloaded hand, a runtime failure after the close) is
*unknown*. The model is consulted only where the cameras did not decide -- ``holding`` or
``lifted`` left ``unknown``, or ``holding`` judged ``unsatisfied`` for want of any sighting
(:func:`refine`) -- never to overturn what was seen, and its verdicts use the same 2-sigma
rule as :mod:`phyagentos.agent.criteria`: never ``satisfied`` inside the band.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping, Sequence

if TYPE_CHECKING:  # numpy is imported where a pose is computed: `run`'s cold start does not load it (issue 12)
    import numpy as np

from .criteria import CLOSED_OPENING_M, CONFIDENCE_MIN, Criterion, CriterionOutcome, confidence, sigma
from .diagnosis import slip_seen

__all__ = ["HeldEstimate", "estimate_held", "refine", "OPENING_STD_M", "HOLD_STD_M", "CAPTURE_RADIUS_M", "PART_GRASPS",
           "WIDTH_MARGIN_M", "MIN_HELD_LOAD_N", "LOAD_STD_FLOOR_N", "LOAD_STD_FRACTION", "MAX_CARRIED_LOAD_N",
           "MIN_LIFT_FOR_LOAD_M", "EMPTY_EFFORT_N"]

#: 1-sigma uncertainty of the measured opening per finger, m. Chosen, not measured: the
#: fingers' compliance under squeeze, several times the 0.01 mm the trace is rounded to.
OPENING_STD_M = 0.0005
#: 1-sigma in-hand displacement of a held object after the close, m: the object may slide
#: along the finger pads without leaving them (the Franka Hand's pads are about 2 cm long,
#: so +-1 cm at 2 sigma); the Runtime's perceiver allows the same 5 mm for a held object.
HOLD_STD_M = 0.005
#: The fingers closed on the object only if the tcp was within this horizontal distance of
#: the perceived centre the grasp aimed at, m (half the Franka Hand's 8 cm stroke).
CAPTURE_RADIUS_M = 0.02
#: Grasps (the trace's ``grasp_pose`` ``grasp_kind``) that close on a part of the object away from its
#: perceived centre: a container's wall at its rim (4-6 cm out on LIBERO's bowls), a mug's handle
#: (6-8 cm out from its cup's axis), a lid's knob. Their capture is judged at the grasp point the
#: skill planned from that part as perceived; the object's centre is still what is carried.
PART_GRASPS = ("rim", "handle", "top_knob")
#: An opening per finger wider than the object's largest perceived horizontal half
#: extent by more than this means something else is between the fingers, m (the
#: perceived sizes on randomised worlds are within about 5 mm of the object's).
WIDTH_MARGIN_M = 0.008
#: A carried object adds at least this much to the wrist load, N (about 10 g; the same
#: floor as the runtime's grasp check).
MIN_HELD_LOAD_N = 0.1
#: 1-sigma uncertainty of a static wrist-load reading: a floor plus a fraction of the load
#: (the arm is not perfectly still when it is read), N and fraction. Chosen, not measured.
LOAD_STD_FLOOR_N = 0.05
LOAD_STD_FRACTION = 0.05
#: Above this load the wrist is pushed by contact, not carrying: the Franka arm's
#: payload, 3 kg x 9.81 m/s^2 (Franka Emika Panda datasheet), N.
MAX_CARRIED_LOAD_N = 3.0 * 9.81
#: Finger effort below which the hand squeezes nothing, N (the runtime's grasp check uses
#: the same 1 N: ``phyagentos.primitives.grasp_sense.MIN_EFFORT_N``).
EMPTY_EFFORT_N = 1.0
#: A load sample counts as carrying only once the tcp has risen this far since the close, m
#: (before that the object still rests on, or presses into, its support).
MIN_LIFT_FOR_LOAD_M = 0.01


@dataclass(frozen=True)
class HeldEstimate:
    """What proprioception says about ``object`` at the end of the evidence.

    Attributes:
        object: the object's declared name.
        status: ``"held"``, ``"not_held"`` or ``"unknown"``.
        reason: one sentence with the numbers behind the status.
        position_m: (3,) m, the held object's centre in the world frame at the end, or
            ``None`` unless ``status == "held"``.
        position_std_m: 1-sigma uncertainty of ``position_m``, m.
        facts: the measurements used (opening, load, tcp rise ...), for the verdict's reason.
    """

    object: str
    status: str
    reason: str
    position_m: tuple[float, float, float] | None = None
    position_std_m: float | None = None
    facts: Mapping[str, Any] = field(default_factory=dict)


def _pose(position: Sequence[float] | None, quat: Sequence[float] | None) -> np.ndarray | None:
    if position is None or quat is None:
        return None
    from phyagentos.geometry import pose_matrix  # noqa: PLC0415

    return pose_matrix(position, quat)


def _entity(snapshot: Mapping, name: str) -> Mapping | None:
    return next((e for e in snapshot.get("entities", []) if e.get("name") == name), None)


def _kind(snapshot: Mapping, kind: str) -> Mapping | None:
    return next((e for e in snapshot.get("entities", []) if e.get("kind") == kind), None)


def _load_std(load_n: float) -> float:
    return LOAD_STD_FLOOR_N + LOAD_STD_FRACTION * abs(load_n)


def _last_close(trace: Sequence[Mapping], obj: str) -> int | None:
    for i in range(len(trace) - 1, -1, -1):
        r = trace[i]
        if r.get("kind") == "gripper" and r.get("command") == "close" and r.get("object") in (None, obj):
            return i
    return None


def _aim(trace: Sequence[Mapping], close: int, obj: str) -> tuple[list[float] | None, float | None]:
    """The perceived centre the grasp aimed at (the last ``grasp_pose`` before the close)
    and the 1-sigma of the observation behind it (the last ``observe`` of ``obj``); ``(None,
    None)`` when that observation's confidence is below :data:`CONFIDENCE_MIN`."""
    aim = std = None
    conf = 1.0
    for r in trace[:close]:
        if r.get("kind") == "grasp_pose" and r.get("object") == obj and r.get("observed_position") is not None:
            aim = [float(v) for v in r["observed_position"]]
        if r.get("kind") == "observe":
            seen = (r.get("objects") or {}).get(obj)
            if seen and seen.get("position_std_m") is not None:
                std = float(seen["position_std_m"])
                conf = float(seen.get("confidence", 1.0))
    if aim is not None and conf < CONFIDENCE_MIN:
        return None, None  # the grasp aimed at a sighting no better than a coin flip: maybe another object
    return aim, std


def estimate_held(evidence: Any, obj: str) -> HeldEstimate:
    """Decide from proprioception whether the gripper holds ``obj`` at the end of ``evidence``.

    Args:
        evidence: an :class:`~phyagentos.agent.verifier.EvidenceBundle` (``trace``,
            ``initial``, ``terminal``, ``outcome``).
        obj: the object's declared name.

    Returns:
        A :class:`HeldEstimate` (``held`` with the object's world-frame position and its
        uncertainty, ``not_held``, or ``unknown``); see the module docstring for the rule.
    """
    trace: Sequence[Mapping] = tuple(evidence.trace or ())
    unknown = lambda why, **f: HeldEstimate(obj, "unknown", why, facts=f)  # noqa: E731
    not_held = lambda why, **f: HeldEstimate(obj, "not_held", why, facts=f)  # noqa: E731
    close = _last_close(trace, obj)
    if close is None:
        return unknown(f"the trace has no close of the gripper on {obj}")
    rec = trace[close]
    after = trace[close + 1:]
    if any(r.get("kind") == "gripper" and r.get("command") == "open" for r in after):
        return not_held(f"the gripper opened after it closed on {obj}")
    closed_opening = rec.get("opening_m")
    if rec.get("closed_on_something") is False or (closed_opening is not None
                                                   and float(closed_opening) < CLOSED_OPENING_M - 2 * OPENING_STD_M):
        return not_held(f"the gripper closed on nothing (opening {1000 * float(closed_opening or 0.0):.1f} mm per "
                        f"finger, empty-closed below {1000 * CLOSED_OPENING_M:.1f} mm)")
    slip = slip_seen(trace, close + 1, obj)
    if slip is not None:
        return not_held(f"{obj} slipped after the close ({slip.get('slip_source')})", **slip)
    if any(r.get("kind") == "failure" for r in after):
        failure = next(r for r in after if r.get("kind") == "failure")
        return unknown(f"the runtime reported {failure.get('code')} after the close: proprioception is not trusted")

    samples = [r for r in after if r.get("kind") == "proprio"]
    at_close = next((r for r in samples if r.get("tcp_position_m") is not None), None)
    T_close = _pose(at_close.get("tcp_position_m"), at_close.get("tcp_quat_wxyz")) if at_close else None
    if T_close is None:
        return unknown("the trace records no tcp pose after the close (no forward kinematics to carry the object)")

    # the gripper now: the terminal snapshot's proprioception, else the last sample
    grip = _kind(evidence.terminal, "gripper") or {}
    gattrs = grip.get("attributes") or {}
    opening = gattrs.get("opening_m", samples[-1].get("opening_m"))
    if opening is None:
        return unknown("no gripper opening at the end of the evidence")
    opening = float(opening)
    if opening < CLOSED_OPENING_M - 2 * OPENING_STD_M:
        return not_held(f"the fingers closed to {1000 * opening:.1f} mm per finger: nothing between them",
                        opening_m=opening)
    if opening <= CLOSED_OPENING_M + 2 * OPENING_STD_M:
        return unknown(f"opening {1000 * opening:.1f} mm per finger is within 2 sigma "
                       f"({1000 * 2 * OPENING_STD_M:.1f} mm) of the empty-closed {1000 * CLOSED_OPENING_M:.1f} mm",
                       opening_m=opening)

    aim, obs_std = _aim(trace, close, obj)
    init = _entity(evidence.initial, obj)
    if aim is None and init is not None and confidence(init) >= CONFIDENCE_MIN:
        aim, obs_std = [float(v) for v in init["position"]], sigma(init)
    if aim is None:
        return unknown(f"no perceived position of {obj} before the close")
    obs_std = float(obs_std if obs_std is not None else (sigma(init) if init is not None else 0.0))
    # a grasp by a part (a container's rim, a mug's handle) closes on that part, at the point it aimed at,
    # not at the centre
    planned = next((r for r in reversed(trace[:close]) if r.get("kind") == "grasp_pose" and r.get("object") == obj), {})
    at = planned["grasp"] if planned.get("grasp_kind") in PART_GRASPS and planned.get("grasp") is not None else aim
    dxy = math.hypot(float(at[0]) - T_close[0, 3], float(at[1]) - T_close[1, 3])
    if dxy > CAPTURE_RADIUS_M + 2 * obs_std:
        return unknown(f"the fingers closed {100 * dxy:.1f} cm from where {obj} was seen", capture_m=dxy)
    if init is not None and init.get("size"):
        half = max(float(init["size"][0]), float(init["size"][1]))
        if opening > half + WIDTH_MARGIN_M + 2 * OPENING_STD_M:
            return unknown(f"opening {1000 * opening:.1f} mm per finger is wider than {obj} "
                           f"({1000 * half:.1f} mm half width): something else may be between the fingers",
                           opening_m=opening)

    # the load after the lift
    carried = [r for r in samples if r.get("wrist_load_n") is not None and r.get("tcp_position_m") is not None
               and float(r["tcp_position_m"][2]) - T_close[2, 3] >= MIN_LIFT_FOR_LOAD_M
               and not str(r.get("phase", "")).startswith(("before_", "after_"))]
    if not carried:
        return unknown("no wrist load sampled after the lift")
    load = float(carried[-1]["wrist_load_n"])
    s_load = _load_std(load)
    facts = {"opening_m": round(opening, 5), "load_n": round(load, 3), "mass_kg": round(load / 9.81, 3)}
    if load > MAX_CARRIED_LOAD_N:
        return unknown(f"wrist load {load:.1f} N exceeds the arm's payload: a contact, not a carried mass", **facts)
    if load <= MIN_HELD_LOAD_N + 2 * s_load:
        return unknown(f"wrist load {load:.2f} N is within 2 sigma ({2 * s_load:.2f} N) of an empty hand "
                       f"(a carried mass adds > {MIN_HELD_LOAD_N} N)", **facts)
    force_end = gattrs.get("wrist_force_n")
    free = [r for r in trace[:close] if r.get("kind") == "proprio" and r.get("wrist_force_n") is not None
            and float(r.get("effort_n") or 0.0) < 0.5 and str(r.get("phase", "")) != "before_close"]
    stamp_end = (evidence.terminal or {}).get("stamp_s")
    if force_end is not None and free and stamp_end is not None \
            and float(stamp_end) > float(carried[-1].get("stamp_s", 0.0)) + 1e-6:
        import numpy as np  # noqa: PLC0415

        base = float(np.linalg.norm(free[-1]["wrist_force_n"]))
        load_end = float(np.linalg.norm(force_end)) - base
        facts["load_end_n"] = round(load_end, 3)
        if load_end < 0.5 * load - 2 * s_load:
            return not_held(f"the wrist load fell from {load:.2f} N to {load_end:.2f} N since the lift: "
                            f"{obj} is no longer carried", **facts)

    # carried rigidly: the object follows the tcp from the close to the end
    tcp = _entity(evidence.terminal, "tcp") or grip
    T_end = _pose(tcp.get("position"), tcp.get("quat_wxyz")) if tcp else None
    if T_end is None:
        last = samples[-1]
        T_end = _pose(last.get("tcp_position_m"), last.get("tcp_quat_wxyz"))
    if T_end is None:
        return unknown("no tcp pose at the end of the evidence", **facts)
    import numpy as np  # noqa: PLC0415

    p = T_end @ np.linalg.inv(T_close) @ np.array([*aim, 1.0])
    std = math.hypot(obs_std, HOLD_STD_M)
    facts["rise_m"] = round(float(T_end[2, 3] - T_close[2, 3]), 4)
    return HeldEstimate(obj, "held",
                        f"held-object model: closed on {obj} at {1000 * opening:.1f} mm per finger, wrist load "
                        f"{load:.2f} N ({load / 9.81:.3f} kg) after the lift, carried to "
                        f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m +- {std:.3f} m",
                        position_m=(float(p[0]), float(p[1]), float(p[2])), position_std_m=std, facts=facts)


def _empty_hand_at_start(trace: Sequence[Mapping]) -> bool:
    """The session's first ``proprio`` sample shows an empty hand: the fingers squeeze with
    less than :data:`EMPTY_EFFORT_N` (a parallel gripper holds nothing it does not squeeze;
    the wrist load is not used here: a hand resting on the table after a missed grasp
    carries tens of newtons of contact force while holding nothing). Only then can the
    grasp's observation stand in for the object's initial height."""
    first = next((r for r in trace if r.get("kind") == "proprio"), None)
    if first is None or first.get("effort_n") is None:
        return False
    return float(first["effort_n"]) < EMPTY_EFFORT_N


def _unseen(snapshot: Mapping, obj: str) -> bool:
    """No camera decided about ``obj``: no ``holding`` relation for it and no confident sighting."""
    if any(r.get("relation") == "holding" and r.get("object") == obj for r in snapshot.get("relations", [])):
        return False
    ent = _entity(snapshot, obj)
    return ent is None or confidence(ent) < CONFIDENCE_MIN


def _lift_seen_from_the_grasp_view(outcome: CriterionOutcome, evidence: Any, obj: str) -> CriterionOutcome | None:
    """``lifted(obj)`` judged by the cameras when the session's initial snapshot missed ``obj``
    or saw it too weakly (below :data:`CONFIDENCE_MIN`) but the observation the grasp aimed at saw it
    confidently (:func:`_aim`: the skill's own view before the fingers touched it, e.g. one
    that fused a second frame) and the terminal snapshot sees it confidently: the rise is the
    terminal centre's height over the aimed-at centre's, with the 2-sigma rule of
    :mod:`phyagentos.agent.criteria`. Only when the hand was empty at the session's start (a
    hand that held it then may have dropped it before the grasp). ``None``: this path does
    not apply (the initial sighting was confident, or any condition fails), and
    the held-object model is asked as before."""
    init, end = _entity(evidence.initial, obj), _entity(evidence.terminal, obj)
    if (init is not None and confidence(init) >= CONFIDENCE_MIN) or end is None or confidence(end) < CONFIDENCE_MIN:
        return None
    trace = tuple(evidence.trace or ())
    close = _last_close(trace, obj)
    aim, s0 = _aim(trace, close, obj) if close is not None else (None, None)
    if aim is None or s0 is None or not _empty_hand_at_start(trace):
        return None
    return _rise(outcome, obj, float(end["position"][2]) - aim[2], math.hypot(s0, sigma(end)),
                 f" from where the grasp's observation saw it (the initial snapshot had no sighting of it at "
                 f"{CONFIDENCE_MIN} or more)")


def _rise(outcome: CriterionOutcome, obj: str, dz: float, s: float, why: str) -> CriterionOutcome:
    """``lifted``'s verdict on a rise ``dz`` (m) with 1-sigma ``s`` (m): the 2-sigma rule of
    :mod:`phyagentos.agent.criteria` against the criterion's ``min_height``; ``why`` says
    where the heights came from (appended to the reason as it is)."""
    c = outcome.criterion
    need = float(c.args["min_height"])
    m = 2.0 * s
    detail = f"rose {dz:.3f} m (need >= {need}, 2 sigma {m:.3f} m){why}"
    if dz >= need + m:
        return CriterionOutcome(c, "satisfied", f"{obj} lifted: {detail}", outcome.evidence)
    if dz < need - m:
        return CriterionOutcome(c, "unsatisfied", f"{obj} not lifted: {detail}", outcome.evidence)
    return CriterionOutcome(c, "unknown", f"{obj} lifted? undecided within the uncertainty: {detail}", outcome.evidence)


def refine(outcome: CriterionOutcome, evidence: Any) -> CriterionOutcome:
    """``outcome`` decided by the held-object model where the cameras left it ``unknown``.

    Only ``holding`` and ``lifted`` outcomes with status ``unknown`` are refined, and a
    ``holding`` judged ``unsatisfied`` only for want of a sighting (no ``holding`` relation,
    the object not seen confidently, the fingers squeezing less than the camera rule's
    threshold); every other outcome is returned unchanged (the model never overturns what
    was seen).

    - ``holding(obj)``: ``satisfied`` when the model says held, ``unsatisfied`` when it
      says not held, else still ``unknown`` (with the model's reason appended);
    - ``lifted(obj, min_height)``: seen confidently at the end but too weakly in the initial
      snapshot, the rise from where the grasp's own observation saw it
      (:func:`_lift_seen_from_the_grasp_view`); else, when held, the carried centre's rise above the initial
      perceived centre ``dz`` is judged with the 2-sigma rule of
      :mod:`phyagentos.agent.criteria` (``sigma = sqrt(sigma_initial^2 + sigma_held^2)``);
      without a confident initial sighting the grasp's observation stands in for it, but
      only when the session's first proprioception shows an empty hand (a hand that held
      the object at the start may have dropped it before the grasp); otherwise still
      ``unknown``.
    """
    c: Criterion = outcome.criterion
    if c.name not in ("holding", "lifted"):
        return outcome
    obj = str(c.args["object"])
    if outcome.status != "unknown" and not (c.name == "holding" and outcome.status == "unsatisfied"
                                            and _unseen(evidence.terminal, obj)):
        return outcome
    if c.name == "lifted" and (seen := _lift_seen_from_the_grasp_view(outcome, evidence, obj)) is not None:
        return seen
    est = estimate_held(evidence, obj)
    if c.name == "holding":
        if est.status == "unknown":
            if outcome.status != "unknown":
                return outcome
            return CriterionOutcome(c, "unknown", f"{outcome.reason}; held-object model: {est.reason}",
                                    outcome.evidence)
        return CriterionOutcome(c, "satisfied" if est.status == "held" else "unsatisfied",
                                est.reason if est.status == "held" else f"held-object model: {est.reason}",
                                outcome.evidence)
    if est.status != "held" or est.position_m is None:
        return CriterionOutcome(c, "unknown", f"{outcome.reason}; held-object model: {est.reason}", outcome.evidence)
    init = _entity(evidence.initial, obj)
    if init is not None and confidence(init) >= CONFIDENCE_MIN:
        z0, s0 = float(init["position"][2]), sigma(init)
    else:  # not in the initial snapshot: the observation the grasp used, if the hand started empty
        trace = tuple(evidence.trace or ())
        close = _last_close(trace, obj)
        aim, s0 = _aim(trace, close, obj) if close is not None else (None, None)
        if aim is not None and not _empty_hand_at_start(trace):
            return CriterionOutcome(c, "unknown", f"{outcome.reason}; {obj} was not seen at the start and the hand "
                                    "was not empty then (it may have held it): no initial height", outcome.evidence)
        if aim is None or s0 is None:
            return CriterionOutcome(c, "unknown", f"{outcome.reason}; {obj} has no confident initial position",
                                    outcome.evidence)
        z0 = aim[2]
    return _rise(outcome, obj, est.position_m[2] - z0, math.hypot(s0, float(est.position_std_m or 0.0)),
                 f"; {est.reason}")
