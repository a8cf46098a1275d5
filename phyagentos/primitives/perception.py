"""Perception leaves: observe the world and derive grasp and place poses from it.

Poses come from the observed snapshot (what the robot perceives), not from the
simulator's ground truth, so perception error shows up as it would on hardware.
"""

from __future__ import annotations

import numpy as np

from phyagentos.motion.grasp import DEFAULT_MAX_GRASP_WIDTH_M, place_pose, top_down_grasp_candidates
from phyagentos.targets.contract import capabilities_of

from .base import Primitive, PrimitiveFailure
from .grasp_sense import plan_grasp
from .observation import has_cameras, make_perceiver, observe_record, perceive_now

__all__ = ["Observe", "ComputeGrasp", "ComputePlace", "entity_pose"]


def entity_pose(snapshot: dict, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``((4, 4) world pose, (3,) half extents in m)`` of entity ``name`` in a snapshot.

    Raises:
        PrimitiveFailure: ``perception.not_found`` listing the entities seen.
    """
    import mujoco  # noqa: PLC0415

    for ent in snapshot.get("entities", []):
        if ent["name"] == name:
            T = np.eye(4)
            T[:3, 3] = ent["position"]
            mat = np.zeros(9)
            mujoco.mju_quat2Mat(mat, np.asarray(ent["quat_wxyz"], dtype=float))
            T[:3, :3] = mat.reshape(3, 3)
            return T, np.asarray(ent.get("size") or (0.0, 0.0, 0.0), dtype=float)
    seen = sorted(e["name"] for e in snapshot.get("entities", []))
    raise PrimitiveFailure("perception.not_found", f"{name!r} is not in the observation; seen: {seen}")


class Observe(Primitive):
    """Observe the world through the robot's sensors into the blackboard (``out``) and
    ENVIRONMENT.md.

    On a target with cameras (``sensors.yaml``) every camera is captured and the
    session's Perceiver fuses the frames with proprioception into the perceived snapshot
    (:func:`~phyagentos.primitives.observation.perceive_now`; frames saved under the
    bundle's ``frames/``). A target without cameras reports its own observation.

    Args:
        out: blackboard key for the snapshot (entities with poses, relations).
        samples: observations fused (>= 1; each with fresh frames); 0 skips the
            observation and keeps what ``out`` holds (a tree can then offer a
            re-observation that a session switches on by parameter).

    The trace records ``observe`` {leaf, samples, stamp_s, objects: {name: {position,
    confidence, position_std_m}}, unknown}: perceived objects only, never simulator truth.
    """

    TOOLS = ("snapshot",)

    def __init__(self, name: str, *, out: str = "snapshot", samples: int = 1):
        super().__init__(name)
        if not isinstance(samples, int) or isinstance(samples, bool) or samples < 0:
            raise ValueError(f"samples must be an integer >= 0, got {samples!r}")
        self.out, self.samples = out, samples
        self.writes(out)

    def step(self):
        if self.samples == 0:
            return
        ctx = self.ctx
        target = ctx.target
        snapshot = None
        if has_cameras(target):
            if ctx.perceiver is None:
                ctx.perceiver = make_perceiver(target)
            ctx.observations += 1
            with ctx.profiler.section("perception"):
                snapshot = perceive_now(target, ctx.perceiver, samples=self.samples, evidence_dir=ctx.evidence_dir,
                                        evidence_rel=ctx.evidence_rel, tag=f"{ctx.observations:02d}_{self.name}")
        if snapshot is None:
            snapshot = (target.perceive(samples=self.samples) if capabilities_of(target).has_sensor("perception")
                        else target.snapshot())
        self.set(self.out, snapshot)
        self.ctx.trace.record("observe", leaf=self.name, samples=self.samples, **observe_record(snapshot))
        if self.ctx.on_observation is not None:
            self.ctx.on_observation(snapshot)


class ComputeGrasp(Primitive):
    """Top-down grasp and pre-grasp tcp poses for ``object`` from the observation.

    Args:
        object: entity name.
        approach_height_m: pre-grasp height above the grasp, m.
        candidate: which top-down grasp to use, best first (another approach
            direction: the hand turned 90 or 180 deg about the vertical; taken
            modulo the number of candidates the box allows).
        snapshot: blackboard key of the observation.
        grasp, pregrasp: blackboard keys written with (4, 4) world poses of the tcp.
    """

    def __init__(self, name: str, *, object: str, approach_height_m: float = 0.10, candidate: int = 0,
                 snapshot: str = "snapshot", grasp: str = "grasp_pose", pregrasp: str = "pregrasp_pose"):
        super().__init__(name)
        if approach_height_m <= 0:
            raise ValueError(f"approach_height_m must be > 0, got {approach_height_m}")
        if not isinstance(candidate, int) or isinstance(candidate, bool) or candidate < 0:
            raise ValueError(f"candidate must be an integer >= 0, got {candidate!r}")
        self.object, self.approach_height_m, self.candidate = object, float(approach_height_m), candidate
        self.snapshot_key, self.grasp_key, self.pregrasp_key = snapshot, grasp, pregrasp
        self.reads(snapshot)
        self.writes(grasp, pregrasp)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        T_obj, half = entity_pose(snapshot, self.object)
        ent = next((e for e in snapshot.get("entities", []) if e["name"] == self.object), {})
        shape = (ent.get("attributes") or {}).get("shape") or "box"
        plans = top_down_grasp_candidates(T_obj, half, approach_height_m=self.approach_height_m,
                                          shape=shape if shape in ("box", "cylinder", "sphere") else "box",
                                          max_width_m=self.ctx.target.max_grasp_width_m or DEFAULT_MAX_GRASP_WIDTH_M)
        plan = plans[self.candidate % len(plans)]
        plan_grasp(self.ctx.target, object=self.object, width_m=plan.width_m)
        self.set(self.grasp_key, plan.grasp)
        self.set(self.pregrasp_key, plan.pregrasp)
        self.ctx.trace.record("grasp_pose", leaf=self.name, object=self.object, candidate=self.candidate,
                              observed_position=T_obj[:3, 3].round(4).tolist(), grasp=plan.grasp[:3, 3].round(4).tolist(),
                              yaw_rad=round(plan.yaw_rad, 4))


class ComputePlace(Primitive):
    """Place and pre-place tcp poses that set the held object down inside ``region``.

    Args:
        object: the held object.
        region: target region entity, or another object to stack on (its top face
            is then the support surface).
        approach_height_m: pre-place height above the place pose, m.
        snapshot: blackboard key of the observation (object pose in hand, region).
        place, preplace: blackboard keys written with (4, 4) world tcp poses.

    The object's pose in the tcp frame comes from the observation and the arm's
    proprioception, so a place session needs nothing from the pick session but
    the world itself.
    """

    def __init__(self, name: str, *, object: str, region: str, approach_height_m: float = 0.10,
                 snapshot: str = "snapshot", place: str = "place_pose", preplace: str = "preplace_pose"):
        super().__init__(name)
        self.object, self.region, self.approach_height_m = object, region, float(approach_height_m)
        self.snapshot_key, self.place_key, self.preplace_key = snapshot, place, preplace
        self.reads(snapshot)
        self.writes(place, preplace)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        T_region, region_half = entity_pose(snapshot, self.region)
        T_obj, half = entity_pose(snapshot, self.object)
        T_tcp_obj = np.linalg.inv(self.ctx.target.tcp_pose()) @ T_obj
        # A region is a patch on its support surface (its z: 0 on the tabletop, a burner's
        # height in the kitchen); an object used as the support (stacking) offers its top
        # face: centre z plus its vertical half extent.
        kind = next((e.get("kind") for e in snapshot.get("entities", []) if e["name"] == self.region), "region")
        surface_z = float(T_region[2, 3] + np.abs(T_region[2, :3]) @ region_half) if kind == "object" else float(T_region[2, 3])
        T_place = place_pose(T_region[:3, 3], half, T_tcp_object=T_tcp_obj, surface_z_m=surface_z)
        T_pre = T_place.copy()
        T_pre[2, 3] += self.approach_height_m
        self.set(self.place_key, T_place)
        self.set(self.preplace_key, T_pre)
        self.ctx.trace.record("place_pose", object=self.object, region=self.region, place=T_place[:3, 3].round(4).tolist())
