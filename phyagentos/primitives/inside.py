"""Setting a held object down inside a fixture's room, through its mouth (a microwave's, behind
its door), the hand keeping its orientation.

The room is what perception reports of it (:mod:`phyagentos.perception.door`: an entity whose
box is the room's footprint from its floor down to the support, ``attributes.mouth`` the
outward normal of its open side, ``roof_z_m`` its roof). The object goes in level, ahead of the
hand that holds it (taken by its handle: :mod:`.handle_grasp`), to the back of the room
:data:`BACK_CLEAR_M` short of its back wall, across to the side away from its door's hinge
(``attributes.hinge_side``; centred without one: a door open less than a right angle leans
over the mouth on its hinge's side, where the hand, 20 cm across its fingers, would meet it),
just over the floor; the pre-place
is straight out through the mouth until the whole object stands outside it. Whether it fits is
judged by its footprint as perceived (:func:`footprint_reach`: a mug's round cup and handle, not
the box round both, which can be turned to span more than the room is deep); where it goes, by
its box.
"""

from __future__ import annotations

import numpy as np
from py_trees.common import Status

from phyagentos.motion.handle_grasp import handle_grasp_rotation

from .affordance import _entity
from .base import Primitive, PrimitiveFailure
from .perception import entity_pose

__all__ = ["ComputePlaceInside", "footprint_reach", "UPRIGHT_COS", "BACK_CLEAR_M", "ROOM_MARGIN_M", "VIEW_BACK_M",
           "VIEW_HEIGHT_M", "VIEW_PITCH_RAD"]

#: The object's far side this far from the room's back wall, m: set deep, its near side (and a
#: handle the hand holds there) stays clear of the door shutting the mouth.
BACK_CLEAR_M = 0.015
#: Room the object needs at its sides and over it, m.
ROOM_MARGIN_M = 0.005
#: Where the hand looks into the room from after letting go (its wrist camera along its axis):
#: this far out of the mouth, this high over the room's floor, pitched down this much (m, m,
#: rad). From there the wrist camera sees a mug set at the back of LIBERO's microwave whole
#: (LIBERO-10 task 9's generated scene 500, at 15, 25 and 35 degrees); from the pre-place,
#: pitched 50 degrees down, it sees the table in front of the mouth.
VIEW_BACK_M, VIEW_HEIGHT_M, VIEW_PITCH_RAD = 0.12, 0.12, 0.44


#: An object counts as standing upright, for its round body's footprint, when its vertical axis
#: is within about 25 degrees of the world's (the cosine): a mug carried level by its handle.
UPRIGHT_COS = 0.9


def footprint_reach(T_obj: np.ndarray, half: np.ndarray, attrs: dict):
    """``reach(d)``: how far (m) the footprint of an object at ``T_obj`` ((4, 4) world pose of
    its perceived box, ``half`` (3,) its half extents, m) reaches from the box's centre along
    the horizontal world direction ``d`` ((2,) unit vector).

    A round body with a handle (perception's ``axis_xy``, ``handle_xy``, ``handle_reach_m`` and
    ``body_radius_m`` in ``attrs``: :mod:`phyagentos.perception.handle`), standing upright, is
    its disc and the segment from its axis out to the handle's reach: from the axis,
    ``max(radius, reach * (handle . d))``. Otherwise the box's projection on ``d``. The box of a
    mug is the minimum-area rectangle round cup and handle, at whatever yaw that came out: LIBERO's
    white and yellow mug, 10.7 by 10.4 cm, boxed at 50 degrees to its handle, spans 15.5 cm both
    ways, where its cup (5.1 cm in radius) and its handle (8.4 cm from the axis) span 13.5 cm along
    the handle and 10.3 across it (perceived on generated LIBERO-10 task 9 scenes)."""
    T_obj = np.asarray(T_obj, dtype=float)
    half = np.asarray(half, dtype=float)
    try:
        axis = np.asarray(attrs["axis_xy"], dtype=float).reshape(2)
        handle = np.asarray(attrs["handle_xy"], dtype=float).reshape(2)
        reach_m, radius = float(attrs["handle_reach_m"]), float(attrs["body_radius_m"])
    except (KeyError, TypeError, ValueError):
        axis = None
    round_ = (axis is not None and abs(float(T_obj[2, 2])) >= UPRIGHT_COS and radius > 0.0 and reach_m >= 0.0
              and np.all(np.isfinite(axis)) and float(np.linalg.norm(handle)) > 0.5)

    def reach(d) -> float:
        d = np.asarray(d, dtype=float)[:2]
        if round_:
            u = handle / float(np.linalg.norm(handle))
            return float((axis - T_obj[:2, 3]) @ d) + max(radius, reach_m * float(u @ d))
        return float(np.abs(T_obj[:3, :3].T @ np.array([d[0], d[1], 0.0])) @ half)

    return reach


