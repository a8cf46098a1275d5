"""The planning world: what the Runtime plane's motion planner checks collisions against, built
from what the robot perceived.

A target that is :class:`~phyagentos.targets.contract.PlansInPerceivedWorld` (LIBERO, and the
tabletop scenes: the Franka's and the SO-101's) plans in this world instead of the simulator's
state, which holds privileged truth (true object poses, initial placements: ``DESIGN.md``,
"What each plane may know"). The world is its model with:

- the robot's joints at its encoders' readings;
- each object the last observation reported (``kind: object``) as its model placed at the
  perceived box: the model's collision geometry centred on the box's centre, stood on the model
  axis that fits the perceived height and turned so that the model's long side lies along the
  box's (:func:`object_root_pose`); an object held in the
  hand (``attributes.held``) stays where the hand holds it, and where the hand lets it go --
  there until a look reports it again, however many looks miss it (the wrist camera straight
  above a mug just let go on a plate did not see it, and the move out of the cameras' view,
  planned without it, swept the fingers through it: LIBERO-10 task 4);
- each fixture where the perceiver reports its model frame (``attributes.body.root``, from
  the fixture's look measured on generated scenes: :class:`~phyagentos.perception.fixtures.RootLook`);
- each drawer at its perceived opening (``attributes.joint_position``; the last reading when
  the handle was hidden, shut before any), and where the hand has moved it since
  (:func:`note_slide`);
- where the target's object models are stand-ins (``PlanningBodies.perceived_shapes``: a
  randomised tabletop world draws each object's shape and size, so its model's are the
  simulator's), each object's primitive geom takes the perceived shape (box, cylinder, sphere)
  and size, centred on the perceived box, turned by its yaw (a mesh the user declared keeps its
  mesh);
- where the target offers spare boxes (``PlanningBodies.unseen_slots``: the tabletop scenes),
  each segment perception saw but could not name (``kind: unknown``: an undeclared thing on the
  table) as a box of its perceived size and yaw, the largest first; not one that lies within
  :data:`FRAGMENT_GAP_M` of a named object (a piece of it) or around the hand (what it holds);
- anything not perceived left out (parked far below the floor), every other joint at the
  model's default.

The model's geometry is the robot's knowledge of its objects and fixtures (their meshes ship
with the benchmark's assets; a tabletop scene's shapes are the user's declaration, and its
table, walls and bins a known workcell); nothing here reads where the simulator has put them.
A target without the capability keeps planning in the simulator's state (FrankaKitchen;
:func:`phyagentos.primitives.motion.session_checker`).

The world is kept in ``target.runtime_notes`` (plain data the target checkpoints), so it
outlives a session and a runner restart, like the perceiver's tracks.
"""

from __future__ import annotations

import logging
import math
import weakref
from typing import Any, Mapping

import mujoco
import numpy as np

from phyagentos.targets.contract import PlansInPerceivedWorld

log = logging.getLogger(__name__)

__all__ = [
    "WORLD_NOTE",
    "PARK_M",
    "ELONGATED_RATIO",
    "STAND_TIE_M",
    "FRAGMENT_GAP_M",
    "HAND_CLEAR_M",
    "plans_in_perceived_world",
    "note_observation",
    "note_release",
    "note_slide",
    "held",
    "in_hand",
    "apply",
    "object_root_pose",
]

#: ``target.runtime_notes`` key of the perceived planning world.
WORLD_NOTE = "planning_world"
#: What was not perceived is parked this far from the world's origin (m, x and y; and as far
#: below the floor): out of every reach, so the planner never meets it.
PARK_M = 50.0
#: A footprint whose long side exceeds its short one by this ratio has a long side to align
#: (:func:`object_root_pose`); a rounder one keeps the perceived box's yaw.
ELONGATED_RATIO = 1.15

_GEOMETRY: "weakref.WeakKeyDictionary[Any, dict[str, tuple[np.ndarray, np.ndarray]]]" = weakref.WeakKeyDictionary()


def plans_in_perceived_world(target) -> bool:
    """Whether ``target``'s motion planning checks collisions in the perceived world."""
    return isinstance(target, PlansInPerceivedWorld)


