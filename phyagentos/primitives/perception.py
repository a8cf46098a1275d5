"""Perception leaves: observe the world and derive grasp and place poses from it.

Poses come from the observed snapshot (what the robot perceives), not from the
simulator's ground truth, so perception error shows up as it would on hardware.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

import numpy as np

from phyagentos.errors import IKError
from phyagentos.geometry import VIEWER_SIDES, pose_matrix, rotation_about, viewer_side_xy, yaw_quat
from phyagentos.motion.cartesian import cartesian_path
from phyagentos.motion.grasp import (
    DEFAULT_MAX_GRASP_WIDTH_M,
    FRANKA_FINGERS,
    hand_yaw,
    place_pose,
    slid_grasp,
    slide_offsets,
    top_down_grasp_candidates,
    top_down_rotation,
    turn_offsets,
    turned_grasp,
)
from phyagentos.motion.rim_grasp import (
    DEFAULT_HANDLED_WALL_M,
    DEFAULT_RIM_WALL_M,
    RIM_PRESHAPE_CLEARANCE_M,
    handled,
    near_long_axis,
    near_short_axis,
    open_container,
    partly_seen_rim_graspable,
    rim_grasp_candidates,
    rim_graspable,
)
from phyagentos.motion.top_knob_grasp import top_knob_grasp_candidates, top_knob_graspable, top_knob_preshape_m
from phyagentos.perception.detect import OPEN_WALL_M
from phyagentos.targets.contract import capabilities_of

from .base import Primitive, PrimitiveFailure
from .grasp_sense import plan_grasp
from .motion import PLANNING_MARGIN_M, clear_ik, ik_options, session_checker
from .observation import has_cameras, make_perceiver, observe_record, perceive_now

__all__ = ["Observe", "ComputeGrasp", "ComputePlace", "entity_pose", "origin_pose", "declared_class", "beside_point",
           "landmark_box", "viewer_side", "leant_place", "SLIDE_STEPS_M", "SLIDE_EDGE_MARGIN_M",
           "HANG_MIN_M"]


def declared_class(target, name: str, entity: dict | None = None) -> str | None:
    """The category of object ``name``: the perceived entity's ``class`` attribute, else the
    class the user declared for it (``target.describe_declared()``), else None. A
    declaration, never the simulator's state."""
    cls = ((entity or {}).get("attributes") or {}).get("class")
    if cls:
        return str(cls)
    describe = getattr(target, "describe_declared", None)
    if describe is None:
        return None
    try:
        objects = describe().get("objects", [])
    except Exception:  # noqa: BLE001 - a target that cannot describe its scene declares no class
        return None
    return next((str(o["class"]) for o in objects if o.get("name") == name and o.get("class")), None)


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


def _xy_attribute(ent: dict, key: str) -> np.ndarray | None:
    """The entity's ``attributes[key]`` as a (2,) array (world x, y), or None when absent or not
    two numbers."""
    v = (ent.get("attributes") or {}).get(key)
    if not (isinstance(v, (list, tuple)) and len(v) == 2):
        return None
    return np.array([float(v[0]), float(v[1])])


def _body_frame(T_obj: np.ndarray, ent: dict) -> np.ndarray | None:
    """``T_obj`` ((4, 4) world) moved onto the entity's round body's axis (``attributes.axis_xy``)
    and turned about world z so that its x axis points to the handle (``attributes.handle_xy``):
    a mug's frame for a rim grasp across its handle; None when perception gave neither."""
    axis, handle = _xy_attribute(ent, "axis_xy"), _xy_attribute(ent, "handle_xy")
    if axis is None or handle is None or float(np.linalg.norm(handle)) <= 0.0:
        return None
    u = np.array([handle[0], handle[1], 0.0]) / float(np.linalg.norm(handle))
    T = np.array(T_obj, dtype=float)
    T[:3, :3] = np.column_stack([u, [-u[1], u[0], 0.0], [0.0, 0.0, 1.0]])
    T[:2, 3] = axis
    return T