class ComputePlaceInside(Primitive):
    """Place and pre-place tcp poses that set the held ``object`` down inside ``region`` (a
    room with a ``mouth``) keeping the hand's current orientation (module docstring): the
    object's lowest point ``clearance_m`` over the room's floor, to the back and away from the
    door's hinge (placed by its perceived box, its fit judged by its footprint:
    :func:`footprint_reach`, a mug's cup and handle); the pre-place out along the
    mouth until the object's far side is ``entry_m`` outside it; and the pose the hand looks into
    the room from after letting go (:data:`VIEW_BACK_M`, :data:`VIEW_HEIGHT_M`,
    :data:`VIEW_PITCH_RAD`).

    Args:
        object: the held object.
        region: the room (an entity with ``attributes.mouth``).
        clearance_m: gap left under the object, m.
        entry_m: how far outside the mouth the object's far side starts, m.

    Raises:
        ValueError: a value out of range.
    """

    def __init__(self, name: str, *, object: str, region: str, clearance_m: float = 0.01, entry_m: float = 0.03,
                 snapshot: str = "snapshot", place: str = "place_pose", preplace: str = "preplace_pose",
                 view: str = "view_pose"):
        super().__init__(name)
        if not clearance_m >= 0 or not entry_m > 0:
            raise ValueError(f"clearance_m must be >= 0 and entry_m > 0, got {clearance_m!r}, {entry_m!r}")
        self.object, self.region = object, region
        self.clearance_m, self.entry_m = float(clearance_m), float(entry_m)
        self.snapshot_key, self.place_key, self.preplace_key, self.view_key = snapshot, place, preplace, view
        self.reads(snapshot)
        self.writes(place, preplace, view)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        attrs = _entity(snapshot, self.region).get("attributes") or {}
        if attrs.get("mouth") is None or attrs.get("roof_z_m") is None:
            raise PrimitiveFailure("perception.affordance", f"{self.region!r} reports no mouth and roof: it is no room "
                                                            f"behind a door to set things into")
        mouth = np.asarray(attrs["mouth"], dtype=float)[:2]
        mouth /= np.linalg.norm(mouth)
        across = np.array([-mouth[1], mouth[0]])
        T_r, half_r = entity_pose(snapshot, self.region)
        R2 = T_r[:2, :2]
        depth = float(np.abs(R2.T @ mouth) @ half_r[:2])
        width = float(np.abs(R2.T @ across) @ half_r[:2])
        floor_z, roof_z = float(T_r[2, 3] + half_r[2]), float(attrs["roof_z_m"])
        centre = T_r[:2, 3]
        back = centre - depth * mouth
        T_obj, half_o = entity_pose(snapshot, self.object)
        T_tcp = self.ctx.target.tcp_pose()
        T_tcp_obj = np.linalg.inv(T_tcp) @ T_obj
        R_o = T_obj[:3, :3]
        reach = footprint_reach(T_obj, half_o, _entity(snapshot, self.object).get("attributes") or {})
        # how far the object's footprint reaches from its centre to the room's back, to the mouth, and
        # to either side (m): a mug's round cup and its handle, not the box round both turned
        to_back, to_mouth = reach(-mouth), reach(mouth)
        to_plus, to_minus = reach(across), reach(-across)
        up_o = float(np.abs(R_o[2, :]) @ half_o)
        fits = (to_plus + to_minus + 2.0 * ROOM_MARGIN_M <= 2.0 * width
                and 2.0 * up_o + self.clearance_m + ROOM_MARGIN_M <= roof_z - floor_z
                and to_back + to_mouth + BACK_CLEAR_M <= 2.0 * depth)
        if not fits:
            raise PrimitiveFailure("perception.too_small", f"{self.object!r} ({to_back + to_mouth:.3f} x "
                                                      f"{to_plus + to_minus:.3f} x {2 * up_o:.3f} m as held) does not "
                                                      f"fit in {self.region!r} ({2 * depth:.3f} deep, {2 * width:.3f} "
                                                      f"wide, {roof_z - floor_z:.3f} m under its roof)")
        # where it goes is reckoned by its box, as before: the box errs outward round a mug's cup
        # and handle, and so set, to the back and away from the door's hinge (the open door leans
        # over that side; centred without one), the cup stands a little nearer the mouth, in view
        # of the look into the room, and the hand stays off the mouth's frame
        box = footprint_reach(T_obj, half_o, {})
        along_o, across_o = box(mouth), box(across)
        side = float(attrs.get("hinge_side") or 0.0)
        shift = -side * max(0.0, width - across_o - ROOM_MARGIN_M)
        xy = back + (BACK_CLEAR_M + along_o) * mouth + (float((centre - back) @ across) + shift) * across
        p_obj = np.array([xy[0], xy[1], floor_z + up_o + self.clearance_m])
        T_place = T_tcp.copy()
        T_place[:3, 3] = p_obj - T_tcp[:3, :3] @ T_tcp_obj[:3, 3]
        out = float((centre + depth * mouth - (xy - along_o * mouth)) @ mouth) + self.entry_m
        T_pre = T_place.copy()
        T_pre[:2, 3] += out * mouth
        T_view = np.eye(4)
        R_view = handle_grasp_rotation(mouth, VIEW_PITCH_RAD)
        flipped = R_view @ np.diag([-1.0, -1.0, 1.0])  # the same view, the hand turned half a turn about its axis
        # the one nearer the hand as it holds the object: a half turn of the wrist there took 8.8 s
        T_view[:3, :3] = max((R_view, flipped), key=lambda R: float(np.trace(T_tcp[:3, :3].T @ R)))
        view_xy = xy + (float((centre + depth * mouth - xy) @ mouth) + VIEW_BACK_M) * mouth
        T_view[:3, 3] = [view_xy[0], view_xy[1], floor_z + VIEW_HEIGHT_M]
        self.set(self.place_key, T_place)
        self.set(self.preplace_key, T_pre)
        self.set(self.view_key, T_view)
        self.ctx.trace.record("place_pose", leaf=self.name, object=self.object, region=self.region, inside=True,
                              place=T_place[:3, 3].round(4).tolist(), preplace=T_pre[:3, 3].round(4).tolist())
        return Status.SUCCESS