def _root_geometry(target, body: str) -> tuple[np.ndarray, np.ndarray]:
    """``(centre (3,), half extents (3,))`` m of the bounding box of the collision geoms of
    every body under root body ``body``, in that root body's frame: the object's model (its
    geometry relative to its own frame does not change as the simulator moves it)."""
    cache = _GEOMETRY.setdefault(target, {})
    if body not in cache:
        m, d = target.model, target.data
        root = m.body(body).id
        Rr, pr = d.xmat[root].reshape(3, 3), d.xpos[root]
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for g in range(m.ngeom):
            if int(m.body_rootid[int(m.geom_bodyid[g])]) != root or not (m.geom_contype[g] or m.geom_conaffinity[g]):
                continue
            Rg = Rr.T @ d.geom_xmat[g].reshape(3, 3)
            c = Rr.T @ (d.geom_xpos[g] - pr) + Rg @ m.geom_aabb[g, :3]
            h = np.abs(Rg) @ m.geom_aabb[g, 3:]
            lo, hi = np.minimum(lo, c - h), np.maximum(hi, c + h)
        if not np.all(np.isfinite(lo)):
            lo, hi = np.zeros(3), np.zeros(3)
        cache[body] = (0.5 * (lo + hi), 0.5 * (hi - lo))
    return cache[body]


