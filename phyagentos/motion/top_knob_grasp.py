"""Knob grasps: a parallel gripper takes an object too wide for it by the knob on its top.

A moka pot's body is wider than the Franka Hand opens, and its handle and spout stand where
the fingers would go down beside it; the knob on its lid is 1 cm across and rises 1.9 cm
above the lid (:mod:`phyagentos.perception.top_knob`). The hand comes down top-down over the
knob, its fingertips :data:`KNOB_TIP_CLEARANCE_M` above the object's top, and closes on the
knob. Same :class:`~phyagentos.motion.grasp.GraspPlan` and tcp conventions as
:mod:`phyagentos.motion.grasp` (tcp z down, tcp y the closing direction, yaw the angle of tcp x
in the world xy plane).

Which objects (:func:`top_knob_graspable`): one whose perceived knob is reported
(``attributes.knob_xy``, ``top_knob_z_m``, ``top_knob_radius_m``) and that is too wide to take
across, or fills the open hand to within :data:`KNOB_PREFERRED_MARGIN_M`: perception's size
is good to about 1 cm (2 sigma), and an across grasp that tight meets what stands out of the
body. Everything comes from perception; never from the simulator's state.
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
    "KNOB_TIP_CLEARANCE_M",
    "KNOB_MIN_PAD_OVERLAP_M",
    "KNOB_PREFERRED_MARGIN_M",
    "KNOB_PRESHAPE_CLEARANCE_M",
    "top_knob_graspable",
    "top_knob_grasp_candidates",
    "top_knob_preshape_m",
    "top_knob_grasp_z",
]

#: The fingertips stay this far above the object's perceived top (its body's), m: perception's
#: top is its segment's 98th percentile height, a few mm under the true one.
KNOB_TIP_CLEARANCE_M = 0.004
#: The pads must hold at least this much of the knob's height, m, or there is no grasp.
KNOB_MIN_PAD_OVERLAP_M = 0.008
#: An object narrower than the gripper takes by less than this is taken by its knob, m.
KNOB_PREFERRED_MARGIN_M = 0.01
#: Each finger goes down this far outside the knob, m (the hand pre-shaped to it: a finger
#: fully open would come down over a moka pot's handle).
KNOB_PRESHAPE_CLEARANCE_M = 0.02


def top_knob_graspable(attributes: dict, half_extents: Sequence[float], *, shape: str = "box",
                   max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M) -> bool:
    """Whether an entity with perceived ``attributes`` (its ``top_knob_*``) and ``half_extents``
    ((3,) m) is taken by its knob: it has one, and its narrowest side across
    (``2 * min(hx, hy)``; a sphere never) leaves the gripper's ``max_width_m`` (less its 4 mm
    of clearance) less than :data:`KNOB_PREFERRED_MARGIN_M`."""
    if shape == "sphere" or attributes.get("top_knob_xy") is None or attributes.get("top_knob_z_m") is None:
        return False
    he = np.asarray(half_extents, dtype=float).reshape(-1)
    return 2.0 * float(min(he[0], he[1])) > max_width_m - 0.004 - KNOB_PREFERRED_MARGIN_M


def top_knob_preshape_m(radius_m: float, *, max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M) -> float:
    """Opening per finger (m) the hand goes down with over a knob of ``radius_m`` (m)."""
    return min(0.5 * max_width_m, float(radius_m) + KNOB_PRESHAPE_CLEARANCE_M)


def top_knob_grasp_z(body_top_z_m: float) -> float:
    """World z (m) of the tcp at a knob grasp of an object whose top is at ``body_top_z_m``
    (world, m): its fingertips :data:`KNOB_TIP_CLEARANCE_M` above that top."""
    return float(body_top_z_m) + KNOB_TIP_CLEARANCE_M + FINGERTIP_BELOW_TCP_M


def top_knob_grasp_candidates(
    knob_xy: Sequence[float],
    knob_top_z_m: float,
    knob_radius_m: float,
    *,
    body_top_z_m: float,
    long_axis_yaw_rad: float,
    approach_height_m: float = 0.10,
    prefer_yaw_rad: float = 0.0,
    current_q7_rad: float | None = None,
    current_yaw_rad: float = 0.0,
) -> tuple[GraspPlan, ...]:
    """Top-down grasps of a knob, best first.

    The tcp stands over ``knob_xy`` ((2,) world, m), its fingertips
    (:data:`~phyagentos.motion.grasp.FINGERTIP_BELOW_TCP_M` below it)
    :data:`KNOB_TIP_CLEARANCE_M` above ``body_top_z_m`` (world z of the object's top, m). The
    fingers close across the knob's faces, which line up with ``long_axis_yaw_rad`` (rad: the
    way the object reaches farthest, its handle): four yaws 90 deg apart, the one nearest
    ``prefer_yaw_rad`` first (0, the first yaw a place tries: the object then goes down as it
    stood), those that would push joint 7 (``current_q7_rad``, the hand's yaw now
    ``current_yaw_rad``) out of its range dropped. ``width_m`` is the knob's diameter.

    Raises:
        IKError: the knob rises less than :data:`KNOB_MIN_PAD_OVERLAP_M` above where the
            fingertips must stay, or no yaw keeps joint 7 inside its range.
    """
    xy = np.asarray(knob_xy, dtype=float).reshape(-1)
    z = top_knob_grasp_z(body_top_z_m)
    held = min(float(knob_top_z_m), z + PAD_DEPTH_ABOVE_TCP_M) - (z - FINGERTIP_BELOW_TCP_M)
    if held < KNOB_MIN_PAD_OVERLAP_M:
        raise IKError(f"the knob rises {(float(knob_top_z_m) - float(body_top_z_m)) * 1000:.1f} mm above the "
                      f"object's top; the pads would hold {max(held, 0.0) * 1000:.1f} mm of it, "
                      f"{KNOB_MIN_PAD_OVERLAP_M * 1000:.0f} mm needed")
    yaws = []
    for k in range(4):
        yaw = _wrap(long_axis_yaw_rad + 0.5 * math.pi * k)
        delta = _wrap(yaw - current_yaw_rad)
        if current_q7_rad is not None and not (JOINT7_RANGE_RAD[0] + 0.05 <= current_q7_rad - delta
                                               <= JOINT7_RANGE_RAD[1] - 0.05):
            continue
        yaws.append(yaw)
    if not yaws:
        raise IKError("no knob grasp yaw keeps joint 7 inside its range")
    yaws.sort(key=lambda a: abs(_wrap(a - prefer_yaw_rad)))
    return tuple(top_down_plan(float(xy[0]), float(xy[1]), z, yaw, approach_height_m=approach_height_m,
                               width_m=2.0 * float(knob_radius_m)) for yaw in yaws)
