"""What the robot knows about its grasp, from proprioception alone (never simulator contacts).

A parallel gripper that closes on an object stops short of closed: the opening per finger
stays above :data:`MIN_OPENING_M` and the finger actuators push (effort above
:data:`MIN_EFFORT_N`). Lifted, the object adds its weight to the wrist force-torque sensor:
``wrist_load_n = |f - f_hand|``, with ``f_hand`` the hand's own weight and inertial force
predicted from the robot model and the joint accelerations (the target's
``wrist_external_force_n()``), and ``mass_estimate_kg = wrist_load_n / g`` (with the arm
still). Without that prediction the load is ``|f| - |f_unloaded|`` (the open hand's reading
before the close). While holding, a slip shows as the fingers closing
further (opening drop > :data:`SLIP_OPENING_DROP_M`) or the wrist load falling by more than
:data:`SLIP_LOAD_DROP_FRACTION` (CONTRACT_9 section 5).

The belief (which object the robot closed on, the opening and load it measured) is kept in
the target's runtime notes, which the target checkpoints with its state, so the ``place``
session continues what ``pick`` measured, as a real controller keeps it in memory.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from phyagentos.targets.contract import capabilities_of

__all__ = ["GraspBelief", "MIN_OPENING_M", "MIN_EFFORT_N", "SLIP_OPENING_DROP_M", "SLIP_LOAD_DROP_FRACTION",
           "MIN_LOAD_FOR_SLIP_N", "GRAVITY_M_S2", "belief", "wrist_load_n", "proprio_record", "holding_problem",
           "sample_while_holding", "mass_estimate_kg", "WIDTH_MARGIN_M", "MIN_HELD_LOAD_N", "plan_grasp",
           "min_opening_m", "closed_on_something"]

#: Opening per finger below which a close found nothing between the fingers, m.
MIN_OPENING_M = 0.002
#: Finger squeeze above which the fingers press on something, N.
MIN_EFFORT_N = 1.0
#: A held object's width may exceed its perceived width by this much per finger, m.
WIDTH_MARGIN_M = 0.01
#: Slip: the fingers closed further than this since the grasp, m (CONTRACT_9 section 5).
SLIP_OPENING_DROP_M = 0.003
#: Slip: the wrist load fell by more than this fraction of the load measured after lift.
SLIP_LOAD_DROP_FRACTION = 0.5
#: Below this lifted load (N) the load is too small to judge a drop from (about 50 g).
MIN_LOAD_FOR_SLIP_N = 0.45
#: A held object must add at least this much to the wrist load after lift, N (20 g).
MIN_HELD_LOAD_N = 0.1
#: Standard gravity, m/s^2.
GRAVITY_M_S2 = 9.81
#: Least sim time between two proprio samples while holding, s (>= 10 Hz: one per tick).
SAMPLE_PERIOD_S = 0.1


class GraspBelief:
    """View of the grasp entries in a target's ``runtime_notes`` dict (plain data, so the
    target can checkpoint it): ``object``, ``width_m``, ``closed_opening_m``,
    ``baseline_force_n``, ``lifted_load_n``, ``slipped``, ``last_sample_s``."""

    KEYS = ("object", "width_m", "closed_opening_m", "baseline_force_n", "lifted_load_n", "slipped", "last_sample_s")

    def __init__(self, notes: dict):
        self._n = notes.setdefault("grasp", {})

    def __getattr__(self, key: str) -> Any:
        if key in GraspBelief.KEYS:
            return self._n.get(key)
        raise AttributeError(key)

    def set(self, **kw: Any) -> None:
        for k, v in kw.items():
            if k not in GraspBelief.KEYS:
                raise KeyError(k)
            self._n[k] = v

    def clear(self) -> None:
        self._n.clear()


def belief(target) -> GraspBelief:
    """The grasp belief kept in ``target.runtime_notes`` (:attr:`Target.runtime_notes
    <phyagentos.targets.contract.Target.runtime_notes>`, a dict the target checkpoints)."""
    return GraspBelief(target.runtime_notes)


def _force_norm(p) -> float | None:
    return None if p.wrist_force_n is None else float(np.linalg.norm(p.wrist_force_n))


def wrist_load_n(target, p) -> float | None:
    """Load on the wrist beyond the unloaded hand, N (``None`` without an F/T sensor):
    ``|f| - |f_unloaded|``, the baseline measured before the close, else the hand's
    weight from the robot model (``target.unloaded_wrist_force_n()``)."""
    if abs(float(target.sim_time) - float(p.stamp_s)) < 1e-9:
        v = target.wrist_external_force_n()
        if v is not None:
            return float(np.linalg.norm(v))
    f = _force_norm(p)
    if f is None:
        return None
    base = belief(target).baseline_force_n
    if base is None:
        base = target.unloaded_wrist_force_n()
    return None if base is None else f - float(base)


def _tcp_fields(p) -> dict:
    """``tcp_position_m`` (3,) and ``tcp_quat_wxyz`` (4,) of the tool site in the world frame,
    from the sample's forward kinematics of the measured joint positions (robot knowledge,
    as a real arm's controller reports its flange pose); ``{}`` without a ``tcp_pose``."""
    T = getattr(p, "tcp_pose", None)
    if T is None:
        return {}
    T = np.asarray(T, dtype=float)
    q = np.empty(4)
    import mujoco  # noqa: PLC0415 - the quaternion of the rotation block (MuJoCo's own conversion)

    mujoco.mju_mat2Quat(q, np.ascontiguousarray(T[:3, :3]).flatten())
    return {"tcp_position_m": [round(float(x), 5) for x in T[:3, 3]], "tcp_quat_wxyz": [round(float(x), 5) for x in q]}


