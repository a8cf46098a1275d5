"""Runtime-side checks of a whole goal graph before anything moves.

The Runtime plane knows what a scene may hold and what an arm can reach; the Agent
plane knows goal graphs. The composition root (:mod:`phyagentos.app.graph_check`) asks
this module, with plain data, three questions:

- :func:`check_scene`: is the scene well-formed for the target's driver (types,
  sizes, positions as numbers of the right length), with the 1-based line of each
  problem in the user's file?
- :func:`scene_names`: which objects and regions may parameters and predicates name?
- :func:`check_reachability`: can the target's arm reach every pick pose (top-down
  grasp and pre-grasp of each object, any of its grasp candidates) and every place
  pose (the held object over a region's centre, and its pre-place pose) the graph
  implies? IK runs on the target's own model (mink, the same solver and options the
  ``solve_ik`` primitive uses), seeded from the target's home configuration; nothing
  is stepped, nothing is written.

Every problem is a :class:`GraphProblem` ``(line, message)``; none of these raise for
bad user input.
"""

from __future__ import annotations

import inspect
import logging
import math
import typing
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from phyagentos.errors import IKError, PhyAgentOSError, TargetError, format_choices
from phyagentos.motion.grasp import DEFAULT_MAX_GRASP_WIDTH_M, place_pose, top_down_grasp_candidates
from phyagentos.motion.ik import solve_ik
from phyagentos.primitives.motion import ik_options
from phyagentos.targets.contract import Target
from phyagentos.targets.perturbations import parse_perturbations, split_scene
from phyagentos.targets.registry import DRIVERS
from phyagentos.targets.scene import SceneSpec
from phyagentos.yamlsource import clip, excerpt, line_of