def _yaw_of(quat_wxyz) -> float:
    w, x, y, z = (float(v) for v in quat_wxyz)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _rz(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


#: An unnamed segment (``kind: unknown``) whose footprint comes this close (m: the centres'
#: distance less each footprint's larger half side) to a named object's is taken for a piece of
#: that object and kept out of the planner's world: it would otherwise stand in the way of the
#: object's own grasp.
FRAGMENT_GAP_M = 0.005
#: An unnamed segment whose centre lies within its footprint's radius and this much more (m) of
#: the tcp is what the hand holds or touches, not an obstacle.
HAND_CLEAR_M = 0.03

#: Two ways of standing an object's model up whose fits to the perceived box differ by less than
#: this (m, summed over its three sides) are a tie: its own z axis up is kept (most models stand so).
STAND_TIE_M = 0.005


def _standing(half: np.ndarray, size: np.ndarray) -> int:
    """Which axis of the model (0, 1, 2: its frame's x, y, z) stands vertical for a perceived
    box of half extents ``size`` (3,) (its height ``size[2]``): the one whose model half extent
    ``half`` (3,) fits the perceived height, the other two the footprint's sides (smaller with
    smaller), best; its z axis where another fits within :data:`STAND_TIE_M`. LIBERO's bottles
    and cartons are modelled lying (their frames' x axis stands up as the sampler sets them)."""
    foot = np.sort(np.asarray(size[:2], dtype=float))

    def cost(k: int) -> float:
        rest = np.sort(np.delete(half, k))
        return abs(float(half[k]) - float(size[2])) + float(np.abs(rest - foot).sum())

    best = min(range(3), key=cost)
    return 2 if cost(2) <= cost(best) + STAND_TIE_M else best


def object_root_pose(target, body: str, entity: Mapping[str, Any]) -> np.ndarray:
    """(4, 4) world pose of object root body ``body`` placed at a perceived ``entity`` (its
    ``position`` (3,) m, the box's centre; ``quat_wxyz``, a yaw; ``size`` (3,) half extents, m):
    the model's collision box centred on the perceived one, standing on the model axis that fits
    the perceived height (:func:`_standing`), and, where both footprints have a long side
    (:data:`ELONGATED_RATIO`), the model's long horizontal side along the perceived box's (either
    way round: a box's yaw is read modulo pi); else the model's first horizontal axis along the
    perceived yaw."""
    centre, half = _root_geometry(target, body)
    size = np.asarray(entity.get("size") or (0.0, 0.0, 0.0), dtype=float)
    psi = _yaw_of(entity.get("quat_wxyz") or (1.0, 0.0, 0.0, 0.0))
    up = _standing(half, size)
    i, j = (a for a in range(3) if a != up)
    heading = psi
    seen_long = max(size[0], size[1]) > ELONGATED_RATIO * max(min(size[0], size[1]), 1e-6)
    if max(half[i], half[j]) > ELONGATED_RATIO * max(min(half[i], half[j]), 1e-6) and seen_long:
        heading = psi if size[0] >= size[1] else psi + 0.5 * math.pi
        if half[j] > half[i]:
            i, j = j, i  # the model's long horizontal side takes the perceived long side's heading
    R = np.zeros((3, 3))
    R[:, up] = (0.0, 0.0, 1.0)
    R[:, i] = (math.cos(heading), math.sin(heading), 0.0)
    R[:, j] = np.cross(R[:, up], R[:, i])
    if np.linalg.det(R) < 0:
        R[:, j] = -R[:, j]
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(entity["position"], dtype=float) - R @ centre
    return T


def _record(target) -> dict[str, Any]:
    return target.runtime_notes.setdefault(WORLD_NOTE, {"objects": {}, "fixtures": {}, "slides": {}})


def note_observation(target, snapshot: Mapping[str, Any]) -> None:
    """Keep the world ``snapshot`` (a perceived snapshot, the robot's pose now) reports, for
    :func:`apply`: every object and fixture as just perceived (what it does not report is no
    longer in the world, but for an object the hand let go and no look has reported since: it
    stays where the hand let it go), each drawer's opening where it was read (else as last
    read). Does nothing for a target that plans in the simulator's state."""
    if not plans_in_perceived_world(target):
        return
    bodies = target.planning_bodies()
    ents = {e.get("name"): e for e in snapshot.get("entities", []) if isinstance(e, Mapping)}
    T_tcp = np.asarray(target.tcp_pose(), dtype=float)
    objects: dict[str, Any] = {}
    for name, body in bodies.objects.items():
        e = ents.get(name)
        if e is None or e.get("kind") != "object" or e.get("position") is None:
            continue
        attrs = e.get("attributes") or {}
        if bodies.perceived_shapes:  # the box as perceived: its centre, its yaw
            T = np.eye(4)
            T[:3, :3] = _rz(_yaw_of(e.get("quat_wxyz") or (1.0, 0.0, 0.0, 0.0)))
            T[:3, 3] = np.asarray(e["position"], dtype=float)
        else:
            T = object_root_pose(target, body, e)
        held = bool(attrs.get("held"))
        objects[name] = {"T": T.reshape(-1).tolist(),
                         "in_hand": (np.linalg.inv(T_tcp) @ T).reshape(-1).tolist() if held else None}
        if bodies.perceived_shapes:
            objects[name].update(shape=str(attrs.get("shape") or "box"),
                                 size=[float(v) for v in (e.get("size") or (0.01, 0.01, 0.01))])
    fixtures: dict[str, Any] = {}
    for name in bodies.fixtures:
        root = (((ents.get(name) or {}).get("attributes") or {}).get("body") or {}).get("root")
        if root is not None:
            fixtures[name] = {"position": [float(v) for v in root["position"]], "yaw": float(root["yaw"])}
    rec = _record(target)
    for name, o in (rec.get("objects") or {}).items():  # let go, and not reported since
        if name not in objects and o.get("let_go") and name in bodies.objects:
            objects[name] = o
    slides = dict(rec.get("slides") or {})
    for ent, (joint, sign) in bodies.slides.items():
        q = ((ents.get(ent) or {}).get("attributes") or {}).get("joint_position")
        if q is not None:
            slides[joint] = float(sign) * float(q)
    rec.update(objects=objects, fixtures=fixtures, slides=slides,
               unseen=_unseen(ents.values(), T_tcp[:3, 3], len(bodies.unseen_slots)))


def _unseen(entities, tcp: np.ndarray, slots: int) -> list[dict[str, Any]]:
    """The unnamed segments (``kind: unknown``) the planner keeps clear of, as
    ``{position (3,), size (3,) half extents, yaw}`` (m, rad, world), the ``slots`` largest: not
    a piece of a named object (:data:`FRAGMENT_GAP_M`), not around the hand at ``tcp`` (3,)
    (:data:`HAND_CLEAR_M`)."""
    if slots <= 0:
        return []
    named, unknown = [], []
    for e in entities:
        if not isinstance(e, Mapping) or e.get("position") is None or e.get("size") is None:
            continue
        p, size = np.asarray(e["position"], dtype=float), np.asarray(e["size"], dtype=float)
        if e.get("kind") == "object":
            named.append((p[:2], float(max(size[0], size[1]))))
        elif e.get("kind") == "unknown":
            unknown.append((p, size, _yaw_of(e.get("quat_wxyz") or (1.0, 0.0, 0.0, 0.0))))
    out = []
    for p, size, yaw in unknown:
        r = float(max(size[0], size[1]))
        if any(float(np.linalg.norm(p[:2] - c)) - r - rc < FRAGMENT_GAP_M for c, rc in named):
            continue
        if float(np.linalg.norm(p - tcp)) < float(np.hypot(size[0], size[1])) + HAND_CLEAR_M:
            continue
        out.append({"position": p.tolist(), "size": size.tolist(), "yaw": yaw})
    out.sort(key=lambda u: -float(np.prod(u["size"])))
    return out[:slots]


def note_release(target) -> None:
    """The hand has opened: an object the world holds in it stays where the hand let it go, until
    a look reports it (:func:`note_observation`)."""
    if not plans_in_perceived_world(target):
        return
    objects = _record(target).get("objects") or {}
    T_tcp = np.asarray(target.tcp_pose(), dtype=float)
    for o in objects.values():
        if o.get("in_hand") is not None:
            o["T"] = (T_tcp @ np.asarray(o["in_hand"], dtype=float).reshape(4, 4)).reshape(-1).tolist()
            o["in_hand"], o["let_go"] = None, True


def note_slide(target, entity: str, opening_m: float) -> None:
    """Drawer ``entity`` stands ``opening_m`` m out now (the hand moved it: what its joint
    encoders say the held handle travelled), until a look reads it again."""
    if not plans_in_perceived_world(target):
        return
    slide = target.planning_bodies().slides.get(entity)
    if slide is not None:
        joint, sign = slide
        _record(target).setdefault("slides", {})[joint] = float(sign) * float(opening_m)


def held(target) -> str | None:
    """The object the planning world holds in the hand (its last look saw it held, and the
    hand has not opened since), else ``None``."""
    for name, o in (_record(target).get("objects") or {}).items():
        if o.get("in_hand") is not None:
            return name
    return None


def in_hand(target, obj: str) -> np.ndarray | None:
    """(4, 4) pose of object ``obj``'s root body in the tcp frame as the planning world holds
    it: where the last observation saw it held, else (closed on since, not yet seen in the
    hand) where it was seen from where the hand is now; ``None`` when it was not perceived."""
    o = (_record(target).get("objects") or {}).get(obj)
    if o is None:
        return None
    if o.get("in_hand") is not None:
        return np.asarray(o["in_hand"], dtype=float).reshape(4, 4)
    return np.linalg.inv(np.asarray(target.tcp_pose(), dtype=float)) @ np.asarray(o["T"], dtype=float).reshape(4, 4)


def _quat(R: np.ndarray) -> np.ndarray:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R).reshape(-1))
    return q


