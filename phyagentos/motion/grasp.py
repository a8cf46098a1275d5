"""Grasp and place poses for boxes, cylinders and spheres with a parallel gripper.

tcp frame conventions below. A box is grasped across its shorter horizontal side; an
upright cylinder or a sphere is round about the vertical, so any yaw closes across its
diameter: four candidates 90 deg apart, nearest the current hand yaw first.

tcp frame (site ``tcp`` of the scene): origin midway between the fingertip pads, z axis
out of the gripper (approach direction), y axis along the finger motion (the closing
direction), x = y x z. A *top-down* pose has z = world -z; its *yaw* is the angle of its
x axis in the world xy plane, so yaw 0 is ``R = diag(1, -1, -1)`` (the home pose).

Joint 7 rotates the hand about the tcp z axis: with z pointing down, increasing q7 by
``d`` changes the hand yaw by ``-d``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from phyagentos.errors import IKError

__all__ = [
    "DEFAULT_MAX_GRASP_WIDTH_M",
    "GraspPlan",
    "top_down_grasp",
    "top_down_grasp_candidates",
    "slid_grasp",
    "slide_offsets",
    "OFF_CENTRE_STEPS_M",
    "turned_grasp",
    "turn_offsets",
    "TURN_STEPS_RAD",
    "PAD_HALF_WIDTH_M",
    "place_pose",
    "top_down_rotation",
    "top_down_plan",
    "hand_yaw",
    "FINGERTIP_BELOW_TCP_M",
    "PAD_DEPTH_ABOVE_TCP_M",
    "FRANKA_FINGERS",
    "JOINT7_RANGE_RAD",
]

#: Distance from the tcp to the lowest point of the fingertips along tcp z, metres.
FINGERTIP_BELOW_TCP_M = 0.015
#: Depth of the finger pads above the tcp before the finger base starts, metres.
PAD_DEPTH_ABOVE_TCP_M = 0.035
#: The Franka Hand's fingers along the tcp's z, m: ``(lowest point below the tcp, pad bottom
#: below it, depth above it before the finger base)`` (a target's ``finger_geometry_m`` when it
#: declares none; the tabletop Franka's tcp).
FRANKA_FINGERS: tuple[float, float, float] = (FINGERTIP_BELOW_TCP_M, FINGERTIP_BELOW_TCP_M, PAD_DEPTH_ABOVE_TCP_M)
#: Half the width of a finger pad across the closing direction (along tcp x), m: robosuite's
#: Panda hand pads are boxes 16 mm wide (``gripper0_finger*_pad_collision``, half size 8 mm).
PAD_HALF_WIDTH_M = 0.008
#: How far (m) an across grasp of a box may slide from the centre along the side it holds, in
#: this order, when no centred grasp is clear of the scene (a neighbour standing beside the
#: box along the closing direction meets the hand, not the box).
OFF_CENTRE_STEPS_M = (0.015, 0.025)
#: How far (rad) an across grasp of a box may turn about the vertical, in this order, when
#: neither a centred nor a slid grasp is clear of the scene (the Panda hand, 20 cm along the
#: closing direction, meets a basket standing beside a butter box that way; turned, its end
#: swings away while the fingers still take the box, which turns to them as they close).
TURN_STEPS_RAD = (math.radians(15.0), math.radians(30.0))
#: Franka joint 7 range, rad.
JOINT7_RANGE_RAD = (-2.8973, 2.8973)


@dataclass(frozen=True)
class GraspPlan:
    """Top-down grasp of a box.

    Attributes:
        grasp: ``(4, 4)`` world tcp pose at which to close the fingers.
        pregrasp: ``(4, 4)`` the same orientation, ``approach_height_m`` higher.
        yaw_rad: hand yaw of both poses (rad).
        width_m: box width across the fingers (m); close below ``width_m / 2`` per finger.
    """

    grasp: np.ndarray
    pregrasp: np.ndarray
    yaw_rad: float
    width_m: float


def top_down_rotation(yaw: float) -> np.ndarray:
    """(3, 3) rotation of a top-down tcp with hand yaw ``yaw`` rad."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


