"""A grasp of a mug by its handle: the fingers across the handle's outer bar, the hand coming in
along the handle's direction from outside, pitched down.

Where a top-down grasp of the rim leaves the hand above the mug (no room under a microwave's
roof), a hand holding the handle stays out beside it: the mug can be carried into an opening
ahead of the hand. From what perception reports of a round body with a handle
(:mod:`phyagentos.perception.handle`: ``axis_xy``, ``handle_xy``, ``handle_reach_m``): the tool
point :data:`~phyagentos.motion.handle_grasp.GRIP_DEPTH_M` inside the handle's reach, at the body's mid-height, the hand's axis
pointing back along the handle's direction towards the cup and down by ``pitch_rad``, the
fingers closing horizontally across the bar.
"""

from __future__ import annotations

import math

import numpy as np
from py_trees.common import Status

from phyagentos.errors import IKError
from phyagentos.motion.handle_grasp import GRIP_DEPTH_M, handle_grasp_rotation, handle_grip_xy
from phyagentos.motion.ik import solve_ik

from .affordance import _entity
from .base import Primitive, PrimitiveFailure

__all__ = ["ComputeHandleGrasp", "GRIP_DEPTH_M"]

class ComputeHandleGrasp(Primitive):
    """Grasp and pre-grasp tcp poses taking ``object`` by its handle (module docstring).

    Writes ``grasp_pose`` and ``pregrasp_pose`` ((4, 4) world: the pre-grasp
    ``approach_height_m`` back along the hand's axis). Of the two hands (turned half a turn about
    their axis) the one the arm reaches at both poses, nearer the current wrist.

    Args:
        object: the object with a handle (its entity reports ``axis_xy``, ``handle_xy`` and
            ``handle_reach_m``: its handle seen).
        pitch_rad: the hand's axis below the horizontal, rad, in (0, pi/2): LIBERO's Panda does
            not reach a level hand pointing sideways low over the table at its middle (IK from
            31 seeds, LIBERO-10 task 9's generated scene 500), and does from 20 degrees down; at
            35 the palm, 20 cm across the fingers, met the other mug beside (3 of 4 generated
            scenes); at 50 it passes over it.
        approach_height_m: the pre-grasp, back along the hand's axis, m.

    Raises:
        ValueError: a value out of range.
    """

    def __init__(self, name: str, *, object: str, pitch_rad: float = math.radians(50.0),
                 approach_height_m: float = 0.08, snapshot: str = "snapshot"):
        super().__init__(name)
        if not 0.0 < pitch_rad < 0.5 * math.pi:
            raise ValueError(f"pitch_rad must be in (0, pi/2), got {pitch_rad!r}")
        if not approach_height_m > 0:
            raise ValueError(f"approach_height_m must be > 0, got {approach_height_m!r}")
        self.object, self.pitch_rad, self.approach_height_m = object, float(pitch_rad), float(approach_height_m)
        self.snapshot_key = snapshot
        self.reads(snapshot)
        self.writes("grasp_pose", "pregrasp_pose")

    #: Random IK seeds tried after the current configuration.
    IK_SEEDS = 12

    def _reaches(self, P: np.ndarray, G: np.ndarray, seeds, names, frame) -> bool:
        """Whether IK reaches the pre-grasp ``P`` from one of ``seeds`` and the grasp ``G`` from there."""
        target = self.ctx.target
        for seed in seeds:
            try:
                with self.ctx.profiler.section("ik"):
                    q = solve_ik(target.model, q_seed=seed, target=P, arm_joint_names=names, frame=frame).q
                    solve_ik(target.model, q_seed=q, target=G, arm_joint_names=names, frame=frame)
            except IKError:
                continue
            return True
        return False

    def step(self):
        ent = _entity(self.get(self.snapshot_key), self.object)
        attrs = ent.get("attributes") or {}
        if attrs.get("handle_xy") is None or attrs.get("handle_reach_m") is None or attrs.get("axis_xy") is None:
            raise PrimitiveFailure("perception.affordance", f"{self.object!r}: its handle is not seen (no handle_xy and "
                                                            f"handle_reach_m reported), so it cannot be taken by it")
        u = np.asarray(attrs["handle_xy"], dtype=float)
        u /= np.linalg.norm(u)
        xy = handle_grip_xy(attrs["axis_xy"], u, float(attrs["handle_reach_m"]))
        z = float(ent["position"][2])  # the body's mid-height: the handle's bar spans most of it
        target = self.ctx.target
        names, frame = tuple(target.arm_joint_names), target.tcp_site
        wrist = target.tcp_pose()[:3, :3]
        jids = [target.model.joint(n).id for n in names]
        lo, hi = target.model.jnt_range[jids, 0], target.model.jnt_range[jids, 1]
        rng = np.random.default_rng(self.ctx.seed)
        # IK from the current configuration, then from seeded random ones (a far reorientation traps a local solver)
        seeds = [target.arm_qpos(), *rng.uniform(lo, hi, size=(self.IK_SEEDS, len(names)))]
        best = None
        for turn in (0.0, math.pi):
            R = handle_grasp_rotation(u, self.pitch_rad)
            c, s = math.cos(turn), math.sin(turn)
            R = R @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            G = np.eye(4)
            G[:3, :3], G[:3, 3] = R, [xy[0], xy[1], z]
            P = G.copy()
            P[:3, 3] -= R[:, 2] * self.approach_height_m
            if not self._reaches(P, G, seeds, names, frame):
                continue
            angle = float(np.arccos(np.clip((np.trace(wrist.T @ R) - 1.0) / 2.0, -1.0, 1.0)))
            if best is None or angle < best[0]:
                best = (angle, G, P)
        if best is None:
            raise PrimitiveFailure("ik.unreachable", f"{self.object!r}: neither hand reaches its handle at "
                                                     f"{np.round([xy[0], xy[1], z], 3).tolist()} m")
        _, G, P = best
        self.set("grasp_pose", G)
        self.set("pregrasp_pose", P)
        self.ctx.trace.record("grasp_pose", leaf=self.name, object=self.object, affordance="handle",
                              grasp_kind="handle", observed_position=np.round(ent["position"], 4).tolist(),
                              grasp=G[:3, 3].round(4).tolist(), approach=G[:3, 2].round(4).tolist())
        return Status.SUCCESS