_PRIMITIVES = {int(mujoco.mjtGeom.mjGEOM_BOX), int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_SPHERE)}


def _shape_geom(m: mujoco.MjModel, body: int, shape: str, size: np.ndarray) -> None:
    """Give body ``body``'s one primitive geom (in the planner's model copy ``m``) the perceived
    ``shape`` (``box``, ``cylinder``, ``sphere``; anything else a box) and ``size`` (3,) half
    extents, m; a body whose geom is a mesh (a declared file) keeps it."""
    g = int(m.body_geomadr[body])
    if int(m.body_geomnum[body]) != 1 or int(m.geom_type[g]) not in _PRIMITIVES:
        return
    h = np.maximum(np.asarray(size, dtype=float), 1e-3)
    r = float(max(h[0], h[1]))
    if shape == "sphere":
        m.geom_type[g], m.geom_size[g] = mujoco.mjtGeom.mjGEOM_SPHERE, (float(h.max()), 0.0, 0.0)
        m.geom_aabb[g] = (0.0, 0.0, 0.0, *([float(h.max())] * 3))
        m.geom_rbound[g] = float(h.max())
    elif shape == "cylinder":
        m.geom_type[g], m.geom_size[g] = mujoco.mjtGeom.mjGEOM_CYLINDER, (r, float(h[2]), 0.0)
        m.geom_aabb[g] = (0.0, 0.0, 0.0, r, r, float(h[2]))
        m.geom_rbound[g] = float(math.hypot(r, h[2]))
    else:
        m.geom_type[g], m.geom_size[g] = mujoco.mjtGeom.mjGEOM_BOX, h
        m.geom_aabb[g] = (0.0, 0.0, 0.0, *h)
        m.geom_rbound[g] = float(np.linalg.norm(h))
    m.geom_pos[g], m.geom_quat[g] = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)