def top_down_plan(x: float, y: float, z: float, yaw: float, *, approach_height_m: float,
                  width_m: float) -> GraspPlan:
    """A :class:`GraspPlan` whose grasp is the top-down tcp pose at ``(x, y, z)`` m (world
    frame) with hand yaw ``yaw`` rad, its pregrasp ``approach_height_m`` straight above;
    both poses read-only."""
    G = np.eye(4)
    G[:3, :3] = top_down_rotation(yaw)
    G[:3, 3] = [x, y, z]
    P = G.copy()
    P[2, 3] += approach_height_m
    G.setflags(write=False)
    P.setflags(write=False)
    return GraspPlan(grasp=G, pregrasp=P, yaw_rad=yaw, width_m=float(width_m))


def hand_yaw(T_tcp: np.ndarray) -> float:
    """Yaw (rad) of the tcp x axis in the world xy plane."""
    return float(math.atan2(T_tcp[1, 0], T_tcp[0, 0]))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


#: Widest object a parallel gripper takes top-down when its target declares none, m: the
#: Franka Hand's 80 mm stroke (Franka Emika datasheet).
DEFAULT_MAX_GRASP_WIDTH_M = 0.08


def top_down_grasp_candidates(
    T_object: np.ndarray,
    half_extents: Sequence[float],
    *,
    approach_height_m: float = 0.10,
    current_yaw_rad: float = 0.0,
    current_q7_rad: float | None = None,
    support_z_m: float | None = None,
    tip_clearance_m: float = 0.004,
    shape: str = "box",
    max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M,
    fingers_m: Sequence[float] | None = None,
) -> tuple[GraspPlan, ...]:
    """All symmetric top-down grasps of an upright box (or a cylinder / sphere), best first.

    ``shape``: ``box`` (default; also for ``unknown``), ``cylinder`` (``half_extents``
    = (r, r, h/2); upright: round about world z) or ``sphere`` ((r, r, r)). A round object
    offers four yaws 90 deg apart starting at ``current_yaw_rad``, closing across 2 r.

    The fingers close across the box's shorter horizontal side, which leaves two yaws
    180 deg apart (four, 90 deg apart, for a square footprint). They are sorted by how
    little the hand has to turn from ``current_yaw_rad``; if ``current_q7_rad`` is given,
    yaws that would push joint 7 (``q7 - delta_yaw``) outside its range are dropped.
    The tcp goes to the box centre, raised if needed so the fingertips stay
    ``tip_clearance_m`` above the support (``support_z_m``, default: the box bottom) and
    the box top stays below the finger base.

    Args:
        T_object: ``(4, 4)`` world pose of the box centre (z axis roughly up).
        half_extents: ``(3,)`` box half sizes, metres.
        approach_height_m: pregrasp offset above the grasp along world z, metres.
        max_width_m: the widest object the gripper takes, m (the target's
            ``max_grasp_width_m``; 8 cm: the Franka Hand); 4 mm of it are clearance.
        fingers_m: ``(lowest finger point below the tcp, pad bottom below it, depth above it
            before the finger base)``, m: the target's ``finger_geometry_m`` (default
            :data:`FRANKA_FINGERS`). The tcp goes no lower than the fingertips' clearance over
            the support, nor so low that the object's top meets the finger base.

    Raises:
        IKError: the box is not upright, too wide for the gripper (``max_width_m``), or no yaw
            keeps joint 7 inside its range.
    """
    T = np.asarray(T_object, dtype=float)
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    if T.shape != (4, 4) or he.shape != (3,):
        raise IKError(f"T_object must be (4, 4) and half_extents (3,), got {T.shape}, {he.shape}")
    if shape == "sphere" or (shape == "cylinder" and abs(T[2, 2]) >= math.cos(math.radians(20))):
        # round about the vertical: express it as an axis-aligned upright "box" whose
        # horizontal axes are the current hand's, so every candidate yaw is equally valid
        r = float(min(he[0], he[1]))
        hz = float(he[2]) if shape == "cylinder" else r
        c, s_ = math.cos(current_yaw_rad), math.sin(current_yaw_rad)
        T = T.copy()
        T[:3, :3] = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        he = np.array([r, r, hz])
    elif shape not in ("box", "cylinder", "unknown"):
        raise IKError(f"unknown shape {shape!r}; valid shapes: box, cylinder, sphere, unknown")
    R = T[:3, :3]
    # A box resting on any face is upright: name its most vertical axis z (a cube
    # tipped over by a failed grasp is still graspable from above).
    k = int(np.argmax(np.abs(R[2, :])))
    if k != 2:
        order = [(k + 1) % 3, (k + 2) % 3, k]
        R, he = R[:, order], he[order]
    if abs(R[2, 2]) < math.cos(math.radians(20)):
        raise IKError("top_down_grasp needs an upright box (one of its axes within 20 deg of vertical)")
    ax = R[:2, 0] / max(np.linalg.norm(R[:2, 0]), 1e-9)
    ay = R[:2, 1] / max(np.linalg.norm(R[:2, 1]), 1e-9)
    closes = []
    if he[0] <= he[1] + 1e-6:
        closes.append((ax, 2 * he[0]))
    if he[1] <= he[0] + 1e-6:
        closes.append((ay, 2 * he[1]))
    width = min(w for _, w in closes)
    if width > max_width_m - 0.004 + 1e-9:
        raise IKError(f"box is {width * 100:.1f} cm wide across the fingers; the gripper takes "
                      f"{(max_width_m - 0.004) * 100:.1f} cm at most")
    deltas = []
    for axis, _ in closes:
        for sign in (1.0, -1.0):
            y = sign * axis  # tcp y = (sin yaw, -cos yaw)
            delta = _wrap(math.atan2(y[0], -y[1]) - current_yaw_rad)
            if current_q7_rad is not None:
                q7 = current_q7_rad - delta
                if not (JOINT7_RANGE_RAD[0] + 0.05 <= q7 <= JOINT7_RANGE_RAD[1] - 0.05):
                    continue
            deltas.append(delta)
    if not deltas:
        raise IKError("no grasp yaw keeps joint 7 inside its range")
    deltas.sort(key=abs)
    ext_z = float(np.abs(R[2, :]) @ he)
    bottom = T[2, 3] - ext_z if support_z_m is None else support_z_m
    top = T[2, 3] + ext_z
    tip_m, _, base_m = FRANKA_FINGERS if fingers_m is None else fingers_m
    z = max(T[2, 3], bottom + tip_m + tip_clearance_m, top - base_m)
    out = []
    for delta in deltas:
        out.append(top_down_plan(T[0, 3], T[1, 3], z, _wrap(current_yaw_rad + delta),
                                 approach_height_m=approach_height_m, width_m=width))
    return tuple(out)


