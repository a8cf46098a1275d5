"""A free spot in a container for one more object: where its footprint stands clearest of what
is already inside, as near the middle as that allows.

Pure geometry in the world's horizontal plane (metres); boxes are footprints, a container's
turned by its yaw, the object's and the occupants' axis-aligned (their world extents).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

__all__ = ["FREE_CLEARANCE_M", "FREE_STEP_M", "free_spot", "slot_grid", "slot_offset"]

#: Clearance (m) from every occupant beyond which a spot is as good as any other: the search then
#: prefers the spot nearest the container's middle (a perceived footprint's 2 sigma is 1 cm).
FREE_CLEARANCE_M = 0.02
#: Spacing (m) of the spots tried across the container's footprint.
FREE_STEP_M = 0.005


def _gap(p: np.ndarray, half: np.ndarray, q: np.ndarray, other: np.ndarray) -> float:
    """Signed distance (m) between two axis-aligned footprints, centres ``p``, ``q`` (2,) and half
    extents ``half``, ``other`` (2,): positive apart (the larger per-axis gap), negative
    overlapping."""
    d = np.abs(p - q) - (half + other)
    return float(np.max(d))


def free_spot(centre_xy: Sequence[float], yaw_rad: float, inner_half_xy: Sequence[float],
              object_half_xy: Sequence[float], occupants: Sequence[tuple[Sequence[float], Sequence[float]]], *,
              prefer_xy: Sequence[float] | None = None) -> tuple[np.ndarray, float] | None:
    """Where to set one more object down in a container already holding ``occupants``.

    Args:
        centre_xy: (2,) the container's middle, world m.
        yaw_rad: the container footprint's yaw about the world z axis, rad.
        inner_half_xy: (2,) half extents of its inside along its own axes, m.
        object_half_xy: (2,) the object's footprint half extents along the world axes, m (as it
            will stand).
        occupants: ``(centre (2,), half extents (2,))`` world m of what stands inside already,
            axis-aligned footprints.
        prefer_xy: (2,) world m, the spot wanted when it is clear (a cell of the container
            shared with objects still to come); default the middle.

    Returns:
        ``((2,) world spot m, clearance m)``: the spot whose smallest gap to an occupant is
        largest (up to :data:`FREE_CLEARANCE_M`, beyond which the one nearest ``prefer_xy``
        wins), among spots :data:`FREE_STEP_M` apart that keep the object's footprint inside;
        with nothing inside, the inside spot nearest ``prefer_xy`` and ``inf``; ``None`` when
        the object does not fit inside at all. The clearance may be negative: the least
        overlap there is.
    """
    c = np.asarray(centre_xy, dtype=float)[:2]
    half = np.asarray(object_half_xy, dtype=float)[:2]
    want = c if prefer_xy is None else np.asarray(prefer_xy, dtype=float)[:2]
    if not occupants and prefer_xy is None:
        return c.copy(), math.inf
    u = np.array([math.cos(yaw_rad), math.sin(yaw_rad)])
    v = np.array([-u[1], u[0]])
    # the object's reach along the container's axes (its world box turned into them)
    reach = np.array([abs(u[0]) * half[0] + abs(u[1]) * half[1], abs(v[0]) * half[0] + abs(v[1]) * half[1]])
    room = np.asarray(inner_half_xy, dtype=float)[:2] - reach
    if np.any(room < 0.0):
        return None
    a = np.arange(-room[0], room[0] + 1e-9, FREE_STEP_M) if room[0] > 0 else np.zeros(1)
    b = np.arange(-room[1], room[1] + 1e-9, FREE_STEP_M) if room[1] > 0 else np.zeros(1)
    occ = [(np.asarray(p, dtype=float)[:2], np.asarray(h, dtype=float)[:2]) for p, h in occupants]
    best: tuple[float, float, np.ndarray, float] | None = None
    for s in a:
        for t in b:
            p = c + s * u + t * v
            clear = min((_gap(p, half, q, h) for q, h in occ), default=math.inf)
            key = (min(clear, FREE_CLEARANCE_M), -float(np.hypot(*(p - want))))
            if best is None or key > best[:2]:
                best = (key[0], key[1], p, clear)
    assert best is not None
    return best[2], best[3]


def slot_grid(region_half_extents, slots: int) -> tuple[int, int]:
    """``(columns, rows)`` of the cells :func:`slot_offset` lays ``slots`` objects out in:
    columns along the region's longer horizontal axis, as many as keep the cells closest to
    square (``ceil(sqrt(slots * long / short))``, at most ``slots``), rows across it. Two
    objects in any region, or three in a strip, stand in one row; three or four in a square
    region stand two by two."""
    hx, hy = float(region_half_extents[0]), float(region_half_extents[1])
    long, short = max(hx, hy), min(hx, hy)
    cols = min(slots, max(1, math.ceil(math.sqrt(slots * long / short)))) if short > 0 else slots
    return cols, math.ceil(slots / cols)


def slot_offset(region_half_extents, slot: int, slots: int) -> np.ndarray:
    """``(2,)`` m offset from a region's centre of cell ``slot`` (0-based) of ``slots``.

    The cells split the region evenly into the grid of :func:`slot_grid` (x is the longer
    axis on a tie) and are numbered along the longer axis first, row by row.
    """
    hx, hy = float(region_half_extents[0]), float(region_half_extents[1])
    axis = 0 if hx >= hy else 1
    cols, rows = slot_grid((hx, hy), slots)
    col, row = slot % cols, slot // cols
    half_long, half_short = (hx, hy)[axis], (hx, hy)[1 - axis]
    out = np.zeros(2)
    out[axis] = -half_long + (2 * col + 1) * half_long / cols
    out[1 - axis] = -half_short + (2 * row + 1) * half_short / rows
    return out