def apply(target, checker) -> dict[str, list[str]]:
    """Set ``checker`` (a :class:`~phyagentos.motion.collision.CollisionChecker` on
    ``target``'s model) to the perceived planning world (module docstring); returns the
    ``placed`` and ``parked`` object and fixture names."""
    bodies = target.planning_bodies()
    rec = _record(target)
    m = checker.model
    q = m.qpos0.copy()
    live = target.data.qpos
    for jn in bodies.robot_joints:
        j = m.joint(jn).id
        adr = int(m.jnt_qposadr[j])
        n = {int(mujoco.mjtJoint.mjJNT_FREE): 7, int(mujoco.mjtJoint.mjJNT_BALL): 4}.get(int(m.jnt_type[j]), 1)
        q[adr:adr + n] = live[adr:adr + n]
    placed, parked = [], []
    objects = rec.get("objects") or {}
    for k, (name, body) in enumerate(bodies.objects.items()):
        b = m.body(body).id
        adr = int(m.jnt_qposadr[int(m.body_jntadr[b])])
        o = objects.get(name)
        if o is None:
            q[adr:adr + 3] = (PARK_M + 2.0 * k, PARK_M, -PARK_M)
            q[adr + 3:adr + 7] = (1.0, 0.0, 0.0, 0.0)
            parked.append(name)
            continue
        T = np.asarray(o["T"], dtype=float).reshape(4, 4)
        q[adr:adr + 3] = T[:3, 3]
        q[adr + 3:adr + 7] = _quat(T[:3, :3])
        if bodies.perceived_shapes and o.get("size") is not None:
            _shape_geom(m, b, str(o.get("shape") or "box"), np.asarray(o["size"], dtype=float))
        placed.append(name)
    for joint, value in (rec.get("slides") or {}).items():
        q[int(m.jnt_qposadr[m.joint(joint).id])] = float(value)
    checker.set_world_state(q)
    unseen = rec.get("unseen") or []
    for k, slot in enumerate(bodies.unseen_slots):
        b = m.body(slot).id
        g, mid = int(m.body_geomadr[b]), int(m.body_mocapid[b])
        # the simulation's collision bits keep the slot out of every contact, down to MuJoCo's
        # per-body filter; the planner's copy lets it meet the robot like the scene's bodies
        m.body_contype[b], m.body_conaffinity[b] = 1, 1
        if k < len(unseen):
            u = unseen[k]
            size = np.maximum(np.asarray(u["size"], dtype=float), 1e-3)
            m.geom_size[g] = size
            m.geom_rbound[g] = float(np.linalg.norm(size))
            m.geom_aabb[g] = (0.0, 0.0, 0.0, *size)
            checker.data.mocap_pos[mid] = u["position"]
            checker.data.mocap_quat[mid] = _quat(_rz(float(u["yaw"])))
            placed.append(slot)
        else:
            checker.data.mocap_pos[mid] = (PARK_M + 2.0 * k, PARK_M, -PARK_M)
    fixtures = rec.get("fixtures") or {}
    for k, (name, body) in enumerate(bodies.fixtures.items()):
        b = m.body(body).id
        f = fixtures.get(name)
        if f is None:
            m.body_pos[b] = (PARK_M + 2.0 * k, -PARK_M, -PARK_M)
            parked.append(name)
            warned = rec.setdefault("unseen_fixtures", [])
            if name not in warned:  # once per fixture and world: the planner does not know it is there
                warned.append(name)
                log.warning("planning world: fixture %r is not perceived (no look declared, or not seen yet), so the "
                            "motion planner does not know it is there; declare its look (docs/libero.md)", name)
            continue
        m.body_pos[b] = f["position"]
        m.body_quat[b] = _quat(_rz(float(f["yaw"])))
        placed.append(name)
    return {"placed": placed, "parked": parked}