def slide_offsets(plan: GraspPlan, T_object: np.ndarray, half_extents: Sequence[float], *,
                  steps_m: Sequence[float] = OFF_CENTRE_STEPS_M, keep_m: float = 0.005) -> tuple[float, ...]:
    """The offsets (m, along the hand's x axis, signed, in the order ``+s, -s`` per step of
    ``steps_m``) by which ``plan`` may slide along the side of a box it holds with both pads
    still on the box: ``|offset| <= e - PAD_HALF_WIDTH_M - keep_m``, ``e`` the box's extent
    (half size) along the hand's x axis through its centre, from ``T_object`` ((4, 4) world
    pose) and ``half_extents`` ((3,) m). An object whose extent leaves no room gives ``()``."""
    R = np.asarray(T_object, dtype=float)[:3, :3]
    x = np.asarray(plan.grasp, dtype=float)[:3, 0]
    extent = float(np.abs(R.T @ x) @ np.asarray(half_extents, dtype=float))
    room = extent - PAD_HALF_WIDTH_M - keep_m
    return tuple(o for s in steps_m if 0.0 < s <= room for o in (s, -s))


def slid_grasp(plan: GraspPlan, offset_m: float) -> GraspPlan:
    """``plan`` with its grasp and pre-grasp moved ``offset_m`` (m) along the hand's x axis
    (across the closing direction; the yaw, height and width unchanged)."""
    x = np.asarray(plan.grasp, dtype=float)[:3, 0]
    G, P = np.array(plan.grasp, dtype=float), np.array(plan.pregrasp, dtype=float)
    G[:3, 3] += offset_m * x
    P[:3, 3] += offset_m * x
    G.setflags(write=False)
    P.setflags(write=False)
    return GraspPlan(grasp=G, pregrasp=P, yaw_rad=plan.yaw_rad, width_m=plan.width_m)


def _across(T_object: np.ndarray, half_extents: Sequence[float], closing: np.ndarray) -> float:
    """The box's extent (m) along the unit ``closing`` (3,) world direction."""
    R = np.asarray(T_object, dtype=float)[:3, :3]
    return float(2.0 * np.abs(R.T @ closing) @ np.asarray(half_extents, dtype=float))


