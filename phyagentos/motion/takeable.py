"""Whether the hand can take a thing at all, judged from its declared look before it is seen.

A planner choosing between carrying a thing and pushing it along the table needs to know,
before anything moves, whether a pick could ever succeed. The two grasps that need nothing
but a thing's size, shape and category decide it here, with the same rules the pick's
``ComputeGrasp`` applies to what it perceives:

- **across** (:func:`~phyagentos.motion.grasp.top_down_grasp_candidates`): the narrower
  horizontal side (a round thing's diameter) fits between the fingers with the 4 mm
  clearance the grasp keeps: at most ``max_width_m - 0.004``;
- **by the rim** (:func:`~phyagentos.motion.rim_grasp.rim_graspable`): an open container (a
  bowl, a mug) too wide to take across.

A grasp by a knob on the thing's top (:mod:`~phyagentos.motion.top_knob_grasp`) needs a knob
that perception reports on the thing where it stands; a look declares none, so a thing too
wide for both grasps above is not takeable here even if a knob might later be seen on it.
Pure geometry on declared values: nothing here reads a simulator.
"""

from __future__ import annotations

import math
from typing import Sequence

from .grasp import DEFAULT_MAX_GRASP_WIDTH_M
from .rim_grasp import rim_graspable

__all__ = ["ACROSS_CLEARANCE_M", "across_width", "takeable"]

#: Clearance the across grasp keeps between the object and the open fingers, m (the same
#: 4 mm as :func:`~phyagentos.motion.grasp.top_down_grasp_candidates`).
ACROSS_CLEARANCE_M = 0.004

_SHAPES = ("box", "cylinder", "sphere", "unknown")


def _size(size_m: Sequence[float]) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in size_m)
    except (TypeError, ValueError):
        raise ValueError(f"size_m must be 3 numbers (x, y, z extents, m), got {size_m!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) and v > 0.0 for v in values):
        raise ValueError(f"size_m must be 3 finite extents > 0 m (x, y, z), got {size_m!r}")
    return values


def across_width(shape: str | None, size_m: Sequence[float]) -> float:
    """The width the fingers close across on a thing standing as declared, m: its narrower
    horizontal side (``size_m`` x, y), a sphere's smallest extent.

    Args:
        shape: ``box``, ``cylinder``, ``sphere``, ``unknown`` or None (a box).
        size_m: ``(3,)`` full extents (x, y, z) of the thing standing upright, m.

    Raises:
        ValueError: ``size_m`` is not three finite extents > 0, or ``shape`` is not one of
            the shapes above.
    """
    x, y, z = _size(size_m)
    if shape is not None and shape not in _SHAPES:
        raise ValueError(f"unknown shape {shape!r}; valid shapes: {', '.join(_SHAPES)} (or None)")
    return min(x, y, z) if shape == "sphere" else min(x, y)


def takeable(category: str | None, shape: str | None, size_m: Sequence[float], *,
             max_width_m: float = DEFAULT_MAX_GRASP_WIDTH_M) -> bool:
    """Whether a thing of this declared look is taken by a grasp across it or by its rim.

    Args:
        category: its declared class (``plate``, ``akita_black_bowl``) or None.
        shape: its declared shape: ``box``, ``cylinder``, ``sphere``, ``unknown`` or None.
        size_m: ``(3,)`` full extents (x, y, z) of the thing standing upright, m.
        max_width_m: the widest thing the gripper takes across, m (a target's
            ``max_grasp_width_m``; default 8 cm, the Franka Hand's stroke).

    Returns:
        True when :func:`across_width` is at most ``max_width_m`` less
        :data:`ACROSS_CLEARANCE_M`, or the thing is an open container taken by its rim;
        False otherwise (LIBERO's plate, 13.9 cm across and 1.7 cm tall).

    Raises:
        ValueError: as :func:`across_width`, or ``max_width_m`` not a finite number above the
            clearance.
    """
    if not (math.isfinite(max_width_m) and max_width_m > ACROSS_CLEARANCE_M):
        raise ValueError(f"max_width_m must be a finite width > {ACROSS_CLEARANCE_M} m, got {max_width_m!r}")
    if across_width(shape, size_m) <= max_width_m - ACROSS_CLEARANCE_M + 1e-9:
        return True
    half = [v / 2.0 for v in _size(size_m)]
    return rim_graspable(category, shape, half, max_width_m=max_width_m)
