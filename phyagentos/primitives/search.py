"""Looking for an object the skill's observation did not name: a look from nearer at what
perception saw but could not tell.

A pick starts from one observation. Where the object it is to take is not in it, the
reason is often that the cameras saw only a piece of it: the arm at its ready pose hides it
from the fixed camera and the wrist camera looks elsewhere, or it stands at the edge of the
frame. Perception then reports an unnamed segment (``kind: unknown``, no class) where the
object stands, not the object. A person would lean over and look. These leaves do that:

``object_seen``
    succeeds when the snapshot names the object; fails quietly otherwise (it records no
    failure, so the skill's failure stays the one of the step that follows when no look
    finds it).
``compute_search_look``
    the tcp pose that puts the hand camera over the most likely unnamed segment, looking
    down on it from ``look_height_m``; raises ``perception.not_found`` when no segment is
    left to look at (or ``max_looks`` looks were taken).

The shipped tree ``look_for`` (``data/trees/look_for.yaml``) runs them under a selector:
object seen, or up to ``looks`` looks from nearer (move there, observe, seen?), or go on;
``pick`` uses it after its first observation (``search_looks``), ``place`` for its region.
When no look names the object, the grasp or place computation that follows reports it not
found, as it did without the looks. Only what perception reports is read; never the
simulator's truth.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from py_trees.common import Status

from phyagentos.errors import IKError
from phyagentos.geometry import pose_matrix
from phyagentos.motion.grasp import hand_yaw, top_down_rotation

from .base import Primitive, PrimitiveFailure
from .motion import clear_ik

__all__ = ["ObjectSeen", "ComputeSearchLook", "declared_names", "unnamed_segments", "hand_camera_offset", "look_pose",
           "LOOK_BOX_MARGIN_M", "LOOK_HEIGHT_M", "LOOK_REVISIT_M"]

logger = logging.getLogger(__name__)

#: Default height of the hand camera above the top of the segment it looks at, m. At 0.30 m a
#: camera with a 75 degree vertical field of view (robosuite's Panda hand camera) sees about
#: +-0.23 m around the point it aims at, enough to take in an object whose visible piece lies
#: up to 10 cm from its centre (LIBERO-PRO's with_milk scenes: a mug behind the arm seen as a
#: 2-3 cm sliver 5-9 cm from where it stands).
LOOK_HEIGHT_M = 0.30
#: A segment within this distance (horizontal, m) of a point already looked at is not looked
#: at again.
LOOK_REVISIT_M = 0.05
#: A look's tcp stays this far inside the SafetyGuard's workspace box, m (``safety.yaml``
#: ``workspace_box``): a look the guard would stop is not aimed at.
LOOK_BOX_MARGIN_M = 0.01
#: Hand yaws tried for a look, offsets from the current one, rad: the current first (the
#: shortest turn of the wrist), then a quarter turn either way, then half.
_LOOK_YAWS_RAD = (0.0, math.pi / 2.0, -math.pi / 2.0, math.pi)
#: Lower look heights tried when the arm cannot reach the first, fractions of it.
_LOOK_HEIGHT_FRACTIONS = (1.0, 0.7)
#: Entity kinds that are never a candidate nor a neighbour (the robot's own parts).
_ROBOT_KINDS = frozenset({"robot", "gripper"})


def _named(snapshot: dict, name: str) -> dict | None:
    return next((e for e in snapshot.get("entities", []) if e.get("name") == name), None)


def declared_names(target) -> frozenset[str]:
    """Names of the objects and fixtures the target's scene declares (``describe_declared``);
    empty when it declares none or cannot say."""
    describe = getattr(target, "describe_declared", None)
    if describe is None:
        return frozenset()
    try:
        doc = describe()
    except Exception:  # noqa: BLE001 - a target that cannot describe its scene declares nothing
        return frozenset()
    return frozenset(str(o["name"]) for key in ("objects", "fixtures") for o in doc.get(key) or () if o.get("name"))


def unnamed_segments(snapshot: dict, *, declared: frozenset[str] | set[str] = frozenset()) -> list[dict]:
    """The snapshot's unnamed segments, most likely a hidden object's first: entities of kind
    ``unknown`` that are not a declared object or fixture (``declared``: their names; one
    perceived below the confidence to be named keeps its name, kind ``unknown``, and is not
    a segment) and carry no class, ordered by their horizontal clearance from the nearest named
    entity (its centre distance less that entity's larger horizontal half extent), largest
    first: a segment apart from everything named is more likely an object perception could
    not tell than a piece of one it did (a mug's handle beside its body). Robot parts are
    neither candidates nor neighbours."""
    ents = [e for e in snapshot.get("entities", []) if e.get("kind") not in _ROBOT_KINDS]
    segs = [e for e in ents if e.get("kind") == "unknown" and e.get("name") not in declared
            and not (e.get("attributes") or {}).get("class")]
    named = [e for e in ents if e not in segs]

    def clearance(seg: dict) -> float:
        p = np.asarray(seg["position"][:2], dtype=float)
        gaps = [float(np.linalg.norm(p - np.asarray(n["position"][:2], dtype=float)))
                - float(max((n.get("size") or (0.0, 0.0))[:2])) for n in named]
        return min(gaps, default=math.inf)

    return sorted(segs, key=clearance, reverse=True)


def hand_camera_offset(target) -> np.ndarray | None:
    """(4, 4) pose of the hand camera's MuJoCo camera frame (looking along its -z axis) in
    the tcp frame: the first camera sensor mounted on a body other than the world
    (``sensors.yaml`` ``mount.body``), read from the target's model at its current state (both
    frames are fixed to the hand). None when the target has no such camera or no MuJoCo
    model."""
    try:
        specs = dict(target.sensors)
        model, data, site = target.model, target.data, target.tcp_site
    except Exception:  # noqa: BLE001 - a target without sensors or a model: no offset known
        return None
    for spec in specs.values():
        if spec.kind not in ("rgbd_camera", "rgb_camera") or spec.mount.body in ("", "world"):
            continue
        try:
            cam, tcp = model.camera(spec.camera_name).id, model.site(site).id
        except KeyError:
            continue
        return np.linalg.inv(pose_matrix(data.site_xpos[tcp], data.site_xmat[tcp])) @ pose_matrix(
            data.cam_xpos[cam], data.cam_xmat[cam])
    return None


def look_pose(point: np.ndarray, *, yaw_rad: float, height_m: float, T_tcp_cam: np.ndarray | None) -> np.ndarray:
    """(4, 4) top-down tcp pose in the world frame, hand yaw ``yaw_rad`` rad, whose hand camera
    looks at ``point`` ((3,) world m) from ``height_m`` m above it.

    With the camera's pose in the tcp frame ``T_tcp_cam`` (:func:`hand_camera_offset`) the
    camera's optical axis passes through the point and the camera is ``height_m`` above it;
    without it (or when that camera does not look down: its axis less than 30 degrees below
    the horizontal), the tcp itself is ``height_m`` straight above the point."""
    p = np.asarray(point, dtype=float)
    T = np.eye(4)
    T[:3, :3] = top_down_rotation(yaw_rad)
    T[:3, 3] = p + np.array([0.0, 0.0, height_m])
    if T_tcp_cam is None:
        return T
    R_cam = T[:3, :3] @ T_tcp_cam[:3, :3]
    axis = -R_cam[:, 2]  # a MuJoCo camera looks along its -z
    if axis[2] > -0.5:
        return T
    cam = p - (height_m / -axis[2]) * axis
    T[:3, 3] = cam - T[:3, :3] @ T_tcp_cam[:3, 3]
    return T


def _safety_box(ctx) -> tuple[np.ndarray, np.ndarray] | None:
    """The session's SafetyGuard workspace box of the tcp (``(3,)`` min, ``(3,)`` max, world m)
    shrunk by :data:`LOOK_BOX_MARGIN_M`, or None without a guard."""
    guard = getattr(ctx, "guard", None)
    limits = getattr(guard, "limits", None)
    if limits is None:
        return None
    return (np.asarray(limits.box_min, dtype=float) + LOOK_BOX_MARGIN_M,
            np.asarray(limits.box_max, dtype=float) - LOOK_BOX_MARGIN_M)


class ObjectSeen(Primitive):
    """Succeed when the snapshot names ``object``; otherwise fail without recording a
    failure (a selector's condition: what fails the skill is what follows).

    Args:
        object: entity name.
        snapshot: blackboard key of the observation.
    """

    TOOLS = ()

    def __init__(self, name: str, *, object: str, snapshot: str = "snapshot"):
        super().__init__(name)
        self.object, self.snapshot_key = object, snapshot
        self.reads(snapshot)

    def step(self):
        return Status.SUCCESS if _named(self.get(self.snapshot_key), self.object) is not None else Status.FAILURE


class ComputeSearchLook(Primitive):
    """The tcp pose from which the hand camera looks down on an unnamed segment where
    ``object`` may be hidden (:func:`unnamed_segments` of the target's :func:`declared_names`,
    best first; those within
    :data:`LOOK_REVISIT_M` of a point this leaf already aimed at are passed over), reachable
    by the arm clear of the scene (IK from the current joints; hand yaws from the current
    one, a quarter turn either way, then half; the look height, then 0.7 of it) with the tcp
    inside the SafetyGuard's workspace box (:data:`LOOK_BOX_MARGIN_M` within it).

    Args:
        object: entity name (named in the trace and the failure only).
        max_looks: looks this leaf aims at most in one session (0: none).
        look_height_m: the hand camera's height above the segment's top, m (in (0.05, 1]).
        snapshot: blackboard key of the observation.
        out: blackboard key written with the (4, 4) world tcp pose.

    Raises (as failures): ``perception.not_found`` when ``max_looks`` looks were aimed, or no
    unnamed segment is left that the arm can look at; the message lists the entities seen.

    The trace records ``search_look`` {leaf, object, segment, aim (3,) world m, yaw_rad,
    height_m, look}.
    """

    TOOLS = ()

    def __init__(self, name: str, *, object: str, max_looks: int = 2, look_height_m: float = LOOK_HEIGHT_M,
                 snapshot: str = "snapshot", out: str = "look_pose"):
        super().__init__(name)
        if not isinstance(max_looks, int) or isinstance(max_looks, bool) or max_looks < 0:
            raise ValueError(f"max_looks must be an integer >= 0, got {max_looks!r}")
        if not isinstance(look_height_m, (int, float)) or not 0.05 < float(look_height_m) <= 1.0:
            raise ValueError(f"look_height_m must be a number in (0.05, 1] m, got {look_height_m!r}")
        self.object, self.max_looks, self.look_height_m = object, max_looks, float(look_height_m)
        self.snapshot_key, self.out = snapshot, out
        self._aimed: list[np.ndarray] = []
        self._exhausted = False
        self.reads(snapshot)
        self.writes(out)

    def step(self):
        snapshot = self.get(self.snapshot_key)
        seen = sorted(e["name"] for e in snapshot.get("entities", []))
        if self._exhausted or len(self._aimed) >= self.max_looks:
            raise PrimitiveFailure("perception.not_found", f"{self.object!r} is not in the observation after "
                                   f"{len(self._aimed)} look(s) from nearer (none named it); seen: {seen}")
        target = self.ctx.target
        T_tcp_cam = hand_camera_offset(target)
        try:
            yaw0 = hand_yaw(np.asarray(target.tcp_pose(), dtype=float))
        except Exception:  # noqa: BLE001 - a target that reports no tcp pose: yaw 0 first
            yaw0 = 0.0
        for seg in unnamed_segments(snapshot, declared=declared_names(target)):
            p = np.asarray(seg["position"], dtype=float)
            if any(float(np.linalg.norm(p[:2] - a[:2])) < LOOK_REVISIT_M for a in self._aimed):
                continue
            top = p.copy()
            top[2] += float((seg.get("size") or (0.0, 0.0, 0.0))[2])
            pose = self._reachable(top, yaw0, T_tcp_cam)
            if pose is None:
                continue
            self._aimed.append(p)
            T, yaw, height = pose
            self.set(self.out, T)
            self.ctx.trace.record("search_look", leaf=self.name, object=self.object, segment=seg["name"],
                                  aim=p.round(4).tolist(), yaw_rad=round(yaw, 4), height_m=round(height, 3),
                                  look=len(self._aimed))
            logger.info("%s: %r not seen; looking at %s from %.2f m", self.name, self.object, seg["name"], height)
            return None
        self._exhausted = True  # nothing left: later attempts fail at once
        raise PrimitiveFailure("perception.not_found", f"{self.object!r} is not in the observation and no unnamed "
                               f"segment is left to look at from nearer; seen: {seen}")

    def _reachable(self, point: np.ndarray, yaw0: float, T_tcp_cam: np.ndarray | None):
        """``(pose, yaw, height)`` of the first look at ``point`` the arm reaches clear of the
        scene, or None."""
        box = _safety_box(self.ctx)
        for frac in _LOOK_HEIGHT_FRACTIONS:
            height = self.look_height_m * frac
            for dyaw in _LOOK_YAWS_RAD:
                yaw = yaw0 + dyaw
                T = look_pose(point, yaw_rad=yaw, height_m=height, T_tcp_cam=T_tcp_cam)
                if box is not None and not (np.all(T[:3, 3] >= box[0]) and np.all(T[:3, 3] <= box[1])):
                    continue  # the SafetyGuard would stop the motion there
                try:
                    _, pairs, _ = clear_ik(self.ctx, T)
                except IKError:
                    continue
                if not pairs:
                    return T, yaw, height
        return None
