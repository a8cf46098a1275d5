"""Pulling a drawer that stands out by the inside of its front, the closed fingers hooked behind it.

A drawer whose handle stands too low for the hand's closing fingers (LIBERO's bottom drawer:
its bar 4.6 cm over the table, the lower finger of an open Panda hand 4 cm under the tool
point) is pulled by its front instead, once it stands out of its body: the closed fingers,
pointing down, go into the drawer just behind its front and the hand moves out along the
drawer's axis (:class:`~phyagentos.primitives.affordance.ArticulateSlide` with ``lead_m``:
the fingers travel the gap to the front before the drawer moves).

It is pushed home the same way, without a grasp: the closed fingers, leaning in, before its
handle's outer face (skill ``push_drawer``).

:class:`ComputeDrawerHook` writes the pose behind the front (or before the handle) and the pose
above it.
"""

from __future__ import annotations

import numpy as np
from py_trees.common import Status

from .affordance import _entity
from .base import Primitive, PrimitiveFailure
from .door import FINGER_HALF_M
from .motion import nearer_reachable_hand
from .perception import entity_pose

__all__ = ["ComputeDrawerHook", "HOOK_CLEAR_M", "PUSH_LEAN_RAD"]

#: How far behind the inside of the drawer's front the closed fingers go down, m: the drawer's
#: perceived opening is good to a few millimetres (LIBERO's bottom drawer: read 2.3 mm short
#: on a generated scene) and the planning world's drawer stands where it was read.
HOOK_CLEAR_M = 0.008
#: Pushed in, the fingers point this far (rad) from straight down towards the drawer's body: the
#: hand, 6 cm over its tool point at the palm, then stands back from what is over the handle
#: (pointing straight down at LIBERO's bottom drawer, the arm met the cabinet 7 cm into the push;
#: at shut the palm would stand under the middle drawer's handle).
PUSH_LEAN_RAD = 0.8


class ComputeDrawerHook(Primitive):
    """The pose from which the closed fingers slide ``object`` without a grasp, and the pose
    above it.

    Pulled out (``pull``): behind the inside of its front. From the drawer entity as perceived (``kind: articulation``,
    ``attributes.support``: its box the floor out of the body, whose edge along the opening
    ``axis`` is the inside of the front): the tool point pointing down :data:`HOOK_CLEAR_M` plus
    the closed fingers' half thickness (:data:`~phyagentos.primitives.door.FINGER_HALF_M`)
    behind the front's inside. Pushed in: as far in front of the handle's outer face (its
    ``grasp`` centre and half ``size`` along the axis). Level with the handle's centre, across
    the drawer where its handle is, the fingers closing across the drawer; of the two such
    hands the one the arm reaches nearer the current wrist. Writes ``grasp_pose`` ((4, 4) world
    tcp) and ``pregrasp_pose`` (``approach_height_m`` above it).

    Args:
        object: the drawer (a perceived drawer entity).
        pull: true to pull it out (behind its front), false to push it in (before its handle).
        approach_height_m: the pose above, m.

    Raises:
        ValueError: ``approach_height_m`` not positive, ``pull`` not a bool.
        PrimitiveFailure: ``perception.not_open`` where a drawer to be pulled offers no floor out
            of its body (shut: nothing to hook behind; pull it by its handle), ``perception.affordance``
            where it is no drawer, ``ik.unreachable`` where the arm reaches neither hand.
    """

    def __init__(self, name: str, *, object: str, pull: bool = True, approach_height_m: float = 0.08,
                 snapshot: str = "snapshot"):
        super().__init__(name)
        if not approach_height_m > 0:
            raise ValueError(f"approach_height_m must be > 0, got {approach_height_m!r}")
        if not isinstance(pull, bool):
            raise ValueError(f"pull must be true (behind the front, pulling out) or false (in front of the handle, "
                             f"pushing in), got {pull!r}")
        self.object, self.approach_height_m, self.snapshot_key = object, float(approach_height_m), snapshot
        self.pull = pull
        self.reads(snapshot)
        self.writes("grasp_pose", "pregrasp_pose")

    def step(self):
        snapshot = self.get(self.snapshot_key)
        ent = _entity(snapshot, self.object)
        attrs = ent.get("attributes") or {}
        grasp = attrs.get("grasp") or {}
        if attrs.get("joint_type") != "slide" or attrs.get("axis") is None or grasp.get("position") is None:
            raise PrimitiveFailure("perception.affordance", f"{self.object!r} is no drawer (a slide with an axis and "
                                                            f"a handle)")
        u = np.asarray(attrs["axis"], dtype=float)[:2]
        u = u / np.linalg.norm(u)
        v = np.array([-u[1], u[0]])
        handle = np.asarray(grasp["position"], dtype=float)
        q = attrs.get("joint_position")
        shutting = not self.pull
        if shutting:  # in front of the handle's outer face, pushing it in
            face = float(handle[:2] @ u) + float((grasp.get("size") or [0.0, 0.0])[1])
            along = face + FINGER_HALF_M + HOOK_CLEAR_M
        else:  # behind the inside of the front, pulling it out
            if not attrs.get("support"):
                raise PrimitiveFailure("perception.not_open", f"{self.object!r} stands out {q} m: no floor out of its "
                                                              f"body to hook the fingers behind its front")
            T_box, half = entity_pose(snapshot, self.object)
            front = float(T_box[:2, 3] @ u + np.abs(T_box[:2, :2].T @ u) @ half[:2])
            along = front - FINGER_HALF_M - HOOK_CLEAR_M
        xy = u * along + v * float(handle[:2] @ v)
        # pushed in, the fingers point in and down so the hand stays clear of what stands over the
        # handle (the drawer above's handle, 6 cm over it when shut)
        lean = PUSH_LEAN_RAD if shutting else 0.0
        pointing = np.array([-u[0] * np.sin(lean), -u[1] * np.sin(lean), -np.cos(lean)])
        point = np.array([xy[0], xy[1], handle[2]])
        best = nearer_reachable_hand(self.ctx, np.array([v[0], v[1], 0.0]), pointing, [point])
        if best is None:
            raise PrimitiveFailure("ik.unreachable", f"{self.object!r}: the arm reaches no hand "
                                                     f"{'before its handle' if shutting else 'behind its front'} at "
                                                     f"{np.round(point, 3).tolist()} m")
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = best[1], point
        P = T.copy()
        P[2, 3] += self.approach_height_m
        self.set("grasp_pose", T)
        self.set("pregrasp_pose", P)
        self.ctx.trace.record("drawer_hook", leaf=self.name, object=self.object,
                              opening_m=attrs.get("joint_position"), hook=np.round(T[:3, 3], 4).tolist(),
                              pushing=shutting, turn_rad=round(best[0], 3))
        return Status.SUCCESS