def _turn(T: np.ndarray, angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    out = np.array(T, dtype=float)
    out[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ out[:3, :3]
    out.setflags(write=False)
    return out


def turn_offsets(plan: GraspPlan, T_object: np.ndarray, half_extents: Sequence[float], *,
                 steps_rad: Sequence[float] = TURN_STEPS_RAD,
                 max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M) -> tuple[float, ...]:
    """The turns (rad about world z, signed, in the order ``+s, -s`` per step of ``steps_rad``)
    of ``plan`` at which the box (``T_object`` (4, 4) world pose, ``half_extents`` (3,) m) still
    fits between the fingers: its extent along the turned closing direction (the hand's y axis)
    at most ``max_width_m`` less the 4 mm of clearance :func:`top_down_grasp_candidates` keeps."""
    return tuple(angle for step in steps_rad if step > 0.0 for angle in (step, -step)
                 if _across(T_object, half_extents, _turn(plan.grasp, angle)[:3, 1]) <= max_width_m - 0.004)


def turned_grasp(plan: GraspPlan, angle_rad: float, T_object: np.ndarray,
                 half_extents: Sequence[float]) -> GraspPlan:
    """``plan`` turned ``angle_rad`` (rad) about the vertical through its tool point, its
    pre-grasp with it; its width (m) the box's extent (``T_object`` (4, 4) world pose,
    ``half_extents`` (3,) m) along the turned closing direction."""
    G = _turn(plan.grasp, angle_rad)
    P = _turn(plan.pregrasp, angle_rad)
    return GraspPlan(grasp=G, pregrasp=P, yaw_rad=float(plan.yaw_rad + angle_rad),
                     width_m=_across(T_object, half_extents, G[:3, 1]))


def top_down_grasp(
    T_object: np.ndarray,
    half_extents: Sequence[float],
    *,
    approach_height_m: float = 0.10,
    current_yaw_rad: float = 0.0,
    current_q7_rad: float | None = None,
    support_z_m: float | None = None,
    tip_clearance_m: float = 0.004,
    shape: str = "box",
) -> GraspPlan:
    """The best top-down grasp of an upright box: tcp z pointing down, fingers closing
    across the shorter horizontal side, yaw (within the joint-7 range when
    ``current_q7_rad`` is given) closest to ``current_yaw_rad``. See
    :func:`top_down_grasp_candidates` for the arguments; raises :class:`IKError`."""
    return top_down_grasp_candidates(
        T_object,
        half_extents,
        approach_height_m=approach_height_m,
        current_yaw_rad=current_yaw_rad,
        current_q7_rad=current_q7_rad,
        support_z_m=support_z_m,
        tip_clearance_m=tip_clearance_m,
        shape=shape,
    )[0]


def place_pose(
    region_center: Sequence[float],
    half_extents: Sequence[float],
    *,
    T_tcp_object: np.ndarray,
    yaw_rad: float = 0.0,
    surface_z_m: float = 0.0,
    clearance_m: float = 0.003,
) -> np.ndarray:
    """tcp pose that holds the object (grasped at ``T_tcp_object``) centred over
    ``region_center`` (x, y) with its lowest point ``clearance_m`` above ``surface_z_m``.

    Args:
        region_center: ``(x, y)`` (or ``(x, y, z)``, z ignored) world metres.
        half_extents: ``(3,)`` object half sizes, metres.
        T_tcp_object: ``(4, 4)`` object pose in the tcp frame (measured after grasping).
        yaw_rad: hand yaw of the top-down place pose.

    Returns:
        ``(4, 4)`` world tcp pose (top-down).
    """
    c = np.asarray(region_center, dtype=float).reshape(-1)
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    To = np.asarray(T_tcp_object, dtype=float)
    if c.shape[0] not in (2, 3) or he.shape != (3,) or To.shape != (4, 4):
        raise IKError("place_pose: region_center (2,), half_extents (3,), T_tcp_object (4, 4) expected")
    Rt = top_down_rotation(yaw_rad)
    Ro = Rt @ To[:3, :3]
    ext_z = float(np.abs(Ro[2, :]) @ he)
    p_obj = np.array([c[0], c[1], surface_z_m + ext_z + clearance_m])
    T = np.eye(4)
    T[:3, :3] = Rt
    T[:3, 3] = p_obj - Rt @ To[:3, 3]
    return T