def proprio_record(target, p, *, phase: str, leaf: str) -> dict:
    """The ``proprio`` trace entry of CONTRACT_9 section 5 for sample ``p``: opening (m per
    finger), finger effort (N), wrist force (3,) N and load (N), and the tcp pose in the
    world frame from forward kinematics (``tcp_position_m`` (3,) m, ``tcp_quat_wxyz`` (4,)); and
    ``finger_offsets_m`` (2,) m where the hand reports each finger."""
    load = wrist_load_n(target, p)
    fingers = getattr(p, "finger_offsets_m", None)
    each = {} if fingers is None else {"finger_offsets_m": [round(float(x), 5) for x in fingers]}
    return {"leaf": leaf, "phase": phase, "stamp_s": round(float(p.stamp_s), 4),
            "opening_m": round(float(p.gripper_opening_m), 5), "effort_n": round(float(p.gripper_effort_n), 3),
            "wrist_force_n": None if p.wrist_force_n is None else [round(float(x), 3) for x in p.wrist_force_n],
            "wrist_load_n": None if load is None else round(load, 3), **_tcp_fields(p), **each}


def holding_problem(target, p, *, expected: str | None = None, after_lift: bool = False) -> str | None:
    """Why proprioception says the gripper does not hold (``expected``), or ``None``.

    Holding: the robot closed on ``expected`` (its belief), the opening is above
    :func:`min_opening_m` of the width it closed on (:data:`MIN_OPENING_M`, less for a
    rim grasp's thin wall) and within the perceived width + :data:`WIDTH_MARGIN_M`, the
    fingers squeeze (effort > :data:`MIN_EFFORT_N`) and, ``after_lift``, the wrist carries
    more than :data:`MIN_HELD_LOAD_N` beyond the unloaded hand.
    """
    b = belief(target)
    if expected is not None and b.object not in (None, expected):
        return f"the gripper closed on {b.object!r}, not {expected!r}"
    if p.gripper_opening_m < min_opening_m(b.width_m):
        return f"fingers closed to {p.gripper_opening_m * 1000:.1f} mm: nothing between them"
    if b.width_m is not None and p.gripper_opening_m > b.width_m / 2.0 + WIDTH_MARGIN_M:
        return (f"opening {p.gripper_opening_m * 1000:.1f} mm per finger is wider than the object "
                f"({b.width_m * 1000:.1f} mm across)")
    if p.gripper_effort_n < MIN_EFFORT_N:
        return f"finger effort {p.gripper_effort_n:.2f} N: the fingers do not squeeze anything"
    if after_lift:
        load = wrist_load_n(target, p)
        if load is not None and load < MIN_HELD_LOAD_N:
            return f"wrist load {load:.2f} N above the unloaded hand: nothing hangs from the gripper"
    return None


