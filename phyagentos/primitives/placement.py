"""Placement leaves: set the held object down at a chosen spot inside a region.

``compute_place`` aims at a region's centre, so a second object placed in the same
region lands on the first. ``compute_place_at`` aims at an ``offset_m`` from the
centre or at cell ``slot`` of ``slots`` cells laid out over the region (:func:`slot_offset`),
and refuses a spot where the object's footprint, as it will stand, would stick out of
the region (``place.outside_region``). Stacking on another object stays
``compute_place`` with ``region`` naming that object.
"""

from __future__ import annotations

import math

import numpy as np

from phyagentos.motion.grasp import place_pose, top_down_rotation

from .base import Primitive, PrimitiveFailure
from .perception import entity_pose, origin_pose

__all__ = ["ComputePlaceAt", "slot_grid", "slot_offset"]


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


class ComputePlaceAt(Primitive):
    """Place and pre-place tcp poses that set the held object down at a spot in ``region``.

    Args:
        object: the held object.
        region: the region (a patch on its support surface).
        offset_m: ``[dx, dy]`` world-frame offset of the spot from the region's centre,
            m; or
        slot, slots: the spot is cell ``slot`` (0-based) of the ``slots`` cells
            :func:`slot_offset` lays over the region (default 0 of 1: the centre).
        approach_height_m: pre-place height above the place pose, m.
        snapshot: blackboard key of the observation.
        place, preplace: blackboard keys written with (4, 4) world tcp poses.

    Fails with ``place.outside_region`` when the object's footprint at the spot does not
    fit inside the region.
    """

    def __init__(self, name: str, *, object: str, region: str, offset_m=None, slot: int = 0, slots: int = 1,
                 approach_height_m: float = 0.10, snapshot: str = "snapshot", place: str = "place_pose",
                 preplace: str = "preplace_pose"):
        super().__init__(name)
        if isinstance(slots, bool) or not isinstance(slots, int) or slots < 1:
            raise ValueError(f"slots must be a whole number >= 1, got {slots!r}")
        if isinstance(slot, bool) or not isinstance(slot, int) or not 0 <= slot < slots:
            raise ValueError(f"slot must be a whole number in [0, {slots - 1}], got {slot!r}")
        if offset_m is not None:
            if (slot, slots) != (0, 1):
                raise ValueError("give either 'offset_m' ([dx, dy] in m) or 'slot' with 'slots', not both")
            offset_m = np.asarray(offset_m, dtype=float)
            if offset_m.shape != (2,) or not np.all(np.isfinite(offset_m)):
                raise ValueError(f"offset_m must be 2 finite numbers in m, got {offset_m!r}")
        self.object, self.region = object, region
        self.offset_m, self.slot, self.slots = offset_m, slot, slots
        self.approach_height_m = float(approach_height_m)
        self.snapshot_key, self.place_key, self.preplace_key = snapshot, place, preplace
        self.reads(snapshot)
        self.writes(place, preplace)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        T_region, region_half = entity_pose(snapshot, self.region)
        T_obj, half = origin_pose(snapshot, self.object)  # the point it names goes to the spot
        offset = self.offset_m if self.offset_m is not None else slot_offset(region_half, self.slot, self.slots)
        T_tcp_obj = np.linalg.inv(self.ctx.target.tcp_pose()) @ T_obj
        # the footprint of the object as it will stand: the place pose is top-down at yaw 0, so
        # the object's axes in the world are top_down_rotation(0) @ (its rotation in the hand)
        R_world_obj = top_down_rotation(0.0) @ T_tcp_obj[:3, :3]
        reach = np.abs(R_world_obj[:2, :]) @ half if half.size == 3 else np.zeros(2)
        if np.any(np.abs(offset) + reach > region_half[:2] + 1e-9):
            raise PrimitiveFailure("place.outside_region",
                                   f"{self.object!r} ({np.round(2 * reach, 3).tolist()} m across in x, y) at offset "
                                   f"{np.round(offset, 3).tolist()} m does not fit inside {self.region!r} (half extents "
                                   f"{np.round(region_half[:2], 3).tolist()} m)")
        center = T_region[:3, 3] + np.array([offset[0], offset[1], 0.0])
        T_place = place_pose(center, half, T_tcp_object=T_tcp_obj, surface_z_m=float(T_region[2, 3]))
        T_pre = T_place.copy()
        T_pre[2, 3] += self.approach_height_m
        self.set(self.place_key, T_place)
        self.set(self.preplace_key, T_pre)
        self.ctx.trace.record("place_pose", object=self.object, region=self.region, offset=np.round(offset, 4).tolist(),
                              place=T_place[:3, 3].round(4).tolist())