def origin_pose(snapshot: dict, name: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`entity_pose` of entity ``name`` with its position moved, on the ground plane, to
    the point a place sets on the spot: for an object whose model origin perception gives
    (``attributes.origin_xy``, (2,) world m: a mug's, its cup's axis moved towards its handle,
    :mod:`phyagentos.perception.handle`), midway between that origin and its body's axis
    (``attributes.axis_xy``), or the origin where the axis is not given. The verifier's ``on``
    judges the origin, and the body must stand on a dish's floor, not lean on its rim: set with
    their origins on a plate's centre, LIBERO's mugs (axis 1.65 cm away) leant 5-6 degrees on
    its rim, and their tops, seen 1 cm off, left the verdict undecided.

    Raises:
        PrimitiveFailure: ``perception.not_found`` listing the entities seen.
    """
    T, half = entity_pose(snapshot, name)
    ent = next(e for e in snapshot.get("entities", []) if e["name"] == name)
    origin, axis = _xy_attribute(ent, "origin_xy"), _xy_attribute(ent, "axis_xy")
    if origin is not None:
        T[:2, 3] = origin if axis is None else 0.5 * (origin + axis)
    return T, half


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
        or_if: blackboard key of a flag (written earlier in the tree) that makes a skipped
            observation (``samples`` 0) take one sample: ``ComputeGrasp``'s ``look_closer``,
            raised when the object was seen only in part, so the pick looks again from its
            pre-grasp, its wrist camera over the object. ``None``: ``samples`` alone decides.

    The trace records ``observe`` {leaf, samples, stamp_s, objects: {name: {position,
    confidence, position_std_m}}, unknown}: perceived objects only, never simulator truth.
    """

    TOOLS = ("snapshot",)

    def __init__(self, name: str, *, out: str = "snapshot", samples: int = 1, or_if: str | None = None):
        super().__init__(name)
        if not isinstance(samples, int) or isinstance(samples, bool) or samples < 0:
            raise ValueError(f"samples must be an integer >= 0, got {samples!r}")
        if or_if is not None and (not isinstance(or_if, str) or not or_if):
            raise ValueError(f"or_if must be a blackboard key or null, got {or_if!r}")
        self.out, self.samples, self.or_if = out, samples, or_if
        self.writes(out)
        if or_if is not None:
            self.reads(or_if)

    def step(self):
        samples = self.samples
        if samples == 0 and self.or_if is not None:
            try:
                samples = 1 if self.get(self.or_if) else 0
            except PrimitiveFailure:  # never raised earlier in the tree: nothing asks for a look
                samples = 0
        if samples == 0:
            return
        ctx = self.ctx
        target = ctx.target
        snapshot = None
        if has_cameras(target):
            if ctx.perceiver is None:
                ctx.perceiver = make_perceiver(target)
            ctx.observations += 1
            with ctx.profiler.section("perception"):
                snapshot = perceive_now(target, ctx.perceiver, samples=samples, evidence_dir=ctx.evidence_dir,
                                        evidence_rel=ctx.evidence_rel, tag=f"{ctx.observations:02d}_{self.name}")
        if snapshot is None:
            snapshot = (target.perceive(samples=samples) if capabilities_of(target).has_sensor("perception")
                        else target.snapshot())
        self.set(self.out, snapshot)
        self.ctx.trace.record("observe", leaf=self.name, samples=samples, **observe_record(snapshot))
        if self.ctx.on_observation is not None:
            self.ctx.on_observation(snapshot)


#: How much higher (m) a pick's pre-grasp is tried when no grasp candidate is clear from the
#: skill's approach height (the recovery ``another_approach`` asks for 0.15 m against the
#: default 0.10 m: the same move, without spending a session on the failure).
HIGHER_APPROACH_M = 0.05
#: Lower pre-grasp heights (m above the grasp) a rim grasp tries, in order, when from the skill's
#: approach height no rim point is usable and some were refused only because their pre-grasp is
#: out of the arm's reach (a bowl in LIBERO's open top drawer, 0.8 m from the base: the pre-grasp
#: 10 cm above its rim is past the Panda's reach while the grasp is not).
LOWER_APPROACH_M = (0.06, 0.04)
#: How far (m) an across grasp whose fingertips would enter the support is raised, in these
#: steps, while the finger pads still reach :data:`MIN_PAD_OVERLAP_M` down the object's side.
#: The support a camera sees need not be where things rest: LIBERO-90's living-room table is
#: seen at z 0.425 m, but its collision box, on which the items stand, tops out at 0.4368 m, so
#: a 1.8 cm cream cheese box is perceived 3.1 cm tall and a grasp set 1.9 cm above the seen
#: table put the fingertips 5 mm into the real one (LIBERO-90 task 47, a training task).
GRASP_RAISE_STEPS_M = (0.004, 0.008, 0.012, 0.016)
#: How far (m) an object set down beside a landmark ("to the right of the plate") stands clear of
#: the landmark's perceived edge: a place lands within about 5 mm of where it was aimed.
BESIDE_GAP_M = 0.015
#: The least depth (m) below the object's top at which the fingertips of a raised grasp close.
MIN_PAD_OVERLAP_M = 0.01


def _wrap_rad(a: float) -> float:
    return float((a + np.pi) % (2.0 * np.pi) - np.pi)


def _unusable(ctx, obj: str, plan, *, opening_m: float | None = None, close_to_m: float | None = None) -> Blocked | None:
    """Why the arm cannot take grasp ``plan`` of object ``obj`` (:func:`reach_blocked` of its
    pre-grasp, then its grasp; the fingers ``opening_m`` m open each at the grasp when given,
    else as they are; with ``close_to_m``, their close down to that opening too); ``None``
    when it can."""
    return reach_blocked(ctx, obj, ("pre-grasp", plan.pregrasp), ("grasp", plan.grasp), opening_m=opening_m,
                         close_to_m=close_to_m)


class Blocked(str):
    """Why a reach is blocked: its text (a ``str``, as traced), with the ``stage`` whose pose
    failed (the label it was given) and whether it ``collides`` (an IK solution that touches
    the scene) rather than has no solution."""

    stage: str
    collides: bool

    def __new__(cls, text: str, *, stage: str, collides: bool) -> "Blocked":
        out = super().__new__(cls, text)
        out.stage, out.collides = stage, collides
        return out


def _object_body(ctx, obj: str) -> str | None:
    """The simulator body of object ``obj`` that a grasp may touch, or None (a target
    without object bodies)."""
    try:
        return ctx.target.object_body(obj)
    except Exception:  # noqa: BLE001 - a target without object bodies
        return None


def reach_blocked(ctx, obj: str, above: tuple[str, np.ndarray], at: tuple[str, np.ndarray], *,
                  opening_m: float | None = None, close_to_m: float | None = None) -> Blocked | None:
    """Why the arm cannot reach ``above`` then ``at`` (``(label, (4, 4) world tcp pose)``):
    no IK solution clear of collisions (:func:`~.motion.clear_ik`, SolveIK's seeds) for the
    pose above (the planner's goal: its margin), or for the pose at the object from there
    (reached by a straight move, touching object ``obj`` by design: only penetration of
    anything else counts; the fingers ``opening_m`` m open each when given: a hand pre-shaped
    after the pose above). With ``close_to_m`` (m per finger), the fingers' close at the pose
    at the object is checked too, at openings :data:`CLOSE_SWEEP_STEP_M` apart from where they
    start down to ``close_to_m``: a finger that would meet anything but ``obj`` on its way in
    (a drawer's wall beside a bowl's rim, outside the open hand) blocks it (stage ``close``).
    ``None`` when all is reachable and clear, else a :class:`Blocked`."""
    own = _object_body(ctx, obj)
    q = None
    for (label, pose), allow, margin, opening in ((above, None, PLANNING_MARGIN_M, None), (at, own, 0.0, opening_m)):
        try:
            sol, pairs, _ = clear_ik(ctx, pose, q_seed=q, allow=allow, margin_m=margin, opening_m=opening)
        except IKError as exc:
            return Blocked(f"{label}: {str(exc)[:100]}", stage=label, collides=False)
        if pairs:
            return Blocked(f"{label} collides: {', '.join('-'.join(pr) for pr in pairs[:3])}", stage=label,
                           collides=True)
        q = sol.q
    if close_to_m is not None and q is not None:
        return _close_blocked(ctx, own, q, opening_m, float(close_to_m))
    return None


#: The close of a grasp is checked at finger openings this far apart, m: under the thickness of
#: the Franka Hand's finger pads (8 mm), so no wall a finger could pass through lies between two
#: checks.
CLOSE_SWEEP_STEP_M = 0.005


def _close_blocked(ctx, own: str | None, q: np.ndarray, opening_m: float | None, close_to_m: float) -> Blocked | None:
    """Why the fingers cannot close from ``opening_m`` (m per finger; ``None``: as they are)
    to ``close_to_m`` with the arm at ``q`` (n,) rad: the first opening, every
    :data:`CLOSE_SWEEP_STEP_M`, at which they meet anything but body ``own``; ``None`` when
    they can (or the target has no collision model)."""
    try:
        start = float(opening_m) if opening_m is not None else float(ctx.target.gripper_opening())
    except Exception:  # noqa: BLE001 - a target that reports no opening: nothing to sweep
        return None
    if start <= close_to_m:
        return None
    try:
        checker = session_checker(ctx, margin_m=0.0)  # the world synced once; only the fingers move below
    except Exception:  # noqa: BLE001 - a target without a collision model
        return None
    n = int(np.ceil((start - close_to_m) / CLOSE_SWEEP_STEP_M - 1e-9))
    for o in np.linspace(start, close_to_m, n + 1)[1:]:
        checker.set_gripper_opening(float(o))
        pairs = [pr for pr in checker.colliding_pairs(q) if own not in pr]
        if pairs:
            return Blocked(f"close collides {o * 1000:.0f} mm open: {', '.join('-'.join(pr) for pr in pairs[:3])}",
                           stage="close", collides=True)
    return None


class ComputeGrasp(Primitive):
    """Top-down grasp and pre-grasp tcp poses for ``object`` from the observation.

    An object too wide to take across whose perceived category is an open container (a
    bowl: :func:`~phyagentos.motion.rim_grasp.rim_graspable`, on its declared class and
    perceived shape and size) is taken by its rim instead
    (:func:`~phyagentos.motion.rim_grasp.rim_grasp_candidates`): one finger inside, one
    outside, closing on the wall; the rim points are tried nearest the current hand yaw
    first, those whose open outer finger would come down on another perceived object last,
    and only those whose grasp and pre-grasp the arm reaches (IK from the current joints)
    are kept. The close then expects the wall's thickness between the fingers, not the
    bowl's diameter. A container seen only in part (a box whose long side is the rim's
    diameter, its far side hidden: :func:`~phyagentos.motion.rim_grasp.partly_seen_rim_graspable`)
    is taken by its rim too, at points near the ends of the long side only. An object too wide
    (or nearly: :func:`~phyagentos.motion.top_knob_grasp.top_knob_graspable`) with a knob on its top
    that perception reports (a moka pot's lid) is taken by the knob, the hand pre-shaped to it
    (:meth:`_top_knob_plan`). When no rim point
    is usable from ``approach_height_m`` and some pre-grasps were out of reach while their
    grasps are not, the pre-grasp is tried lower (:data:`LOWER_APPROACH_M`).

    Args:
        object: entity name.
        approach_height_m: pre-grasp height above the grasp, m.
        candidate: which top-down grasp to use, best first (another approach
            direction: the hand turned 90 or 180 deg about the vertical; taken
            modulo the number of candidates the box allows; for a rim grasp another
            reachable rim point). A candidate whose pre-grasp or grasp the arm cannot
            reach clear of the scene gives way to the next one that it can.
        rim_wall_m: assumed wall thickness of a container taken by its rim, m; None: the
            perceiver's ``holding.rim_wall_m`` (``holding.handled_wall_m`` for a mug;
            perception.yaml), else :data:`~phyagentos.motion.rim_grasp.DEFAULT_RIM_WALL_M`
            (:data:`~phyagentos.motion.rim_grasp.DEFAULT_HANDLED_WALL_M`).
        snapshot: blackboard key of the observation.
        grasp, pregrasp: blackboard keys written with (4, 4) world poses of the tcp.
        look_closer: blackboard key written True when the object was seen only in part (the
            rim of a partly seen container), else False: the pick's re-observation at the
            pre-grasp (``Observe`` ``or_if``) then takes place.

    Raises (as failures): ``IKError`` when the object is too wide and no container, or no
    rim point is reachable (the message lists why for each).
    """

    def __init__(self, name: str, *, object: str, approach_height_m: float = 0.10, candidate: int = 0,
                 rim_wall_m: float | None = None, snapshot: str = "snapshot", grasp: str = "grasp_pose",
                 pregrasp: str = "pregrasp_pose", look_closer: str = "look_closer"):
        super().__init__(name)
        if approach_height_m <= 0:
            raise ValueError(f"approach_height_m must be > 0, got {approach_height_m}")
        if not isinstance(candidate, int) or isinstance(candidate, bool) or candidate < 0:
            raise ValueError(f"candidate must be an integer >= 0, got {candidate!r}")
        if rim_wall_m is not None and not (isinstance(rim_wall_m, (int, float)) and 0.0 < float(rim_wall_m) < 0.05):
            raise ValueError(f"rim_wall_m must be a number in (0, 0.05) m or null, got {rim_wall_m!r}")
        self.rim_wall_m = None if rim_wall_m is None else float(rim_wall_m)
        self.object, self.approach_height_m, self.candidate = object, float(approach_height_m), candidate
        self.snapshot_key, self.grasp_key, self.pregrasp_key = snapshot, grasp, pregrasp
        self.look_closer_key = look_closer
        self.reads(snapshot)
        self.writes(grasp, pregrasp, look_closer)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        T_obj, half = entity_pose(snapshot, self.object)
        ent = next((e for e in snapshot.get("entities", []) if e["name"] == self.object), {})
        shape = (ent.get("attributes") or {}).get("shape") or "box"
        max_width = self.ctx.target.max_grasp_width_m or DEFAULT_MAX_GRASP_WIDTH_M
        category = declared_class(self.ctx.target, self.object, ent)
        extra = {}
        if rim_graspable(category, shape, half, max_width_m=max_width):
            mug = handled(category)  # near the ends of its short side, away from its handle, as round as its body
            lo = float(min(half[0], half[1]))
            body = np.array([lo, lo, float(half[2])]) if mug else half
            short = half if mug else None
            if mug and (turned := _body_frame(T_obj, ent)) is not None:
                # its cup's axis and handle seen: the rim points across the handle, about the axis
                T_obj, short = turned, np.array([lo + 1.0, lo, float(half[2])])
                extra["about_axis"] = True
            plan, rim = self._rim_plan(snapshot, T_obj, body, max_width, short_axis_of=short)
            extra.update(rim)
        elif partly_seen_rim_graspable(category, shape, half, max_width_m=max_width):
            # seen in part (its far side hidden): the long side is the rim's diameter
            hi = float(max(half[0], half[1]))
            plan, extra = self._rim_plan(snapshot, T_obj, np.array([hi, hi, float(half[2])]), max_width,
                                         long_axis=True)
            extra["partly_seen"] = True
        elif top_knob_graspable(ent.get("attributes") or {}, half, shape=shape, max_width_m=max_width):
            plan, extra = self._top_knob_plan(ent["attributes"], T_obj, half, max_width)
        else:
            plan, extra = self._across_plan(T_obj, half, shape if shape in ("box", "cylinder", "sphere") else "box",
                                            max_width)
        plan_grasp(self.ctx.target, object=self.object, width_m=plan.width_m, kind=extra.get("grasp_kind", "across"),
                   preshape_m=extra.get("preshape_m"))
        self.set(self.grasp_key, plan.grasp)
        self.set(self.pregrasp_key, plan.pregrasp)
        self.set(self.look_closer_key, bool(extra.get("partly_seen") or extra.pop("look_closer", False)))
        self.ctx.trace.record("grasp_pose", leaf=self.name, object=self.object, candidate=self.candidate,
                              observed_position=T_obj[:3, 3].round(4).tolist(), grasp=plan.grasp[:3, 3].round(4).tolist(),
                              yaw_rad=round(plan.yaw_rad, 4), **extra)

    def _across_plan(self, T_obj: np.ndarray, half: np.ndarray, shape: str, max_width: float):
        """Candidate ``self.candidate`` of the top-down grasps across the object (modulo their
        number) or, when the arm cannot reach it clear of the scene (:func:`_unusable`: a
        pre-grasp whose forearm passes through a neighbouring bottle), the next one that it
        can, in candidate order; when none is clear at ``approach_height_m``, the same from
        :data:`HIGHER_APPROACH_M` higher (an object near the base, the elbow folded over the
        neighbours); when none is clear either way, the first refused only at its grasp (its
        pre-grasp, the planner's goal, reached clear; the fingertips at the grasp in what is
        under or beside the object, where the straight approach stops on contact: a flat cream
        cheese box beside a milk carton, whose pre-grasps from 10 cm meet the carton and whose
        grasps from 15 cm put the fingertips in the table, traced ``fallback``), else candidate
        ``self.candidate`` as before (the planner then says why). Re-computed with a pre-grasp
        already chosen (``RecomputeGrasp`` after a closer look), the candidate whose hand yaw
        is nearest that pre-grasp's, at its height: the refinement never turns the hand. When no centred grasp of a box is clear
        from either height, the same candidates slid along the side they hold
        (:func:`~phyagentos.motion.grasp.slide_offsets`: :data:`~phyagentos.motion.grasp.OFF_CENTRE_STEPS_M`,
        both pads still on the box): a carton standing beside a cream cheese box along the
        closing direction meets the hand, not the box, and a grasp 2.5 cm to one side clears
        it. A re-computed grasp keeps the slide of the pre-grasp it refines. Returns the plan
        and the trace fields that say so."""
        try:
            previous = np.asarray(self.get(self.pregrasp_key), dtype=float)
        except PrimitiveFailure:
            previous = None
        if previous is not None and previous.shape == (4, 4):
            # re-computed from the pre-grasp the arm went to (RecomputeGrasp after a closer
            # look): the same side and height, refined; never another candidate
            plans = top_down_grasp_candidates(T_obj, half, approach_height_m=self.approach_height_m, shape=shape,
                                              max_width_m=max_width, fingers_m=self._fingers)
            height = max(self.approach_height_m, float(previous[2, 3] - plans[0].grasp[2, 3]))
            plans = top_down_grasp_candidates(T_obj, half, approach_height_m=height, shape=shape, max_width_m=max_width,
                                              fingers_m=self._fingers)
            yaw = hand_yaw(previous)
            best = min(range(len(plans)), key=lambda k: abs(_wrap_rad(hand_yaw(plans[k].grasp) - yaw)))
            plan = plans[best]
            slid = turn = 0.0
            if shape == "box":  # the slide of the pre-grasp the arm went to, while both pads stay on the box
                along = float(np.dot(previous[:3, 3] - plan.pregrasp[:3, 3], plan.grasp[:3, 0]))
                fits = [o for o in slide_offsets(plan, T_obj, half, steps_m=(abs(along),)) if o * along > 0]
                slid = fits[0] if abs(along) > 0.002 and fits else 0.0
                plan = slid_grasp(plan, slid) if slid else plan
                # ... and its turn, while the box still fits between the fingers
                off = _wrap_rad(yaw - hand_yaw(plan.grasp))
                turns = turn_offsets(plan, T_obj, half, steps_rad=(abs(off),), max_width_m=max_width)
                turn = off if abs(off) > math.radians(1.0) and turns else 0.0
                plan = turned_grasp(plan, turn, T_obj, half) if turn else plan
            plan, raised, _ = self._clear_of_support(plan, T_obj, half)  # as high as the first plan's, if need be
            used = {"candidate_used": best} if best != self.candidate % len(plans) else {}
            return plan, {**used, **({"raised_m": raised} if raised else {}),
                          **({"slid_m": round(slid, 4)} if slid else {}),
                          **({"turned_rad": round(turn, 3)} if turn else {})}
        refused = []
        first = None
        fallback = None  # the first plan refused only at its grasp: the planner reaches its pre-grasp
        heights = (self.approach_height_m, self.approach_height_m + HIGHER_APPROACH_M)
        for mode in (("centred", "slid", "turned") if shape == "box" else ("centred",)):
            for height in heights:
                plans = top_down_grasp_candidates(T_obj, half, approach_height_m=height, shape=shape,
                                                  max_width_m=max_width, fingers_m=self._fingers)
                first = first or plans[self.candidate % len(plans)]
                for k in range(len(plans)):
                    i = (self.candidate + k) % len(plans)
                    variants = ([(0.0, 0.0)] if mode == "centred"
                                else [(o, 0.0) for o in slide_offsets(plans[i], T_obj, half)] if mode == "slid"
                                else [(0.0, a) for a in turn_offsets(plans[i], T_obj, half, max_width_m=max_width)])
                    for offset, turn in variants:
                        base = slid_grasp(plans[i], offset) if offset else plans[i]
                        plan, raised, why = self._clear_of_support(
                            turned_grasp(base, turn, T_obj, half) if turn else base, T_obj, half)
                        if why is None:
                            used = {"candidates_refused": refused, "candidate_used": i,
                                    "approach_height_m": round(height, 3)}
                            used = {**(used if refused else {}), **({"raised_m": raised} if raised else {}),
                                    **({"slid_m": round(offset, 4)} if offset else {}),
                                    **({"turned_rad": round(turn, 3)} if turn else {})}
                            return plan, used
                        how = (f" slid {offset * 100:+.1f} cm" if offset else "") + (
                            f" turned {math.degrees(turn):+.0f} deg" if turn else "")
                        refused.append(f"candidate {i}{how} from {height:.2f} m: {why}")
                        if fallback is None and isinstance(why, Blocked) and why.stage == "grasp":
                            fallback = (plan, i, height, refused[-1])
        if fallback is not None:
            plan, i, height, line = fallback
            return plan, {"candidates_refused": refused, "candidate_used": i, "approach_height_m": round(height, 3),
                          "fallback": line}
        return first, {"candidates_refused": refused}

    def _top_knob_plan(self, attrs: dict, T_obj: np.ndarray, half: np.ndarray, max_width: float):
        """The knob grasp (:func:`~phyagentos.motion.top_knob_grasp.top_knob_grasp_candidates`):
        candidate ``self.candidate`` among those the arm reaches clear of the scene with the
        hand pre-shaped to the knob (:func:`_unusable`), the next usable one in order when it
        does not; re-computed with a pre-grasp already chosen (``RecomputeGrasp``), the one
        whose yaw is nearest that pre-grasp's, from its height. Returns the plan and the trace
        fields (``grasp_kind: top_knob``).

        Raises:
            IKError: no candidate is usable (the message lists why for each).
        """
        R = np.asarray(T_obj, dtype=float)[:3, :3]
        # the knob's faces line up with the body's axes: the handle's direction where perception
        # gives it (a moka pot's knob is a box), or the way the object reaches farthest from
        # the knob (its handle and spout), else the footprint's long side (its rectangle may
        # stand turned on the octagon)
        axis, axis_from = None, "footprint"
        for key, source in (("handle_xy", "handle"), ("top_knob_axis_xy", "reach")):
            v = _xy_attribute({"attributes": attrs}, key)
            if v is not None and float(np.linalg.norm(v)) > 0.0:
                axis, axis_from = v, source
                break
        seen_axis = axis is not None
        if axis is None:
            axis = R[:2, 0] if half[0] >= half[1] else R[:2, 1]
        top = float(attrs.get("top_knob_base_z_m") or T_obj[2, 3] + np.abs(R[2, :]) @ np.asarray(half, dtype=float))
        radius = float(attrs.get("top_knob_radius_m") or 0.006)
        preshape = top_knob_preshape_m(radius, max_width_m=max_width)
        T_tcp = np.asarray(self.ctx.target.tcp_pose(), dtype=float)
        q = np.asarray(self.ctx.target.arm_qpos(), dtype=float)

        def candidates(height: float):
            return top_knob_grasp_candidates(attrs["top_knob_xy"], float(attrs["top_knob_z_m"]), radius,
                                             body_top_z_m=top, long_axis_yaw_rad=float(np.arctan2(axis[1], axis[0])),
                                             approach_height_m=height, current_yaw_rad=hand_yaw(T_tcp),
                                             current_q7_rad=float(q[6]) if q.shape == (7,) else None)

        fields = {"grasp_kind": "top_knob", "preshape_m": round(preshape, 4), "top_knob_xy": list(attrs["top_knob_xy"]),
                  "top_knob_z_m": attrs["top_knob_z_m"], "axis_from": axis_from,
                  # no axis seen: the wrist camera looks from the pre-grasp (it sees the handle there)
                  "look_closer": not seen_axis}
        try:
            previous = np.asarray(self.get(self.pregrasp_key), dtype=float)
        except PrimitiveFailure:
            previous = None
        if previous is not None and previous.shape == (4, 4):
            # refined from the pre-grasp's height: the yaw nearest the pre-grasp's (a turn of 45 deg
            # at most, to the faces the closer look gives) whose grasp the arm reaches clear
            plans = candidates(self.approach_height_m)
            plans = candidates(max(self.approach_height_m, float(previous[2, 3] - plans[0].grasp[2, 3])))
            yaw = hand_yaw(previous)
            ranked = sorted(plans, key=lambda pl: abs(_wrap_rad(pl.yaw_rad - yaw)))
            usable = next((pl for pl in ranked if _unusable(self.ctx, self.object, pl, opening_m=preshape) is None),
                          ranked[0])
            return usable, {**fields, "look_closer": False}
        plans = candidates(self.approach_height_m)
        why = []
        for k in range(len(plans)):
            i = (self.candidate + k) % len(plans)
            bad = _unusable(self.ctx, self.object, plans[i], opening_m=preshape)
            if bad is None:
                return plans[i], {**fields, **({"candidate_used": i, "candidates_refused": why} if why else {})}
            why.append(f"knob candidate {i} (yaw {plans[i].yaw_rad:.2f} rad): {bad[:160]}")
        raise IKError(f"no knob grasp of {self.object!r} is reachable: " + "; ".join(why))

    @property
    def _fingers(self) -> tuple[float, float, float]:
        """The target's ``finger_geometry_m`` (m along the tcp's z), else the Franka Hand's."""
        return tuple(getattr(self.ctx.target, "finger_geometry_m", None) or FRANKA_FINGERS)  # type: ignore[return-value]

    def _clear_of_support(self, plan, T_obj: np.ndarray, half: np.ndarray):
        """``(plan, raised m, why)``: ``plan`` when the arm reaches it clear (:func:`_unusable`);
        when only its grasp collides (the fingertips in what the object stands on), the same
        grasp raised by the first step of :data:`GRASP_RAISE_STEPS_M` that is clear while the
        finger pads' bottom (the target's ``finger_geometry_m``) still closes
        :data:`MIN_PAD_OVERLAP_M` below the object's top (the perceived centre plus its
        vertical half extent); else ``plan`` and why not."""
        why = _unusable(self.ctx, self.object, plan)
        if not (isinstance(why, Blocked) and why.stage == "grasp" and why.collides):
            return plan, 0.0, why
        top = float(T_obj[2, 3] + np.abs(T_obj[2, :3]) @ np.asarray(half, dtype=float))
        for dz in GRASP_RAISE_STEPS_M:
            if float(plan.grasp[2, 3]) + dz - self._fingers[1] > top - MIN_PAD_OVERLAP_M:
                break  # the pads would close less than MIN_PAD_OVERLAP_M below its top
            up = np.eye(4)
            up[2, 3] = dz
            raised = replace(plan, grasp=up @ plan.grasp, pregrasp=up @ plan.pregrasp)
            if _unusable(self.ctx, self.object, raised) is None:
                return raised, dz, None
        return plan, 0.0, why

    def _reaches(self, pose: np.ndarray) -> bool:
        """Whether the arm has an IK solution clear of the scene for the (4, 4) world tcp
        ``pose`` alone (touching the object being grasped allowed)."""
        try:
            _, pairs, _ = clear_ik(self.ctx, pose, allow=_object_body(self.ctx, self.object), margin_m=0.0)
        except IKError:
            return False
        return not pairs

    def _rim_plan(self, snapshot: dict, T_obj: np.ndarray, half: np.ndarray, max_width: float, *,
                  long_axis: bool = False, short_axis_of: np.ndarray | None = None):
        """The rim grasp (candidate ``self.candidate`` among the usable ones) and the trace
        fields that say so.

        A rim point is usable when the arm reaches its pre-grasp and grasp clear of the
        scene (:func:`_unusable`: the planner's collision model and margin; at the grasp,
        contact with the bowl itself is expected) and its fingers close on the wall without
        meeting anything else on their way in (``close_to_m``: half the wall). Points are
        ranked by :func:`~phyagentos.motion.rim_grasp.rim_grasp_candidates` with the arm's
        base as the preferred side (the shorter reach; the base does not move, so the
        ranking is the same before and after the move to the pre-grasp). Re-computed with
        a pre-grasp already chosen (``RecomputeGrasp`` after a re-observation), the usable
        point nearest that pre-grasp is kept, from that pre-grasp's height: the refinement
        never switches sides. ``long_axis``: only the points near the ends of the perceived
        box's long side (a container seen in part, ``half`` already made round);
        ``short_axis_of``: the perceived (3,) half extents of a handled container (a mug,
        ``half`` its round body), whose points are kept near the ends of the short side only.
        """
        target = self.ctx.target
        wall = self.rim_wall_m
        mug = short_axis_of is not None
        if wall is None:
            perceiver = getattr(self.ctx, "perceiver", None)
            wall = getattr(getattr(getattr(perceiver, "config", None), "holding", None),
                           "handled_wall_m" if mug else "rim_wall_m", None)
        wall = float(wall) if wall is not None else (DEFAULT_HANDLED_WALL_M if mug else DEFAULT_RIM_WALL_M)
        T_tcp = np.asarray(target.tcp_pose(), dtype=float)
        q = np.asarray(target.arm_qpos(), dtype=float)
        others = []
        for e in snapshot.get("entities", []):
            if e["name"] == self.object or e.get("kind") not in ("object", "unknown"):
                continue
            size = np.asarray(e.get("size") or (0.0, 0.0, 0.0), dtype=float)
            p = np.asarray(e["position"], dtype=float)
            others.append((p[:2], float(max(size[0], size[1])), float(p[2] + size[2])))
        model = target.model
        base = target.data.xpos[model.jnt_bodyid[model.joint(target.arm_joint_names[0]).id]][:2].copy()
        try:
            previous = np.asarray(self.get(self.pregrasp_key), dtype=float)
        except PrimitiveFailure:
            previous = None
        if previous is not None and previous.shape != (4, 4):
            previous = None
        want = 0 if previous is not None else self.candidate

        def candidates(height: float):
            plans = rim_grasp_candidates(T_obj, half, wall_m=wall, approach_height_m=height,
                                         current_yaw_rad=hand_yaw(T_tcp),
                                         current_q7_rad=float(q[6]) if q.shape == (7,) else None,
                                         prefer_xy=base, max_width_m=max_width, keep_clear=others)
            if short_axis_of is not None:
                return near_short_axis(plans, T_obj, short_axis_of)
            return near_long_axis(plans, T_obj) if long_axis else plans

        # from the skill's approach height; where only pre-grasps were out of reach, lower ones;
        # re-computed, from the height of the pre-grasp the arm went to
        if previous is not None:
            rim_z = float(candidates(self.approach_height_m)[0].grasp[2, 3])
            heights = [max(min(LOWER_APPROACH_M), float(previous[2, 3]) - rim_z)]
        else:
            heights = [self.approach_height_m, *(h for h in LOWER_APPROACH_M if h < self.approach_height_m)]
        usable, why = [], []
        # the hand fully open; where only fingers in the way refused every rim point (a bowl in
        # a drawer whose walls stand within the open hand's reach), pre-shaped to the wall
        preshape = min(0.5 * max_width, 0.5 * wall + RIM_PRESHAPE_CLEARANCE_M)
        for opening in (None, preshape):
            collided = False
            for height in heights:
                plans = candidates(height)
                if previous is not None:
                    plans = tuple(sorted(plans, key=lambda pl: float(np.linalg.norm(pl.pregrasp[:3, 3]
                                                                                    - previous[:3, 3]))))
                out_of_reach = False
                for i, plan in enumerate(plans):
                    bad = _unusable(self.ctx, self.object, plan, opening_m=opening, close_to_m=0.5 * wall)
                    if bad is not None:
                        # one rim point whose grasp alone is reachable is enough to try lower pre-grasps
                        out_of_reach = out_of_reach or (bad.stage == "pre-grasp" and not bad.collides
                                                        and self._reaches(plan.grasp))
                        collided = collided or (bad.stage in ("grasp", "close") and bad.collides)
                        hand = f" hand {opening * 100:.1f} cm open" if opening is not None else ""
                        why.append(f"rim point {i} (yaw {plan.yaw_rad:.2f} rad) from {height:.2f} m{hand}: {bad[:160]}")
                        continue
                    usable.append((i, plan))
                    if len(usable) > want:
                        break
                if usable or not out_of_reach:
                    break
            if usable or not collided:
                break
        if not usable:
            raise IKError(f"no rim grasp of {self.object!r} is reachable: " + "; ".join(why))
        i, plan = usable[want % len(usable)]
        low = {"approach_height_m": round(height, 3)} if abs(height - self.approach_height_m) > 1e-6 else {}
        shaped = {"preshape_m": round(opening, 4)} if opening is not None else {}
        return plan, {"grasp_kind": "rim", "rim_point": i, "wall_m": round(wall, 4), "rim_points_refused": len(why),
                      **low, **shaped}


def place_yaws(current_rad: float) -> list[float]:
    """Hand yaws (rad, about the world z axis) a top-down place tries, in order: 0, the
    hand's yaw now ``current_rad`` (no wrist turn in the transfer), then 0 +- 45, 90, 135
    and 180 degrees; duplicates (within 1 degree) dropped."""
    out: list[float] = []
    for a in (0.0, float(current_rad), *(s * k * np.pi / 4.0 for k in (1, 2, 3) for s in (1.0, -1.0)), np.pi):
        a = float(a) if -np.pi < a <= np.pi else float((a + np.pi) % (2.0 * np.pi) - np.pi)
        if all(abs((a - b + np.pi) % (2.0 * np.pi) - np.pi) > np.radians(1.0) for b in out):
            out.append(a)
    return out


#: Room left on each side of an object set into a drawer, m (:meth:`ComputePlace._check_into`),
#: beyond its perceived footprint, which already errs outward (LIBERO's black bowl: 11.3 cm
#: perceived against its model's 10.7): the hand's placing error in the tracking servo, a few
#: millimetres. With 5 mm, the bowl did not fit LIBERO's bottom drawer at its open stop by the
#: perceived sizes (12.2 cm of room to the handle of the drawer above) where the model leaves it
#: 8 mm a side.
INTO_MARGIN_M = 0.003


#: How far (m) a place onto a fixture's top slides the held object from the top's centre when
#: every yaw there is blocked by a collision (:meth:`ComputePlace._slid_spots`), nearest first:
#: libero_goal_swap task 1 puts the stove under the wine rack's overhang, whose side stands 6 cm
#: over the stove's back half; a bowl 11.3 cm across at the stove's centre meets it by 4.2 cm.
SLIDE_STEPS_M = (0.02, 0.035, 0.05)
#: A slid place keeps the held object's centre this far (m) inside the top's perceived footprint:
#: the perceived footprint's error (a few mm) and the top's edge, where the object would tip.
SLIDE_EDGE_MARGIN_M = 0.02
#: Onto a fixture's flat top, a held object that was seen, when the hand closed, hanging more
#: than this (m) lower in the hand than perception carries it is set down by the height seen
#: then (:class:`ComputePlace`). LIBERO's wine bottle taken across its neck hangs 4.6 cm below
#: the tcp, carried centred (0): lowered onto the wooden cabinet's top by the centred height, it
#: was pressed 4.3 cm into the top, the arm's tracking error 0.043 rad of the 0.05 allowed
#: (libero_goal task 2) or past it (libero_goal_swap task 2, the cabinet further back). Grasps by
#: a rim or a knob are carried at the height they were seen at (within 2 mm on LIBERO-10 and
#: libero_goal): never corrected.
HANG_MIN_M = 0.02
#: Directions a place slides in, in the top's own frame (8, every 45 degrees).
_SLIDE_DIRECTIONS = tuple((float(np.cos(a)), float(np.sin(a))) for a in np.arange(8) * np.pi / 4.0)


#: Yaws a place into a compartment tries beyond :func:`place_yaws`, rad apart
#: (:meth:`ComputePlace._fitting_yaws`): 5 degrees.
FIT_YAW_STEP_RAD = float(np.radians(5.0))
#: The held object's bottom clears a compartment's walls by this much at the pre-place, m.
COMPARTMENT_CLEAR_M = 0.02
#: A place into a compartment whose hand would meet the walls is raised this much at a time
#: (:meth:`ComputePlace._let_down`), m.
LET_DOWN_STEP_M = 0.01
#: Into an open container (perception's ``open_depth_m``: a basket) the held object is lowered
#: between the walls until its base stands this far over the perceived floor, m, or as low as
#: the hand clears them (:meth:`ComputePlace._sink`): the perceived floor is the 5th percentile
#: of the inside's heights (a few mm of noise), and a can let go 2 cm up stays where it lands,
#: where one let go at the rim (12 cm over LIBERO's basket floor) slid 3-5 cm on landing
#: (LIBERO-10 task 0 inits 2 and 7; docs/libero.md, "Let go low in the basket").
SINK_CLEAR_M = 0.02
#: ... where the hand's fingers, opened fully there, stay this far (m) from everything but the
#: object let go (:meth:`ComputePlace._release_blocked`): the perceived pose's few millimetres.
RELEASE_MARGIN_M = 0.005


def _lean(attrs: dict) -> tuple[np.ndarray, np.ndarray, float] | None:
    """A perceived fixture's ramp (``attributes.lean``, perception's measured look: LIBERO's
    wine rack) as ``(crest (3,) world m, toward (2,) world unit, angle rad)``; None without one
    or when malformed."""
    lean = attrs.get("lean")
    if not isinstance(lean, dict):
        return None
    try:
        pos = np.asarray(lean["position"], dtype=float).reshape(3)
        toward = np.asarray(lean["toward_xy"], dtype=float).reshape(2)
        angle = float(lean["angle_rad"])
    except (KeyError, TypeError, ValueError):
        return None
    n = float(np.linalg.norm(toward))
    if not (np.all(np.isfinite(pos)) and n > 1e-6 and 0.0 < angle < 0.5 * math.pi):
        return None
    return pos, toward / n, angle


def leant_place(T_place: np.ndarray, half: Sequence[float], T_tcp_obj: np.ndarray, *,
                toward_xy: Sequence[float], angle_rad: float) -> np.ndarray:
    """The top-down place pose ``T_place`` ((4, 4) world tcp pose holding the object, ``half``
    (3,) m its half extents and ``T_tcp_obj`` (4, 4) its pose in the tcp frame) turned by
    ``angle_rad`` about the centre of the object's base (its centre less its vertical half
    extent) so that its top leans towards ``toward_xy`` (2,) world unit, and raised by its
    horizontal half extent times the sine of the angle: the edge of its base on that side,
    which the turn lowers, stays as high as the base was. Let go there, a bottle on LIBERO's
    wine rack falls back onto the ramp and lies on it (:func:`_lean`; docs/libero.md,
    thirtieth pass). Returns a new (4, 4) world tcp pose."""
    u = np.array([float(toward_xy[0]), float(toward_xy[1]), 0.0])
    axis = np.cross([0.0, 0.0, 1.0], u)
    R = rotation_about(axis, float(angle_rad))
    T_obj = np.asarray(T_place, float) @ np.asarray(T_tcp_obj, float)
    h = np.asarray(half, float)
    r = float(np.max(np.abs(T_obj[:2, :3]) @ h))
    b = T_obj[:3, 3] - [0.0, 0.0, float(np.abs(T_obj[2, :3]) @ h)]
    out = np.array(T_place, dtype=float, copy=True)
    out[:3, :3] = R @ out[:3, :3]
    out[:3, 3] = R @ (out[:3, 3] - b) + b + [0.0, 0.0, r * math.sin(float(angle_rad))]
    return out


#: An object set things on (a plate, a basket) must be named at least this confidently
#: (:meth:`ComputePlace._check_support`): an association no better than a coin flip is no
#: support (the perceiver's own floor for a relation, ``relations.min_confidence``, and the
#: verifier's). LIBERO-10 task 4 init 3: with the left plate hidden by the held mug, a weak
#: sighting 39 cm away was named it at 0.16-0.18, and the mug was let go on the bare table
#: there, in every run; of 2488 recorded places, one other (LIBERO-PRO's swap, task 8 init 0,
#: at 0.18) was onto so weak a support, and its verdict was a replan too.
SUPPORT_MIN_CONFIDENCE = 0.5
#: Room left between two objects set in neighbouring slots of one region, m
#: (:meth:`ComputePlace._slot_point`): about the 2-sigma of a perceived size.
SLOT_GAP_M = 0.01
#: A slot's centre stays this far inside its region's edge, m: the 2-sigma band the verifier's
#: ``on`` puts about a pot set on LIBERO's stove (2.0-2.3 cm in generated LIBERO-10 task 8
#: scenes) and a little.
SLOT_EDGE_M = 0.025
#: Extents of a held object along a region's two axes within this fraction of the larger are
#: one round fit's (:meth:`ComputePlace._slot_point`): the row of slots then runs across its
#: handle where perception found one.
SLOT_ROUND_FRACTION = 0.1


def landmark_box(snapshot: dict, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``((4, 4) world pose, (3,) half extents in m)`` of the thing ``name`` as a landmark: a
    fixture's whole body (``attributes.body``: its position, yaw and size) where perception
    reports one, since its entity's box is its place patch (the stove's burner, the cabinet's
    top); else its entity's box (:func:`entity_pose`).

    Raises:
        PrimitiveFailure: ``perception.not_found`` listing the entities seen.
    """
    T, half = entity_pose(snapshot, name)
    ent = next(e for e in snapshot.get("entities", []) if e["name"] == name)
    body = (ent.get("attributes") or {}).get("body")
    if isinstance(body, dict) and len(body.get("position") or ()) == 3 and len(body.get("size") or ()) == 3:
        T = pose_matrix(body["position"], yaw_quat(float(body.get("yaw") or 0.0)))
        half = np.asarray(body["size"], dtype=float)
    return T, half


def viewer_side(snapshot: dict, side: str, *, who: str, of: str) -> np.ndarray:
    """(2,) unit vector on the table (world frame) towards the viewer's ``side`` of a thing, from
    the snapshot's ``viewer.right_xy`` (:func:`~phyagentos.geometry.viewer_side_xy`).

    Raises:
        PrimitiveFailure: ``perception.no_viewer`` when the snapshot says nothing of the viewer's
            left and right (``who``: the leaf asking; ``of``: the thing whose side it is).
    """
    right = (snapshot.get("viewer") or {}).get("right_xy")
    if not right or len(right) != 2 or not np.hypot(float(right[0]), float(right[1])) > 0:
        raise PrimitiveFailure("perception.no_viewer", f"{who}: the observation says nothing of the viewer's "
                                                       f"left and right, so the {side} of {of} is unknown")
    return viewer_side_xy(right, side)


def beside_point(snapshot: dict, landmark: str, side: str, reach_m: float, *, who: str = "beside"
                 ) -> tuple[np.ndarray, float]:
    """``((3,) world point, surface z m)`` where an object goes down (or is pushed to) beside
    ``landmark`` on the viewer's ``side`` of it: from the landmark's centre along that side
    (:func:`~phyagentos.geometry.viewer_side_xy` of the snapshot's ``viewer.right_xy``) by the
    landmark's half extent that way (a fixture's whole body: :func:`landmark_box`), ``reach_m``
    (the object's own extent that way as it goes down, m) and :data:`BESIDE_GAP_M`; on the surface the
    landmark stands on (its bottom; a region's own height).

    Raises:
        PrimitiveFailure: ``perception.no_viewer`` when the snapshot says nothing of the
            viewer's left and right; ``perception.not_found`` (:func:`entity_pose`) when the
            landmark is not seen.
    """
    T_region, region_half = landmark_box(snapshot, landmark)
    d = np.array([*viewer_side(snapshot, side, who=who, of=landmark), 0.0])
    extent = float(np.abs(T_region[:3, :3].T @ d) @ np.asarray(region_half, dtype=float))
    reach = extent + float(reach_m) + BESIDE_GAP_M
    ent = next((e for e in snapshot.get("entities", []) if e["name"] == landmark), {})
    bottom = (float(T_region[2, 3] - np.abs(T_region[2, :3]) @ region_half)
              if ent.get("kind", "region") in ("object", "fixture") else float(T_region[2, 3]))
    return T_region[:3, 3] + reach * d, bottom


class ComputePlace(Primitive):
    """Place and pre-place tcp poses that set the held object down inside ``region``.

    Args:
        object: the held object.
        region: target region entity, or another object to stack on (its top face
            is then the support surface).
        approach_height_m: pre-place height above the place pose, m.
        beside: ``left`` / ``right`` / ``front`` / ``back``: set the object down beside ``region``
            (a landmark: an object or a fixture) on that side as the viewer sees it, not on it
            (:func:`beside_point`, the object's near face :data:`BESIDE_GAP_M` off the
            landmark's; the yaws that turn its narrow side towards the landmark tried first);
            None: on / in it.
        slot: ``[k, n]``: the region takes ``n`` objects side by side, this one in slot ``k``
            (:meth:`_slot_point`: "put both moka pots on the stove"); None: at its centre.
        snapshot: blackboard key of the observation (object pose in hand, region).
        place, preplace: blackboard keys written with (4, 4) world tcp poses.
        sunk: blackboard key written with how far (m, 0 but into an open container) the place
            was lowered below the container's top (the retreat rises that much more).

    The object's pose in the tcp frame comes from the observation and the arm's
    proprioception, so a place session needs nothing from the pick session but
    the world itself. The hand's yaw at the place is the first of :func:`place_yaws` (0
    first, as always before; then the hand's yaw now, then steps of 45 degrees) whose
    pre-place and place poses the arm reaches without collision (IK and the planner's
    collision checker, the held object attached): a bowl held by its rim, the hand 5.6 cm
    off its centre, is set down beside a cabinet with the hand on the side away from it.
    When none is clear, yaw 0 (the planner then reports the collision). Where every yaw was
    refused only at its pre-place -- out of the arm's reach (a wine bottle held near its neck
    over the top of a cabinet 0.69 m from the base) or, held 10 cm up, within the planner's
    margin of something beside the place (a bowl over a plate beside the open top drawer it was
    taken from: libero_spatial_swap task 4) -- the pre-place is tried lower
    (:data:`LOWER_APPROACH_M`; the held object is lowered the rest of the way in a straight line).

    Onto a fixture with a ramp (perception's ``attributes.lean``: LIBERO's wine rack, whose
    bottle lies back on its upper ramp against the lip at its foot) the object's base goes over
    the lip's crest and the hand is turned about the base by the ramp's slope, the top leaning
    up the ramp (:func:`leant_place`), the hand's fingers across the lean first (what falls
    back onto the ramp then slips out between them); the object's height in the hand is the
    one seen when the hand closed (``grasp_z_tcp_m``), where perception reports it.

    Into a compartment (a perceived ``class: compartment`` fixture entity, its box the floor
    between its walls: "in the back compartment of the caddy") only the yaws at which the held
    object's footprint fits between the walls are tried (:meth:`_fitting_yaws`;
    ``perception.too_small`` when none does), the pre-place stands high enough for the object
    to clear the walls (``walls_m`` + :data:`COMPARTMENT_CLEAR_M` + its half height, since it
    may hang that much lower in the hand than perceived), and where the hand would meet the
    walls at the floor the object is let go higher (:meth:`_let_down`).

    Onto a fixture's flat top (not a compartment, not a ramp) a held object seen, when the hand
    closed, hanging more than :data:`HANG_MIN_M` lower in the hand than perception carries it is
    set down by the height seen then (``grasp_z_tcp_m``; traced ``hangs_lower_m``): its base, not
    its centred stand-in, comes down on the top. Into a container or compartment it is let go
    among walls, as before.

    Onto a fixture's top (a stove, a cabinet's top) where every yaw at the top's centre is
    blocked by a collision (something beside the fixture hangs over it: libero_goal_swap's wine
    rack over the stove), the held object is slid across the top, nearest spot first
    (:data:`SLIDE_STEPS_M` in 8 directions, its centre kept :data:`SLIDE_EDGE_MARGIN_M` inside
    the top's perceived footprint), at the first spot and yaw the arm reaches clear (traced
    ``slid_m``, the world xy offset). Never onto an object (LIBERO counts a thing on another
    only within 3 cm of its centre), beside a landmark, in a slot, a compartment or on a ramp.

    Into an open container (perception's ``open_depth_m``: a basket; not beside it) the object
    is lowered between the walls towards the perceived floor, as far as the hand clears them and
    its fingers open clear of them (:meth:`_sink`, :meth:`_release_blocked`; traced ``sunk_m``),
    and let go there rather than at the rim: a can let go at the rim of LIBERO's basket fell 12 cm
    and slid on landing. Into LIBERO's black bowl the fingers would open against its inside, so
    a thing is let go at its rim, as before.

    Onto an object (stacking: a plate, a basket) only one perception names at
    :data:`SUPPORT_MIN_CONFIDENCE` or more: a weak sighting is no support (``perception.not_found``,
    before anything moves: the recovery looks again).
    """

    def __init__(self, name: str, *, object: str, region: str, approach_height_m: float = 0.10,
                 beside: str | None = None, slot: Sequence[int] | None = None, snapshot: str = "snapshot",
                 place: str = "place_pose",
                 preplace: str = "preplace_pose", sunk: str = "place_sunk_m"):
        super().__init__(name)
        if beside is not None and beside not in VIEWER_SIDES:
            raise ValueError(f"beside must be one of {', '.join(VIEWER_SIDES)} or null, got {beside!r}")
        if slot is not None and not (isinstance(slot, (list, tuple)) and len(slot) == 2
                                     and all(isinstance(v, int) and not isinstance(v, bool) for v in slot)
                                     and 0 <= slot[0] < slot[1]):
            raise ValueError(f"slot must be [k, n] with integers 0 <= k < n, or null; got {slot!r}")
        if slot is not None and beside is not None:
            raise ValueError("slot and beside exclude each other: a slot is on the region, beside is next to it")
        self.beside, self.slot = beside, (None if slot is None else (int(slot[0]), int(slot[1])))
        self.object, self.region, self.approach_height_m = object, region, float(approach_height_m)
        self.snapshot_key, self.place_key, self.preplace_key, self.sunk_key = snapshot, place, preplace, sunk
        self.reads(snapshot)
        self.writes(place, preplace, sunk)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        T_region, region_half = entity_pose(snapshot, self.region)
        ent = next((e for e in snapshot.get("entities", []) if e["name"] == self.region), {})
        self._check_support(ent, snapshot)
        # on or in it: the point origin_pose names goes to the centre (a mug's: midway between its
        # model origin and its cup's axis); beside it: its footprint's centre, clear of the
        # landmark by its half extents
        T_obj, half = (entity_pose if self.beside is not None else origin_pose)(snapshot, self.object)
        T_tcp_obj = np.linalg.inv(self.ctx.target.tcp_pose()) @ T_obj
        # A region is a patch on its support surface (its z: 0 on the tabletop, a burner's
        # height in the kitchen); an object used as the support (stacking), or a perceived
        # fixture (its box is its place patch: the stove's burner, the cabinet's top), offers
        # its top face: centre z plus its vertical half extent.
        held = next((e for e in snapshot.get("entities", []) if e["name"] == self.object), {})
        kind = ent.get("kind", "region")
        attrs = ent.get("attributes") or {}
        compartment = kind == "fixture" and attrs.get("class") == "compartment"
        yaws = place_yaws(hand_yaw(self.ctx.target.tcp_pose()))
        approach = self.approach_height_m
        if kind == "articulation":  # into a drawer: onto its floor out of the body, which must take the object
            self._check_into(ent, T_region, region_half, T_obj, half, held=held)
        if compartment:  # among walls: turned to fit between them, let down from above their top
            yaws = self._fitting_yaws(yaws, T_region, region_half, T_tcp_obj, half)
            # the held object's bottom over the walls' top, though it may hang up to its half height
            # lower in the hand than its perceived pose says (a book taken near its top)
            approach = max(approach, float(attrs.get("walls_m") or 0.0) + COMPARTMENT_CLEAR_M + float(half[2]))
        surface_z = (float(T_region[2, 3] + np.abs(T_region[2, :3]) @ region_half)
                     if kind in ("object", "fixture", "articulation") else float(T_region[2, 3]))
        centre = T_region[:3, 3]
        beside_reach = None
        if self.beside is not None:  # on the surface the landmark stands on, clear of it on the viewer's side
            beside_reach = self._beside_reach(viewer_side(snapshot, self.beside, who=self.name, of=self.region),
                                              T_tcp_obj, half)
            # the held object's narrow side towards the landmark first (stable: place_yaws' order
            # among yaws whose reach is the same to the millimetre)
            yaws = sorted(yaws, key=lambda y: round(beside_reach(y), 3))
        lean = _lean(attrs) if kind == "fixture" and self.beside is None and self.slot is None else None
        if lean is not None:  # a ramp (a wine rack): over its crest, the hand's fingers across the lean first
            centre, surface_z = lean[0], float(lean[0][2])
            yaws = sorted(yaws, key=lambda y: abs(float(top_down_rotation(y)[:2, 1] @ lean[1])))
            # turned about its base, the object's true height in the hand counts: the one seen
            # when the hand closed (a bottle taken near its neck hangs lower than centred)
            seen_z = (held.get("attributes") or {}).get("grasp_z_tcp_m")
            if isinstance(seen_z, (int, float)) and math.isfinite(seen_z):
                T_tcp_obj = T_tcp_obj.copy()
                T_tcp_obj[2, 3] = float(seen_z)
        hang = None
        if kind == "fixture" and not compartment and lean is None:
            # onto a fixture's flat top the object must come down on its base: where it hangs lower
            # in the hand than perception carries it (centred, for a grasp across: a bottle taken
            # by its neck), the height seen when the hand closed counts (as on a ramp, above)
            seen_z = (held.get("attributes") or {}).get("grasp_z_tcp_m")
            if (isinstance(seen_z, (int, float)) and math.isfinite(seen_z)
                    and float(seen_z) - float(T_tcp_obj[2, 3]) > HANG_MIN_M):
                hang = float(seen_z) - float(T_tcp_obj[2, 3])
                T_tcp_obj = T_tcp_obj.copy()
                T_tcp_obj[2, 3] = float(seen_z)
        # an open container (a basket, a bowl: perception found its inside's floor below its top):
        # slots share its inside, within its walls
        wall = OPEN_WALL_M if kind == "object" and float(attrs.get("open_depth_m") or 0.0) > 0.0 else 0.0
        upright_round = (held.get("attributes") or {}).get("shape") == "cylinder" and abs(float(T_obj[2, 2])) > 0.9
        handle_tcp = None  # the held object's handle, as perception found it, in the tcp frame
        if self.slot is not None:
            handle_xy = _xy_attribute(held, "handle_xy")
            if handle_xy is not None:
                handle_tcp = np.asarray(self.ctx.target.tcp_pose(), dtype=float)[:3, :3].T @ np.array(
                    [float(handle_xy[0]), float(handle_xy[1]), 0.0])
        rejected: list[dict] = []
        chosen = clear = None
        # from the skill's approach height; where only pre-places were refused (out of the arm's
        # reach, or within the planner's margin of something; the place itself clear or not
        # tried), from lower ones
        lower = [h for h in LOWER_APPROACH_M if h < approach and not compartment]
        for height in (approach, *lower):
            preplace_only = True
            for yaw in yaws:
                if beside_reach is not None:  # clear of the landmark by the object's own extent at this yaw
                    spot, surface_z = beside_point(snapshot, self.region, self.beside, beside_reach(yaw), who=self.name)
                else:
                    spot = (centre if self.slot is None
                            else self._slot_point(T_region, region_half, T_tcp_obj, half, yaw, handle_tcp=handle_tcp,
                                                  wall_m=wall, round_=upright_round))
                T_place = place_pose(spot, half, T_tcp_object=T_tcp_obj, surface_z_m=surface_z, yaw_rad=yaw)
                if lean is not None:
                    T_place = leant_place(T_place, half, T_tcp_obj, toward_xy=lean[1], angle_rad=lean[2])
                T_pre = T_place.copy()
                T_pre[2, 3] += height
                # a place raised by the hang, or a pre-place lowered for the arm's reach: near the
                # reach's edge, where a straight lowering can leave it between two ends within it
                why = self._place_blocked(T_pre, T_place, near_edge=hang is not None or height < approach)
                if why is not None and compartment and why.stage == "place" and why.collides:
                    T_place, why = self._let_down(T_pre, T_place, why)
                if why is None:
                    clear = (yaw, T_place, T_pre)
                    break
                preplace_only = preplace_only and why.stage == "preplace"
                rejected.append({"yaw_rad": round(yaw, 3), "approach_m": round(height, 3), "why": why})
                chosen = chosen or (yaw, T_place, T_pre)  # none clear: the first (yaw 0), as before
            if clear is not None or not preplace_only:
                break
        slid = None
        if (clear is None and kind == "fixture" and not compartment and lean is None and self.beside is None
                and self.slot is None and any(r["why"].collides for r in rejected)):
            # blocked at the top's centre by something beside or over it: where else on the top
            for offset, spot in self._slid_spots(T_region, region_half):
                for yaw in yaws:
                    T_place = place_pose(spot, half, T_tcp_object=T_tcp_obj, surface_z_m=surface_z, yaw_rad=yaw)
                    T_pre = T_place.copy()
                    T_pre[2, 3] += approach
                    if self._place_blocked(T_pre, T_place, near_edge=hang is not None) is None:
                        clear, slid = (yaw, T_place, T_pre), offset
                        break
                if clear is not None:
                    break
        yaw, T_place, T_pre = clear or chosen  # type: ignore[misc]
        sunk = 0.0
        if clear is not None and wall > 0.0 and self.beside is None:
            # into an open container: down between its walls, not let go at the rim
            T_place, sunk = self._sink(T_pre, T_place, depth_m=float(attrs["open_depth_m"]),
                                       hang_m=self._hang_in_hand(held, T_tcp_obj))
        self.set(self.place_key, T_place)
        self.set(self.preplace_key, T_pre)
        self.set(self.sunk_key, sunk)
        self.ctx.trace.record("place_pose", object=self.object, region=self.region, place=T_place[:3, 3].round(4).tolist(),
                              yaw_rad=round(float(yaw), 3), rejected_yaws=rejected,
                              **({"slid_m": np.round(slid, 4).tolist()} if slid is not None else {}),
                              **({"hangs_lower_m": round(hang, 4)} if hang is not None else {}),
                              **({"sunk_m": round(sunk, 4)} if sunk > 0.0 else {}),
                              **({"beside": self.beside} if self.beside else {}),
                              **({"lean_rad": round(lean[2], 3), "toward_xy": np.round(lean[1], 3).tolist()}
                                 if lean is not None else {}))

    @staticmethod
    def _slid_spots(T_region: np.ndarray, region_half: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """``[(offset (2,) world m, spot (3,) world m)]``: the top's centre (``T_region`` (4, 4)
        world pose, ``region_half`` (3,) m half extents) slid by each of :data:`SLIDE_STEPS_M`
        in each of the 8 directions of the top's own frame, nearest first, keeping the object's
        centre :data:`SLIDE_EDGE_MARGIN_M` inside the footprint (a step that would leave it is
        shortened to the margin; spots repeated to the millimetre are dropped)."""
        room = np.maximum(np.asarray(region_half[:2], dtype=float) - SLIDE_EDGE_MARGIN_M, 0.0)
        R = np.asarray(T_region, dtype=float)[:3, :3]
        out: list[tuple[np.ndarray, np.ndarray]] = []
        seen: set[tuple[int, int]] = set()
        for step in SLIDE_STEPS_M:
            for dx, dy in _SLIDE_DIRECTIONS:
                local = np.array([dx, dy]) * step
                scale = min([1.0] + [float(room[i] / abs(local[i])) for i in (0, 1) if abs(local[i]) > 1e-9])
                local = local * max(scale, 0.0)
                key = (round(float(local[0]) * 1000), round(float(local[1]) * 1000))
                if np.linalg.norm(local) < 0.005 or key in seen:
                    continue
                seen.add(key)
                world = R[:2, :2] @ local
                spot = np.asarray(T_region, dtype=float)[:3, 3].copy()
                spot[:2] += world
                out.append((world, spot))
        return out

    @staticmethod
    def _beside_reach(side_xy: np.ndarray, T_tcp_obj: np.ndarray, half: np.ndarray):
        """``reach(yaw)``: the held object's extent (m) from its footprint's centre towards the
        landmark, ``side_xy`` (2,) world unit (the viewer's side), when it is set down top-down at
        hand yaw ``yaw`` rad (``T_tcp_obj`` (4, 4) its pose in the tcp frame, ``half`` (3,) m its
        half extents): the projection of its box onto that direction. Beside a landmark the
        object's near face then stands :data:`BESIDE_GAP_M` off the landmark's at every yaw:
        LIBERO-10's chocolate pudding, perceived 8.6 by 5.2 cm, goes down 1.7 cm nearer the plate
        turned with its short side towards it than with its long side."""
        d = np.array([float(side_xy[0]), float(side_xy[1]), 0.0])
        Rt = np.asarray(T_tcp_obj, dtype=float)[:3, :3]
        h = np.asarray(half, dtype=float)

        def reach(yaw: float) -> float:
            return float(np.abs((top_down_rotation(yaw) @ Rt).T @ d) @ h)
        return reach

    def _sink(self, T_pre: np.ndarray, T_place: np.ndarray, *, depth_m: float,
              hang_m: float) -> tuple[np.ndarray, float]:
        """The place pose into an open container lowered from ``T_place`` ((4, 4) world tcp
        pose, the held object's base at the container's perceived top, clear of collisions)
        towards its floor, ``depth_m`` (m, perception's ``open_depth_m``) below the top: the
        lowest of the poses from the object's base :data:`SINK_CLEAR_M` over the floor (and
        ``hang_m``, m, more: how much lower it may hang in the hand than carried) upward in
        :data:`LET_DOWN_STEP_M` steps at which the hand and the object clear the walls, the
        line down from ``T_pre`` stays in reach and the fingers open clear of them
        (:meth:`_release_blocked`). Returns ``(pose, how far below T_place
        in m)``; ``(T_place, 0.0)`` when none below it is clear."""
        drop = depth_m - SINK_CLEAR_M - max(hang_m, 0.0)
        steps = int(math.floor(drop / LET_DOWN_STEP_M + 1e-9))
        for k in range(steps, 0, -1):
            T = T_place.copy()
            T[2, 3] -= k * LET_DOWN_STEP_M
            if self._place_blocked(T_pre, T, near_edge=True) is None and self._release_blocked(T) is None:
                return T, k * LET_DOWN_STEP_M
        return T_place, 0.0

    def _release_blocked(self, T_place: np.ndarray) -> Blocked | None:
        """Why the hand cannot open at ``T_place`` ((4, 4) world tcp pose): its fingers, opened
        fully (the gripper's ``open``, :attr:`~phyagentos.motion.collision.CollisionChecker.full_opening_m`),
        come within :data:`RELEASE_MARGIN_M` of anything but the held object; ``None`` when they
        do not (or the target has no collision model, or its gripper no slide joints). The
        fingers' pose follows from the tcp pose alone, so any clear IK solution serves. Let down
        2 cm into LIBERO's black bowl, the cream cheese's fingers opened against the bowl's
        inside and the retreat carried the bowl off the table (libero_goal task 6, fifty-second
        pass)."""
        ctx = self.ctx
        try:
            full = session_checker(ctx, margin_m=RELEASE_MARGIN_M).full_opening_m
        except Exception:  # noqa: BLE001 - a target without a collision model
            return None
        if full is None:
            return None
        try:
            _, pairs, _ = clear_ik(ctx, T_place, allow=_object_body(ctx, self.object), margin_m=RELEASE_MARGIN_M,
                                   opening_m=full)
        except IKError as exc:
            return Blocked(f"release: {str(exc)[:100]}", stage="place", collides=False)
        if pairs:
            return Blocked(f"release collides: {', '.join('-'.join(pr) for pr in pairs[:3])}", stage="place",
                           collides=True)
        return None

    @staticmethod
    def _hang_in_hand(held: dict, T_tcp_obj: np.ndarray) -> float:
        """How much lower (m, >= 0) the held object may hang in the hand than ``T_tcp_obj``
        ((4, 4) its carried pose in the tcp frame) puts it: by the height perception saw it at
        when the hand closed (``attributes.grasp_z_tcp_m``); 0 where that is not known."""
        seen_z = (held.get("attributes") or {}).get("grasp_z_tcp_m")
        if not isinstance(seen_z, (int, float)) or not math.isfinite(seen_z):
            return 0.0
        return max(0.0, float(seen_z) - float(T_tcp_obj[2, 3]))

    def _let_down(self, T_pre: np.ndarray, T_place: np.ndarray, why: Blocked) -> tuple[np.ndarray, Blocked | None]:
        """The place pose into a compartment raised by :data:`LET_DOWN_STEP_M` at a time, from
        ``T_place`` ((4, 4) world tcp pose, where the object would rest on the floor) towards
        the pre-place ``T_pre``, to the lowest at which the hand clears the walls (the object is
        then let go above the floor and the walls guide it down); ``(pose, None)``, or
        ``(T_place, why)`` when none below :data:`COMPARTMENT_CLEAR_M` under the pre-place is."""
        T = T_place.copy()
        while T[2, 3] + LET_DOWN_STEP_M <= T_pre[2, 3] - COMPARTMENT_CLEAR_M:
            T[2, 3] += LET_DOWN_STEP_M
            if self._blocked(T_pre, T) is None:
                self.ctx.trace.record("place_let_down", object=self.object, region=self.region,
                                      raised_m=round(float(T[2, 3] - T_place[2, 3]), 3))
                return T, None
        return T_place, why

    def _fitting_yaws(self, yaws: list[float], T_region: np.ndarray, region_half: np.ndarray,
                      T_tcp_obj: np.ndarray, half: np.ndarray) -> list[float]:
        """The hand yaws (rad) at which the held object (``T_tcp_obj`` (4, 4) its pose in the tcp
        frame, ``half`` (3,) m) set down top-down fits within the compartment's footprint
        (``T_region`` (4, 4) world, ``region_half`` (3,) m, its inside between the walls): those
        of ``yaws`` that fit, in their order, then the others every :data:`FIT_YAW_STEP_RAD`
        that fit, the roomiest first (a book into a caddy's slot turns its spine along the
        slot). No margin is asked beyond the perceived sizes: the walls guide the object in, and
        the pre-place and place poses are then checked for collisions with the object attached.

        Raises:
            PrimitiveFailure: ``perception.too_small`` when it fits at no yaw (its least footprint
                and the compartment's in the message).
        """
        room = np.asarray(region_half[:2], dtype=float)

        def spare(yaw: float) -> float:  # the least room left on a side, m (< 0: does not fit)
            Ro = top_down_rotation(yaw) @ np.asarray(T_tcp_obj, dtype=float)[:3, :3]
            need = np.abs(T_region[:3, :3].T @ Ro)[:2] @ np.asarray(half, dtype=float)
            return float(np.min(room - need))

        grid = [float(a) for a in np.arange(-np.pi + FIT_YAW_STEP_RAD, np.pi + 1e-9, FIT_YAW_STEP_RAD)]
        first = [y for y in yaws if spare(y) >= 0.0]
        rest = sorted((y for y in grid if spare(y) >= 0.0 and all(abs(y - f) > 1e-6 for f in first)),
                      key=lambda y: -spare(y))
        if not first and not rest:
            least = min(grid, key=lambda y: -spare(y))
            Ro = top_down_rotation(least) @ np.asarray(T_tcp_obj, dtype=float)[:3, :3]
            need = np.abs(T_region[:3, :3].T @ Ro)[:2] @ np.asarray(half, dtype=float)
            raise PrimitiveFailure("perception.too_small", f"{self.object!r} needs at least "
                                   f"{np.round(2 * need, 3).tolist()} m (x, y); "
                                   f"{self.region!r} offers {np.round(2 * room, 3).tolist()} m")
        return first + rest

    def _check_into(self, ent: dict, T_region: np.ndarray, region_half: np.ndarray, T_obj: np.ndarray,
                    half: np.ndarray, *, held: dict) -> None:
        """Raise unless the articulated ``region`` (a drawer) offers a floor (``attributes.support``:
        open far enough that its floor stands out of the body) whose footprint (``T_region`` (4, 4)
        world pose, ``region_half`` (3,) m) takes the object's (``T_obj`` (4, 4), ``half`` (3,) m,
        ``held`` its entity;
        as it is held now, about z; an upright ``shape: cylinder``, or an open container whose
        footprint is round (:func:`~phyagentos.motion.rim_grasp.open_container`: a bowl perceived
        as a box with sides within 20 % of each other), its larger horizontal half extent every
        way, a bowl's rim being round whatever yaw its box was given: LIBERO-10 task 3 init 5's
        bowl, perceived as a box 11.3 by 11.0 cm turned 4 degrees, asked 12.3 cm of the bottom
        drawer's 12.2 as a box, 11.9 as the round thing it is) with
        :data:`INTO_MARGIN_M` to spare each side.

        Raises:
            PrimitiveFailure: ``perception.not_open`` (no floor out of the body), ``perception.too_small``.
        """
        attrs = ent.get("attributes") or {}
        if not attrs.get("support"):
            raise PrimitiveFailure("perception.not_open", f"{self.region!r} offers no floor to set {self.object!r} on "
                                   f"(open {attrs.get('joint_position', '?')} m: a drawer must stand out of its body)")
        shape = (held.get("attributes") or {}).get("shape")
        round_ = shape == "cylinder" or open_container(declared_class(self.ctx.target, self.object, held), shape, half)
        if round_ and abs(float(T_obj[2, 2])) > 0.9:
            # upright and round (a cylinder, or a bowl whose box is as wide both ways): its radius every way
            need = np.full(2, float(max(half[0], half[1]))) + INTO_MARGIN_M
        else:
            need = np.abs(T_region[:3, :3].T @ T_obj[:3, :3])[:2] @ np.asarray(half, dtype=float) + INTO_MARGIN_M
        if np.any(need > np.asarray(region_half[:2], dtype=float)):
            raise PrimitiveFailure("perception.too_small", f"{self.object!r} needs {np.round(2 * need, 3).tolist()} m "
                                   f"(x, y; {INTO_MARGIN_M} m spare each side); {self.region!r} offers "
                                   f"{np.round(2 * np.asarray(region_half[:2]), 3).tolist()} m out of its body")

    def _check_support(self, ent: dict, snapshot: dict) -> None:
        """Refuse to set anything on the region's entity ``ent`` when it is an object (``kind:
        object``) perceived below :data:`SUPPORT_MIN_CONFIDENCE`.

        Raises:
            PrimitiveFailure: ``perception.not_found``, with the confidence and the entities seen.
        """
        conf = (ent.get("attributes") or {}).get("confidence")
        if ent.get("kind") == "object" and conf is not None and float(conf) < SUPPORT_MIN_CONFIDENCE:
            seen = sorted(e["name"] for e in snapshot.get("entities", []))
            raise PrimitiveFailure("perception.not_found",
                                   f"{self.region!r} is seen only at confidence {float(conf):.2f} (< "
                                   f"{SUPPORT_MIN_CONFIDENCE}): no support to set {self.object!r} on; seen: {seen}")

    def _slot_point(self, T_region: np.ndarray, region_half: np.ndarray, T_tcp_obj: np.ndarray, half: np.ndarray,
                    yaw: float, handle_tcp: np.ndarray | None = None, wall_m: float = 0.0,
                    round_: bool = False) -> np.ndarray:
        """(3,) world point where slot ``k`` of ``n`` (:attr:`slot`) of the region puts the held
        object's centre, set down with hand yaw ``yaw`` (rad): the n slots stand in a row along the
        region's horizontal axis (``T_region`` (4, 4) world, ``region_half`` (3,) m) across
        which the object, so turned, is narrower; they share the region's length there, and
        stand at least the object's width plus :data:`SLOT_GAP_M` apart, centred; no centre
        nearer the region's edge than :data:`SLOT_EDGE_M` (the verifier's ``on`` judges the
        centre within the region by 2 sigma). An object perceived about as wide both ways
        (within :data:`SLOT_ROUND_FRACTION`) whose handle perception found (``handle_tcp`` (3,),
        its direction in the tcp frame) is longer along its handle than its round fit says:
        the row then runs across the handle (LIBERO-10 task 8 init 7: a held moka pot fitted
        as a cylinder 10.5 cm across; the row ran along its 12.7 cm handle and the first pot
        went to the stove's edge, its verdict undecided).

        Inside an open container (``wall_m`` > 0, m: its walls' and rim's allowance, the
        perceiver's own :data:`~phyagentos.perception.detect.OPEN_WALL_M`) the slots share its
        inside, the footprint less ``wall_m`` on every side, and keep the object's whole footprint
        within it (:meth:`_container_slot`; ``round_``: the held object is an upright cylinder,
        its radius its extent every way)."""
        k, n = self.slot  # type: ignore[misc]
        Ro = top_down_rotation(yaw) @ np.asarray(T_tcp_obj, dtype=float)[:3, :3]
        axes = [np.asarray(T_region[:3, j], dtype=float) for j in (0, 1)]
        extents = [float(np.abs(Ro.T @ a) @ np.asarray(half, dtype=float)) for a in axes]
        j = int(np.argmin(extents))
        if handle_tcp is not None and abs(extents[0] - extents[1]) <= SLOT_ROUND_FRACTION * max(extents):
            handle = top_down_rotation(yaw) @ np.asarray(handle_tcp, dtype=float)
            j = int(np.argmin([abs(float(handle @ a)) for a in axes]))
        if wall_m > 0.0:
            return self._container_slot(T_region, region_half, axes, extents, Ro, half, j, wall_m, round_=round_)
        room = float(region_half[j])
        spacing = max(2.0 * room / n, 2.0 * extents[j] + SLOT_GAP_M)
        offset = float(np.clip((k - 0.5 * (n - 1)) * spacing, -(room - SLOT_EDGE_M), room - SLOT_EDGE_M))
        return np.asarray(T_region[:3, 3], dtype=float) + offset * axes[j]

    def _container_slot(self, T_region: np.ndarray, region_half: np.ndarray, axes: list[np.ndarray],
                        extents: list[float], Ro: np.ndarray, half: np.ndarray, j: int, wall_m: float, *,
                        round_: bool = False) -> np.ndarray:
        """(3,) world point of slot ``k`` of ``n`` (:attr:`slot`) inside an open container
        (``T_region`` (4, 4) world pose, ``region_half`` (3,) m its perceived outer half extents;
        ``axes``: its two horizontal (3,) world unit axes, ``extents``: the held object's half
        extent along each, m, as :meth:`_slot_point` found them) for the held object turned by
        ``Ro`` (3, 3, world from object) with ``half`` (3,) m half extents (``round_``: an
        upright cylinder, whose extent along a diagonal is its radius, not its box's corner).
        The inside is the footprint less ``wall_m`` (m) each side; the
        object's centre may go ``reach`` = the inside less its own extent along each of the
        container's axes.

        The slots stand as near the centre as keeps the footprints :data:`SLOT_GAP_M` apart
        (every other item assumed the held one's size): an item let go onto the rim falls out,
        the worse thing to meet. In a row along axis ``j`` (across the object's narrow side,
        :meth:`_slot_point`) where that row fits within the reach; else corner to corner along
        the diagonal of the reach, as a person sets two cans in a basket too small for them side
        by side (LIBERO's basket is 11.8 by 13.0 cm between its walls at its floor, from its
        model, wider up to its rim, where things are let go; the soup and the tomato sauce are
        perceived 6.8 cm across in the hand), at most the reach's corners apart (the items then
        touch rather than stand one on the other: the second let go onto the first lay tilted on
        it, seen at confidence 0.45-0.49 or not at all, LIBERO-10 tasks 0 and 7, docs/libero.md).
        One slot of one is the centre (the row's only cell)."""
        k, n = self.slot  # type: ignore[misc]
        centre = np.asarray(T_region[:3, 3], dtype=float)
        h = np.asarray(half, dtype=float)
        room = np.maximum(np.asarray(region_half[:2], dtype=float) - float(wall_m), 0.0)
        reach = np.maximum(room - extents, 0.0)
        step = k - 0.5 * (n - 1)
        least = 2.0 * extents[j] + SLOT_GAP_M
        if (n - 1) * least <= 2.0 * reach[j]:  # a row fits
            return centre + step * least * axes[j]
        length = float(np.hypot(reach[0], reach[1]))
        if length <= 0.0:
            return centre
        u = (reach[0] * axes[0] + reach[1] * axes[1]) / length  # along the diagonal, world
        along = float(max(h[0], h[1])) if round_ else float(np.abs(Ro.T @ u) @ h)
        spacing = min(2.0 * along + SLOT_GAP_M, 2.0 * length / (n - 1))
        return centre + step * spacing * u

    def _place_blocked(self, T_pre: np.ndarray, T_place: np.ndarray, *, near_edge: bool) -> Blocked | None:
        """:meth:`_blocked`, and for a place ``near_edge`` of the arm's reach (raised by the
        object's hang, or its pre-place lowered because the skill's own was out of reach or
        collided) then :meth:`_line_blocked`; ``None`` when neither blocks it."""
        why = self._blocked(T_pre, T_place)
        if why is None and near_edge:
            why = self._line_blocked(T_pre, T_place)
        return why

    def _line_blocked(self, T_pre: np.ndarray, T_place: np.ndarray) -> Blocked | None:
        """Why the straight lowering from ``T_pre`` to ``T_place`` ((4, 4) world tcp poses)
        leaves the arm's reach: IK along the line (:func:`~phyagentos.motion.cartesian.cartesian_path`,
        as the ``Lower`` leaf moves) from the pre-place's clear IK solution; ``None`` when it
        stays in reach. A place raised by the object's hang (``HANG_MIN_M``) is checked so: LIBERO's
        wine bottle set on the cabinet's top 4.6 cm higher put the line's middle past the reach
        its two ends were within (libero_goal task 2 init 2: 1.8 mm off at the 4th of 10 waypoints),
        and so is one from a pre-place lowered for reach (``libero_goal_swap`` task 9 init 0: the
        bottle's lowering onto the rack 1.8 mm out at the 5th of 6 waypoints)."""
        target = self.ctx.target
        try:
            sol, _, _ = clear_ik(self.ctx, T_pre)
            cartesian_path(target.model, q_start=sol.q, T_goal=T_place, **ik_options(target))
        except IKError as exc:
            return Blocked(f"lowering: {str(exc)[:100]}", stage="preplace", collides=False)
        return None

    def _blocked(self, T_pre: np.ndarray, T_place: np.ndarray) -> Blocked | None:
        """Why the arm cannot hold the object at ``T_pre`` and ``T_place`` ((4, 4) world tcp
        poses; :func:`reach_blocked`, the held object attached); ``None`` when it can."""
        return reach_blocked(self.ctx, self.object, ("preplace", T_pre), ("place", T_place))