def sample_while_holding(ctx, leaf: str, *, force: bool = False) -> None:
    """Record a ``proprio`` sample (>= 10 Hz of sim time) while the robot believes it holds
    something, and a ``slip`` entry the first time the opening or the load drops."""
    target = ctx.target
    b = belief(target)
    if b.object is None or not capabilities_of(target).has_sensor("proprioception"):
        return
    p = target.proprioception()
    last = b.last_sample_s
    if not force and last is not None and p.stamp_s - float(last) < SAMPLE_PERIOD_S - 1e-9:
        return
    b.set(last_sample_s=float(p.stamp_s))
    rec = proprio_record(target, p, phase=leaf, leaf=leaf)
    ctx.trace.record("proprio", **rec)
    if b.slipped:
        return
    drop = (float(b.closed_opening_m) - p.gripper_opening_m) if b.closed_opening_m is not None else 0.0
    load = rec["wrist_load_n"]
    lifted = b.lifted_load_n
    load_drop = (float(lifted) - load) if (lifted is not None and load is not None) else 0.0
    load_slip = lifted is not None and lifted >= MIN_LOAD_FOR_SLIP_N and load is not None and \
        load < (1.0 - SLIP_LOAD_DROP_FRACTION) * float(lifted)
    if drop > SLIP_OPENING_DROP_M or load_slip:
        b.set(slipped=True)
        ctx.trace.record("slip", leaf=leaf, object=b.object, stamp_s=round(float(p.stamp_s), 4),
                         opening_drop_m=round(drop, 5), load_drop_n=round(load_drop, 3))


def mass_estimate_kg(load_n: float | None) -> float | None:
    """Mass (kg) hanging from the wrist for a static load (N): load / g."""
    if load_n is None or not math.isfinite(load_n):
        return None
    return max(0.0, load_n / GRAVITY_M_S2)


def plan_grasp(target, *, object: str, width_m: float | None, kind: str = "across",
               preshape_m: float | None = None) -> None:
    """Remember the grasp the robot is about to make (object, the width the fingers will
    close on, m, and ``kind``: ``across`` the object or by its ``rim``, where the width is
    the container's wall; ``preshape_m``: how far open per finger, m, the hand goes down to
    it, ``None`` fully open), for the pre-shape and the close that follow."""
    target.runtime_notes["planned_grasp"] = {"object": object, "width_m": None if width_m is None else float(width_m),
                                             "kind": str(kind),
                                             "preshape_m": None if preshape_m is None else float(preshape_m)}


def min_opening_m(width_m: float | None) -> float:
    """Opening per finger (m) below which a close found nothing between the fingers, for an
    expected held width ``width_m`` (m; None: unknown): :data:`MIN_OPENING_M`, or a quarter
    of the width (half the opening it should leave per finger) when that is smaller: a
    bowl's 3 mm wall leaves 1.5 mm per finger, which the 2 mm default would call empty."""
    if width_m is None or not math.isfinite(float(width_m)) or width_m <= 0:
        return MIN_OPENING_M
    return min(MIN_OPENING_M, 0.25 * float(width_m))


def closed_on_something(p, width_m: float | None = None) -> bool:
    """Whether the hand's encoders say its closed fingers hold something: proprioception ``p``'s
    opening per finger above :func:`min_opening_m` for an expected held width ``width_m`` (m;
    None: unknown) and its squeeze above :data:`MIN_EFFORT_N`."""
    return bool(p.gripper_opening_m > min_opening_m(width_m) and p.gripper_effort_n > MIN_EFFORT_N)