__all__ = ["GraphProblem", "PickPose", "PlacePose", "check_scene", "scene_names", "check_reachability",
           "build_trees", "check_scenes", "check_reach"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class GraphProblem:
    """One problem found before motion: 1-based ``line`` in the user's file (or ``None``)."""

    line: int | None
    message: str


@dataclass(frozen=True)
class PickPose:
    """Node ``node`` picks ``obj`` (``approach_height_m`` above the grasp); ``line`` for messages."""

    node: str
    obj: str
    line: int | None
    approach_height_m: float = 0.10


@dataclass(frozen=True)
class PlacePose:
    """Node ``node`` sets ``obj`` down in ``region``; ``line`` for messages."""

    node: str
    obj: str
    region: str
    line: int | None
    approach_height_m: float = 0.10


_NUMBER = (int, float)
_PLACE_YAWS = (0.0, math.pi / 2, -math.pi / 2, math.pi)


def _is_number(v: Any) -> bool:
    return isinstance(v, _NUMBER) and not isinstance(v, bool) and math.isfinite(v)


def _item_problems(kind: str, index: int, item: Any, cls: type, root: Any = None) -> list[GraphProblem]:
    """Type problems of one scene item, from its dataclass field defaults; a mesh object's
    file is checked here too (:func:`phyagentos.targets.mesh.load_mesh`), at the line of
    its ``mesh`` key."""
    from phyagentos.targets.scene import item_keys, mesh_for  # noqa: PLC0415

    line = line_of(item)
    if not isinstance(item, Mapping):
        return [GraphProblem(line, f"scene {kind}[{index}] must be a mapping with keys "
                                   f"{format_choices(item_keys(kind))}, got {excerpt(item)}")]
    fields = {k: cls.__dataclass_fields__[k] for k in item_keys(kind) if k in cls.__dataclass_fields__}
    if kind == "objects":
        fields["class"] = cls.__dataclass_fields__["cls"]
    out = []
    for key, value in item.items():
        where = line_of(item, key)
        label = f"scene {kind}[{index}]" + (f" ({item['name']!r})" if isinstance(item.get("name"), str) else "")
        if key not in fields:
            out.append(GraphProblem(where, f"{label}: unknown key {excerpt(key)}; valid keys: {format_choices(fields)}"))
            continue
        default = fields[key].default
        if isinstance(default, tuple) and default and all(isinstance(d, _NUMBER) for d in default):
            n = len(default)
            if not isinstance(value, list) or len(value) != n or not all(_is_number(v) for v in value):
                shown = "a string" if isinstance(value, str) else excerpt(value)
                out.append(GraphProblem(where, f"{label}: {key} must be a list of {n} numbers "
                                               f"(e.g. {list(default)}), got {shown}: {excerpt(value)}"))
        elif isinstance(default, _NUMBER) and not isinstance(default, bool) and not _is_number(value):
            out.append(GraphProblem(where, f"{label}: {key} must be a number (e.g. {default}), got {excerpt(value)}"))
    if not out:
        args = dict(item)
        if kind == "objects" and "class" in args:
            args["cls"] = args.pop("class")
        if kind == "objects" and args.get("shape") == "mesh":
            where = f"scene {kind}[{index}] ({item.get('name')!r})"
            try:
                args["mesh_data"] = mesh_for(args, root=root, where=where)
            except PhyAgentOSError as exc:
                key = "half_extents" if "half_extents" in item else ("mesh" if "mesh" in item else None)
                return [GraphProblem(line_of(item, key) if key else line, clip(str(exc), 400))]
        try:
            cls(**args)
        except (PhyAgentOSError, TypeError, ValueError) as exc:
            out.append(GraphProblem(line, f"scene {kind}[{index}]: {clip(str(exc))}"))
    return out


def _tabletop(cls: type[Target]) -> bool:
    """Whether a driver's scene is the tabletop :class:`SceneSpec`: it keeps
    :meth:`Target.scene_from_dict`, or its own is annotated to return one."""
    if inspect.getattr_static(cls, "scene_from_dict") is inspect.getattr_static(Target, "scene_from_dict"):
        return True
    try:
        return typing.get_type_hints(cls.scene_from_dict).get("return") is SceneSpec
    except Exception:  # noqa: BLE001 - unresolvable annotations: not a tabletop scene
        return False


def check_scene(raw: Mapping[str, Any] | None, driver: str, *,
                root: Any = None) -> tuple[Any, list[GraphProblem]]:
    """Validate a goal graph's ``scene`` for a target driver.

    Args:
        raw: the scene as loaded by :func:`phyagentos.yamlsource.load_yaml` (mappings
            carry lines), or ``None`` for the driver's default scene.
        driver: TARGETS.md ``driver`` of the node's target.
        root: the workspace root that mesh files (``shape: mesh``) are relative to.

    Returns:
        ``(scene, problems)``: the parsed scene (``None`` when it has problems).
    """
    cls = DRIVERS.get(driver)
    if cls is None:
        return None, [GraphProblem(None, f"unknown target driver {driver!r}; valid drivers: {format_choices(DRIVERS)}")]
    scene_line = line_of(raw)
    try:
        base, perturb = split_scene(raw or None)
    except PhyAgentOSError as exc:
        return None, [GraphProblem(scene_line, clip(str(exc)))]
    problems: list[GraphProblem] = []
    if _tabletop(cls) and isinstance(raw, Mapping):
        from phyagentos.targets.scene import _ITEM_TYPES  # noqa: PLC0415 - the scene's own item types

        for kind, item_cls in _ITEM_TYPES.items():
            items = raw.get(kind)
            if items is None:
                continue
            if not isinstance(items, list):
                problems.append(GraphProblem(line_of(raw, kind), f"scene {kind} must be a list, got {excerpt(items)}"))
                continue
            for i, item in enumerate(items):
                problems += _item_problems(kind, i, item, item_cls, root)
    if problems:
        return None, problems
    try:
        scene = cls.scene_from_dict(base, root=root)  # the tabletop SceneSpec unless the driver has its own
    except (PhyAgentOSError, TypeError, ValueError) as exc:
        return None, [GraphProblem(scene_line, f"scene: {clip(str(exc))}")]
    try:
        parse_perturbations(perturb, objects=getattr(scene, "object_names", ()))
    except PhyAgentOSError as exc:
        line = line_of(raw, "perturbations") if isinstance(raw, Mapping) else scene_line
        return None, [GraphProblem(line, f"scene perturbations: {clip(str(exc))}")]
    return scene, []


def scene_names(scene: Any) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
    """``(objects, regions)`` a graph may name on this scene; ``None`` when the scene type
    (e.g. FrankaKitchen's task list) does not enumerate them."""
    if isinstance(scene, SceneSpec):
        return scene.object_names, scene.region_names
    return None


def _T(xyz: Sequence[float], yaw: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = xyz
    return T


def _start_collisions(target: Any, target_name: str, *, line: int | None) -> list[GraphProblem]:
    """The arm's start (home) configuration must not reach into an obstacle: its contacts
    would push the arm from the first command on (a ``hold`` drifts, plans start invalid)."""
    m, d = target.model, target.data
    mujoco.mj_forward(m, d)
    hits = set()
    for i in range(d.ncon):
        c = d.contact[i]
        names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or "" for g in (c.geom1, c.geom2)]
        bodies = [int(m.geom_bodyid[g]) for g in (c.geom1, c.geom2)]
        for k in (0, 1):
            other = 1 - k
            if names[k].startswith("obstacle:") and bodies[other] != 0 and m.body_jntnum[bodies[other]] > 0 \
                    and m.jnt_type[m.body_jntadr[bodies[other]]] != mujoco.mjtJoint.mjJNT_FREE:
                hits.add(names[k].split(":", 1)[1])
    if not hits:
        return []
    return [GraphProblem(line, f"{target_name!r} starts in collision: its home pose reaches into obstacle(s) "
                               f"{format_choices(hits)}; move the obstacle or use another target")]


def _wider_grippers(driver: str, width_m: float) -> list[str]:
    """``"driver (N cm)"`` for every other target driver whose gripper takes ``width_m``
    (its ``max_grasp_width_m``, less grasp planning's 4 mm clearance); only asked when an
    object is too wide, so loading the drivers costs nothing otherwise."""
    out = []
    for name in DRIVERS:
        if name == driver:
            continue
        try:
            cls = DRIVERS[name]
        except (ImportError, KeyError, TargetError):  # an optional driver whose package is missing
            continue
        w = cls.max_grasp_width_m
        if w is not None and w - 0.004 >= width_m:
            out.append(f"{name} ({w * 100:.1f} cm)")
    return sorted(out)


def check_reachability(driver: str, target_name: str, scene: Any, *, picks: Sequence[PickPose] = (),
                       places: Sequence[PlacePose] = ()) -> list[GraphProblem]:
    """IK on every pick and place pose of a node list; problems for the unreachable ones.

    Builds the driver's target on ``scene`` (a model only: it is not stepped and no
    state file is written), then for each pick tries every top-down grasp candidate of
    the object at its scene pose (grasp and pre-grasp must both solve) and for each
    place the held object's tcp pose over the region centre and its pre-place pose.
    Also checks that the arm's home pose touches no obstacle. Scenes that are not a
    :class:`SceneSpec` (FrankaKitchen) are not checked here.
    """
    if not isinstance(scene, SceneSpec):
        return []
    cls = DRIVERS[driver]
    target = cls(target_name, scene, seed=0)
    problems: list[GraphProblem] = []
    try:
        problems += _start_collisions(target, target_name, line=(picks[0].line if picks else None))
        opts = ik_options(target)
        q_home = np.asarray(target.arm_qpos(), dtype=float)

        data = mujoco.MjData(target.model)
        adr = [target.model.joint(n).qposadr[0] for n in opts["arm_joint_names"]]
        site = target.model.site(opts["frame"]).id
        reached: dict[int, np.ndarray] = {}

        def reachable(T: np.ndarray) -> str | None:
            """``None`` when IK solves ``T``; the tcp pose it reaches is kept in ``reached``."""
            try:
                sol = solve_ik(target.model, q_seed=q_home, target=T, **opts)
            except IKError as exc:
                return str(exc)
            data.qpos[adr] = sol.q
            mujoco.mj_kinematics(target.model, data)
            pose = np.eye(4)
            pose[:3, :3] = data.site_xmat[site].reshape(3, 3)
            pose[:3, 3] = data.site_xpos[site]
            reached[id(T)] = pose
            return None

        grasp_of: dict[str, np.ndarray] = {}
        for pick in picks:
            obj = scene.object(pick.obj)
            T_obj = _T((obj.position[0], obj.position[1], obj.rest_z), obj.yaw)
            try:
                cands = top_down_grasp_candidates(T_obj, obj.half_extents, approach_height_m=pick.approach_height_m,
                                                  max_width_m=target.max_grasp_width_m or DEFAULT_MAX_GRASP_WIDTH_M)
            except IKError as exc:
                wider = _wider_grippers(driver, 2.0 * min(obj.half_extents[:2]))
                problems.append(GraphProblem(pick.line, f"node {pick.node!r}: no top-down grasp of {pick.obj!r} on "
                                             f"{target_name!r}: {exc}" + (f"; drivers whose gripper takes it: "
                                                                          f"{', '.join(wider)}" if wider else "")))
                continue
            why = None
            for plan in cands:
                why = reachable(plan.grasp) or reachable(plan.pregrasp)
                if why is None:
                    # the hand as the arm really reaches it (a 5-joint arm tilts it)
                    grasp_of[pick.obj] = np.linalg.inv(reached[id(plan.grasp)]) @ T_obj
                    break
            if why is not None:
                dist = math.hypot(*obj.position)
                problems.append(GraphProblem(pick.line, (
                    f"node {pick.node!r}: {target_name!r} cannot reach {pick.obj!r} at "
                    f"({obj.position[0]:.3f}, {obj.position[1]:.3f}) m, {dist:.2f} m from its base "
                    f"(IK of every top-down grasp failed: {excerpt(why)}); move the object or use another target")))
        for place in places:
            obj = scene.object(place.obj)
            if place.region in scene.object_names:  # stacking: on top of another object
                support = scene.object(place.region)
                center, surface_z = support.position, 2.0 * support.rest_z
            else:
                center, surface_z = scene.region(place.region).center, 0.0
            T_tcp_obj = grasp_of.get(place.obj)
            if T_tcp_obj is None:  # not picked in this graph: assume its best top-down grasp
                T_obj = _T((obj.position[0], obj.position[1], obj.rest_z), obj.yaw)
                try:
                    plan = top_down_grasp_candidates(T_obj, obj.half_extents)[0]
                except IKError as exc:
                    problems.append(GraphProblem(place.line, f"node {place.node!r}: cannot hold {place.obj!r}: {exc}"))
                    continue
                T_tcp_obj = np.linalg.inv(plan.grasp) @ T_obj
            why = None
            for yaw in _PLACE_YAWS:  # any hand yaw will do for the check
                T_place = place_pose(center, obj.half_extents, T_tcp_object=T_tcp_obj, yaw_rad=yaw,
                                     surface_z_m=surface_z)
                T_pre = T_place.copy()
                T_pre[2, 3] += place.approach_height_m
                why = reachable(T_place) or reachable(T_pre)
                if why is None:
                    break
            if why is not None:
                problems.append(GraphProblem(place.line, (
                    f"node {place.node!r}: {target_name!r} cannot reach {place.region!r} at "
                    f"({center[0]:.3f}, {center[1]:.3f}) m to set {place.obj!r} down "
                    f"(IK failed: {excerpt(why)}); move the region or use another target")))
    finally:
        target.close()
    return problems


# -- the Runtime plane's part of the whole-graph check, in batches of plain data ---------
# ``phyagentos.app.graph_check`` runs the check; these are the steps that need the runtime
# (primitives, scenes, the motion stack). Plain tuples in and out, so that the same
# functions serve the check in one process and the check whose runtime half runs in the
# runner (``phyagentos.runtime.worker``, job ``graph_checks``).


def build_trees(trees: Any, items: Sequence[tuple[str, Mapping[str, Any]]]) -> list[str | None]:
    """Build each ``(tree name, params)`` of ``items`` with the tree library ``trees``
    (without a target); per item ``None`` or the error's message (clipped to 400 characters)."""
    out: list[str | None] = []
    for tree, params in items:
        try:
            trees.build(tree, params)
            out.append(None)
        except PhyAgentOSError as exc:
            out.append(clip(str(exc), 400))
    return out


def check_scenes(items: Sequence[tuple[Any, str]], *, root: Any = None
                 ) -> list[tuple[Any, list[tuple[int | None, str]], tuple[tuple[str, ...], tuple[str, ...]] | None]]:
    """:func:`check_scene` of each ``(raw scene, driver)``; per item ``(scene, problems as
    (line, message), scene_names(scene))``."""
    out = []
    for raw, driver in items:
        scene, problems = check_scene(raw, driver, root=root)
        out.append((scene, [(p.line, p.message) for p in problems], scene_names(scene)))
    return out


def check_reach(items: Sequence[tuple[str, str, Any, Sequence[tuple], Sequence[tuple]]]
                ) -> list[list[tuple[int | None, str]]]:
    """:func:`check_reachability` of each ``(driver, target name, scene, picks, places)``,
    picks and places as the fields of :class:`PickPose` and :class:`PlacePose`; per item
    its problems as ``(line, message)``."""
    return [[(p.line, p.message) for p in check_reachability(
                driver, name, scene, picks=[PickPose(*p) for p in picks], places=[PlacePose(*p) for p in places])]
            for driver, name, scene, picks, places in items]
