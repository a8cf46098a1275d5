"""Tabletop scene description and the MuJoCo model built from it.

A scene is a Franka Panda (the model shipped inside the ``gymnasium-robotics`` wheel)
standing at the world origin on a table whose top is the plane z = 0, plus:

- objects: free-floating boxes resting on the table (:class:`ObjectSpec`);
- regions: thin, non-colliding coloured patches on the table top (:class:`RegionSpec`);
- obstacles: static collision boxes (:class:`ObstacleSpec`).

:func:`build_scene` composes a small wrapper MJCF that includes the Franka asset files by
absolute path, loads it into a :class:`mujoco.MjSpec` and adds everything else
programmatically. Names in the compiled model:

- arm joints ``robot:panda0_joint1`` .. ``robot:panda0_joint7`` (:data:`ARM_JOINT_NAMES`),
  finger joints :data:`FINGER_JOINT_NAMES`, actuators ``panda0_joint1`` .. ``7`` and the
  two finger actuators :data:`FINGER_ACTUATOR_NAMES` (always driven with the same value);
- site ``tcp`` midway between the fingertip pads, z axis pointing out of the gripper,
  y axis along the finger motion (:data:`TCP_SITE`);
- object ``name``: body ``name``, geom ``name``, free joint ``name:free``;
- region ``name``: geom ``region:name``; obstacle ``name``: geom ``obstacle:name``;
- geoms ``table`` and ``floor``; camera ``overview``; keyframe ``home``.

Physics choices (so a 4 cm, 0.1 kg cube is grasped and carried without slip):
elliptic friction cones with ``impratio`` 10, 3 noslip iterations, the implicitfast
integrator; finger pads with friction 1.5, condim 4 (torsional friction), stiff contacts
(solref 0.004, solimp 0.95/0.99) and no margin; objects condim 4 with the same contact
stiffness; the two finger joints coupled by an equality constraint; gravity compensation
on every robot body (the real Panda controller compensates gravity); contacts between
adjacent links excluded.

Units: metres, radians, kilograms, seconds. World frame: z up, origin at the robot base.
"""

from __future__ import annotations

import importlib.util
import logging
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.geometry import look_at_quat, yaw_quat

from .mesh import MeshData, load_mesh

__all__ = [
    "ObjectSpec",
    "RegionSpec",
    "ObstacleSpec",
    "SceneSpec",
    "DEFAULT_SCENE",
    "build_scene",
    "build_scene_spec",
    "franka_asset_dir",
    "ARM_JOINT_NAMES",
    "FINGER_JOINT_NAMES",
    "ARM_ACTUATOR_NAMES",
    "FINGER_ACTUATOR_NAMES",
    "ROBOT_BODY_NAMES",
    "FINGER_BODY_NAMES",
    "TCP_SITE",
    "FT_SITE",
    "WRIST_CAMERA",
    "OBJECT_SHAPES",
    "SCENE_OBJECT_SHAPES",
    "add_tabletop_world",
    "HOME_QPOS",
    "GRIPPER_MAX_OPENING_M",
    "TABLE_GEOM",
    "FLOOR_GEOM",
    "UNSEEN_SLOTS",
    "UNSEEN_SLOT_BIT",
    "unseen_slot_name",
    "region_geom_name",
    "obstacle_geom_name",
    "object_joint_name",
]

log = logging.getLogger(__name__)

ARM_JOINT_NAMES: tuple[str, ...] = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))
FINGER_JOINT_NAMES: tuple[str, ...] = ("robot:panda0_finger_joint1", "robot:panda0_finger_joint2")
ARM_ACTUATOR_NAMES: tuple[str, ...] = tuple(f"panda0_joint{i}" for i in range(1, 8))
FINGER_ACTUATOR_NAMES: tuple[str, ...] = ("r_gripper_finger_joint", "l_gripper_finger_joint")
ROBOT_BODY_NAMES: tuple[str, ...] = tuple(f"panda0_link{i}" for i in range(8)) + (
    "panda0_leftfinger",
    "panda0_rightfinger",
)
FINGER_BODY_NAMES: tuple[str, ...] = ("panda0_leftfinger", "panda0_rightfinger")
TCP_SITE = "tcp"
#: Site of the wrist force/torque sensors (``wrist_force``, ``wrist_torque``): on link7 at
#: the flange, 0.107 m along link7's z (Franka Emika datasheet: flange offset d7 = 0.107 m),
#: i.e. between link7 and the hand; it measures the load of everything distal to it.
FT_SITE = "wrist_ft"
_FLANGE_Z_M = 0.107
#: Wrist RGB-D camera on the hand, looking along the gripper (tcp z).
WRIST_CAMERA = "wrist"
#: Primitive object shapes (also what a randomised world draws from).
OBJECT_SHAPES: tuple[str, ...] = ("box", "cylinder", "sphere")
#: Every shape a scene object may have: the primitives, or ``mesh`` (a file in the
#: workspace, :mod:`phyagentos.targets.mesh`).
SCENE_OBJECT_SHAPES: tuple[str, ...] = OBJECT_SHAPES + ("mesh",)
TABLE_GEOM = "table"
FLOOR_GEOM = "floor"
#: Spare boxes in every tabletop scene for the motion planner's perceived world
#: (:mod:`phyagentos.primitives.planning_world`): each takes one segment perception saw but
#: could not name (``kind: unknown``, an undeclared thing on the table), so the planner keeps
#: clear of it. Mocap bodies parked under the table, in geom group 5 and transparent (no
#: camera renders them), with the collision bit :data:`UNSEEN_SLOT_BIT` that no other geom's
#: affinity has: the simulation never lets them touch anything; the planner's copy of the model
#: turns them on.
UNSEEN_SLOTS = 8
#: The collision type of the spare boxes (:data:`UNSEEN_SLOTS`): a bit no simulated geom's
#: ``conaffinity`` carries.
UNSEEN_SLOT_BIT = 8
GRIPPER_MAX_OPENING_M = 0.04

#: Ready configuration (rad): tcp about 0.46 m in front of the base, 0.37 m above the
#: table, gripper pointing straight down with the fingers closing along world y.
HOME_QPOS: tuple[float, ...] = (0.0, -0.30, 0.0, -2.20, 0.0, 0.33, 0.0)

# Distance (m) along link7's z axis from the link7 origin to the tcp. The finger pads
# (capsule rows of the shipped model) span 0.200 .. 0.253 m; the tcp sits 8 mm above the
# centre line of the last row, so a box grasped at its centre keeps the fingertips
# about 5 mm above the surface it rests on.
_TCP_OFFSET_M = 0.245
_TABLE_THICKNESS_M = 0.05
_TABLE_HEIGHT_M = 0.75
_TABLE_X = (-0.35, 1.05)
_TABLE_Y = (-0.80, 0.80)
_REGION_THICKNESS_M = 0.0005


def region_geom_name(name: str) -> str:
    """Name of the geom that draws region ``name``."""
    return f"region:{name}"


def obstacle_geom_name(name: str) -> str:
    """Name of the geom of obstacle ``name``."""
    return f"obstacle:{name}"


def object_joint_name(name: str) -> str:
    """Name of the free joint of object ``name``."""
    return f"{name}:free"


def franka_asset_dir() -> Path:
    """Directory of the Franka Panda assets shipped inside the gymnasium-robotics wheel.

    Returns the folder holding ``assets.xml``, ``actuator.xml``, ``chain.xml`` and
    ``meshes/``. Raises :class:`TargetError` if gymnasium-robotics is missing or the
    files are not where this version ships them.
    """
    # Locate the package without importing it: its __init__ registers every
    # gymnasium environment and prints a banner, neither of which we need.
    spec = importlib.util.find_spec("gymnasium_robotics")
    if spec is None or not spec.submodule_search_locations:  # pragma: no cover - dependency is declared
        raise TargetError("gymnasium-robotics is not installed (pip install gymnasium-robotics)")
    root = Path(list(spec.submodule_search_locations)[0]).resolve()
    path = root / "envs" / "assets" / "kitchen_franka" / "franka_assets"
    missing = [f for f in ("assets.xml", "actuator.xml", "chain.xml", "meshes") if not (path / f).exists()]
    if missing:
        raise TargetError(f"Franka assets not found in {path}: missing {', '.join(missing)}")
    return path


# ----------------------------------------------------------------------------- specs


def _floats(value: Any, n: int, what: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise TargetError(f"{what} must be a sequence of {n} numbers, got {value!r}") from exc
    if len(out) != n:
        raise TargetError(f"{what} must have {n} numbers, got {len(out)}: {value!r}")
    if not all(math.isfinite(v) for v in out):
        raise TargetError(f"{what} must be finite, got {value!r}")
    return out


def _positive(values: tuple[float, ...], what: str) -> None:
    if any(v <= 0.0 for v in values):
        raise TargetError(f"{what} must be > 0, got {values!r}")


def _check_name(name: Any, what: str) -> str:
    if not isinstance(name, str) or not name or any(c in name for c in " :/\t\n"):
        raise TargetError(f"{what} name must be a non-empty string without spaces, ':' or '/', got {name!r}")
    return name


def _rgba(value: Any, what: str) -> tuple[float, float, float, float]:
    out = _floats(value, 4, f"{what}.rgba")
    if any(not 0.0 <= v <= 1.0 for v in out):
        raise TargetError(f"{what}.rgba components must be in [0, 1], got {out!r}")
    return out  # type: ignore[return-value]


@dataclass(frozen=True)
class ObjectSpec:
    """A free rigid object resting on the table: a box, an upright cylinder, a sphere or a mesh.

    Attributes:
        name: unique scene name (also the MuJoCo body and geom name).
        half_extents: ``(hx, hy, hz)`` half sizes of the object's bounding box in metres,
            object frame: a cylinder has radius ``hx == hy`` and half height ``hz``; a
            sphere radius ``hx == hy == hz``; a mesh the half sizes of its axis-aligned
            bounding box after ``scale`` (computed from the file, never written).
        position: ``(x, y)`` of the box centre in the world frame, metres; z is computed
            so the box rests on the table (``z = hz``).
        yaw: rotation about world z in radians.
        mass: kilograms.
        friction: sliding friction coefficient (torsional 0.005, rolling 0.0001).
        rgba: colour, components in [0, 1].
        shape: ``box`` | ``cylinder`` | ``sphere`` | ``mesh`` (:data:`SCENE_OBJECT_SHAPES`).
        cls: the user's object class (``class:`` in YAML, e.g. ``"mug"``), or None.
        mesh: for ``shape: mesh``, the OBJ/STL file relative to the workspace root.
        scale: for ``shape: mesh``, uniform scale of the file's vertices (> 0).
        mesh_data: the checked file (:func:`phyagentos.targets.mesh.load_mesh`), set by
            :meth:`SceneSpec.from_dict` with the workspace root; required for a mesh.

    Raises :class:`TargetError` on invalid values.
    """

    name: str
    half_extents: tuple[float, float, float] = (0.02, 0.02, 0.02)
    position: tuple[float, float] = (0.5, 0.0)
    yaw: float = 0.0
    mass: float = 0.1
    friction: float = 1.0
    rgba: tuple[float, float, float, float] = (0.85, 0.20, 0.15, 1.0)
    shape: str = "box"
    cls: str | None = None
    mesh: str | None = None
    scale: float = 1.0
    mesh_data: MeshData | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        _check_name(self.name, "object")
        if self.shape == "mesh":
            md = self.mesh_data
            if not isinstance(md, MeshData) or md.path != self.mesh or md.scale != float(self.scale):
                raise TargetError(f"object {self.name!r}: a mesh object is read from the workspace "
                                  f"(load_mesh / SceneSpec.from_dict with root=), got mesh={self.mesh!r}")
            object.__setattr__(self, "half_extents", md.half_extents)
            object.__setattr__(self, "scale", md.scale)
        elif self.mesh is not None or self.mesh_data is not None or self.scale != 1.0:
            raise TargetError(f"object {self.name!r}: mesh and scale need shape: mesh, got shape {self.shape!r}")
        he = _floats(self.half_extents, 3, f"object {self.name!r} half_extents")
        _positive(he, f"object {self.name!r} half_extents")
        object.__setattr__(self, "half_extents", he)
        object.__setattr__(self, "position", _floats(self.position, 2, f"object {self.name!r} position"))
        object.__setattr__(self, "yaw", _floats([self.yaw], 1, f"object {self.name!r} yaw")[0])
        mass = _floats([self.mass], 1, f"object {self.name!r} mass")[0]
        friction = _floats([self.friction], 1, f"object {self.name!r} friction")[0]
        _positive((mass,), f"object {self.name!r} mass")
        _positive((friction,), f"object {self.name!r} friction")
        object.__setattr__(self, "mass", mass)
        object.__setattr__(self, "friction", friction)
        object.__setattr__(self, "rgba", _rgba(self.rgba, f"object {self.name!r}"))
        if self.shape not in SCENE_OBJECT_SHAPES:
            raise TargetError(f"object {self.name!r}: unknown shape {self.shape!r}; valid shapes: "
                              f"{format_choices(SCENE_OBJECT_SHAPES)}")
        if self.shape == "cylinder" and abs(he[0] - he[1]) > 1e-9:
            raise TargetError(f"object {self.name!r}: a cylinder's half_extents need hx == hy (its radius), got {he!r}")
        if self.shape == "sphere" and (abs(he[0] - he[1]) > 1e-9 or abs(he[0] - he[2]) > 1e-9):
            raise TargetError(f"object {self.name!r}: a sphere's half_extents must all equal its radius, got {he!r}")
        if self.cls is not None and (not isinstance(self.cls, str) or not self.cls.strip()):
            raise TargetError(f"object {self.name!r}: class must be a non-empty string, got {self.cls!r}")

    @property
    def rest_z(self) -> float:
        """World z (m) of the box centre when resting on the table."""
        return self.half_extents[2]


@dataclass(frozen=True)
class RegionSpec:
    """A rectangular target region drawn on the table top (no collision).

    Attributes:
        name: unique scene name (geom ``region:<name>``).
        center: ``(x, y)`` world metres.
        half_extents: ``(hx, hy)`` metres, axis aligned with the world frame.
        rgba: colour.
    """

    name: str
    center: tuple[float, float] = (0.5, 0.25)
    half_extents: tuple[float, float] = (0.08, 0.08)
    rgba: tuple[float, float, float, float] = (0.20, 0.75, 0.30, 0.6)

    def __post_init__(self) -> None:
        _check_name(self.name, "region")
        object.__setattr__(self, "center", _floats(self.center, 2, f"region {self.name!r} center"))
        he = _floats(self.half_extents, 2, f"region {self.name!r} half_extents")
        _positive(he, f"region {self.name!r} half_extents")
        object.__setattr__(self, "half_extents", he)
        object.__setattr__(self, "rgba", _rgba(self.rgba, f"region {self.name!r}"))

    def contains_xy(self, xy, margin_m: float = 0.0) -> bool:
        """Whether world point ``xy`` (m) lies in the footprint shrunk by ``margin_m``."""
        return all(
            abs(float(xy[i]) - self.center[i]) <= self.half_extents[i] - margin_m for i in range(2)
        )


@dataclass(frozen=True)
class ObstacleSpec:
    """A static collision box.

    Attributes:
        name: unique scene name (geom ``obstacle:<name>``).
        center: ``(x, y, z)`` world metres.
        half_extents: ``(hx, hy, hz)`` metres, axis aligned.
        rgba: colour.
    """

    name: str
    center: tuple[float, float, float] = (0.5, 0.0, 0.1)
    half_extents: tuple[float, float, float] = (0.1, 0.01, 0.1)
    rgba: tuple[float, float, float, float] = (0.55, 0.55, 0.60, 1.0)

    def __post_init__(self) -> None:
        _check_name(self.name, "obstacle")
        object.__setattr__(self, "center", _floats(self.center, 3, f"obstacle {self.name!r} center"))
        he = _floats(self.half_extents, 3, f"obstacle {self.name!r} half_extents")
        _positive(he, f"obstacle {self.name!r} half_extents")
        object.__setattr__(self, "half_extents", he)
        object.__setattr__(self, "rgba", _rgba(self.rgba, f"obstacle {self.name!r}"))


_ITEM_TYPES = {"objects": ObjectSpec, "regions": RegionSpec, "obstacles": ObstacleSpec}
_SCENE_KEYS = ("objects", "regions", "obstacles", "timestep", "randomise")
_RESERVED_NAMES = frozenset({"table", "floor", "world", "robot", "gripper", "tcp"})


#: Dataclass fields a scene file never writes (derived from other keys).
_DERIVED_KEYS = frozenset({"mesh_data"})


def item_keys(kind: str) -> tuple[str, ...]:
    """The keys a scene file may write for an item of ``kind`` (objects, regions, obstacles)."""
    keys = tuple(k for k in _ITEM_TYPES[kind].__dataclass_fields__ if k not in _DERIVED_KEYS)
    return tuple("class" if k == "cls" else k for k in keys)


def mesh_for(d: Mapping[str, Any], *, root: str | Path | None, where: str) -> MeshData:
    """Load the mesh of object mapping ``d`` (``shape: mesh``) from the workspace ``root``.

    Raises:
        TargetError: no workspace root, ``half_extents`` written for a mesh, no ``mesh``
            key, or any refusal of :func:`phyagentos.targets.mesh.load_mesh`.
    """
    if "half_extents" in d:
        raise TargetError(f"{where}: a mesh object's size is its file's bounding box; remove half_extents "
                          "(use scale to resize it)")
    if "mesh" not in d:
        raise TargetError(f"{where}: shape mesh needs a mesh file (mesh: meshes/part.obj, relative to the workspace)")
    if root is None:
        raise TargetError(f"{where}: a mesh object is read from the workspace, and no workspace was given")
    return load_mesh(d["mesh"], root=root, scale=d.get("scale", 1.0), where=where)


def _item_from_dict(kind: str, d: Any, index: int, root: str | Path | None = None):
    cls = _ITEM_TYPES[kind]
    if isinstance(d, cls):
        return d
    if not isinstance(d, Mapping):
        raise TargetError(f"scene {kind}[{index}] must be a mapping, got {type(d).__name__}")
    valid = tuple(k for k in cls.__dataclass_fields__ if k not in _DERIVED_KEYS)
    if kind == "objects":
        d = dict(d)
        if "class" in d:
            d["cls"] = d.pop("class")
        valid = tuple("class" if k == "cls" else k for k in valid)
    unknown = set(d) - set(valid) - ({"cls"} if kind == "objects" else set())
    if unknown:
        raise TargetError(
            f"scene {kind}[{index}]: unknown key(s) {format_choices(unknown)}; valid keys: {format_choices(valid)}"
        )
    if "name" not in d:
        raise TargetError(f"scene {kind}[{index}]: missing key 'name'; valid keys: {format_choices(valid)}")
    if kind == "objects" and d.get("shape") == "mesh":
        d = {**d, "mesh_data": mesh_for(d, root=root, where=f"object {d['name']!r}")}
    return cls(**dict(d))


@dataclass(frozen=True)
class SceneSpec:
    """Everything on the table; immutable and hashable.

    Attributes:
        objects: tuple of :class:`ObjectSpec`.
        regions: tuple of :class:`RegionSpec`.
        obstacles: tuple of :class:`ObstacleSpec`.
        timestep: physics step in seconds, (0, 0.01].

    Names must be unique across objects, regions and obstacles and must not be one of
    ``table``, ``floor``, ``world``, ``robot``, ``gripper``, ``tcp``. Raises
    :class:`TargetError` otherwise.
    """

    objects: tuple[ObjectSpec, ...] = ()
    regions: tuple[RegionSpec, ...] = ()
    obstacles: tuple[ObstacleSpec, ...] = ()
    timestep: float = 0.002
    #: ``{seed, distractors?}``: draw the objects' physical properties and distractors from
    #: the seed (:func:`phyagentos.targets.world.draw_world`); kept as sorted pairs so the
    #: spec stays hashable (``dict(spec.randomise)`` reads it).
    randomise: Any = None

    def __post_init__(self) -> None:
        if self.randomise is not None:
            if isinstance(self.randomise, Mapping):
                pairs = tuple(sorted((str(k), tuple(v) if isinstance(v, list) else v) for k, v in self.randomise.items()))
            elif isinstance(self.randomise, tuple):
                pairs = self.randomise
            else:
                raise TargetError(f"scene randomise must be a mapping like {{seed: 3}}, got {self.randomise!r}")
            object.__setattr__(self, "randomise", pairs or None)
        for kind in ("objects", "regions", "obstacles"):
            items = getattr(self, kind)
            if isinstance(items, (str, bytes, Mapping)):
                raise TargetError(f"scene {kind} must be a sequence, got {type(items).__name__}")
            object.__setattr__(self, kind, tuple(_item_from_dict(kind, d, i) for i, d in enumerate(items)))
        ts = _floats([self.timestep], 1, "scene timestep")[0]
        if not 0.0 < ts <= 0.01:
            raise TargetError(f"scene timestep must be in (0, 0.01] s, got {ts}")
        object.__setattr__(self, "timestep", ts)
        seen: set[str] = set()
        for item in (*self.objects, *self.regions, *self.obstacles):
            if item.name in seen:
                raise TargetError(f"scene name {item.name!r} is used twice; names must be unique")
            if item.name in _RESERVED_NAMES:
                raise TargetError(f"scene name {item.name!r} is reserved: {format_choices(_RESERVED_NAMES)}")
            seen.add(item.name)

    # -- lookup ---------------------------------------------------------------------
    @property
    def object_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.objects)

    @property
    def region_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.regions)

    @property
    def obstacle_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.obstacles)

    def object(self, name: str) -> ObjectSpec:
        """The object called ``name``; TargetError listing the objects otherwise."""
        for o in self.objects:
            if o.name == name:
                return o
        raise TargetError(f"unknown object {name!r}; objects: {format_choices(self.object_names)}")

    def region(self, name: str) -> RegionSpec:
        """The region called ``name``; TargetError listing the regions otherwise."""
        for r in self.regions:
            if r.name == name:
                return r
        raise TargetError(f"unknown region {name!r}; regions: {format_choices(self.region_names)}")

    def obstacle(self, name: str) -> ObstacleSpec:
        """The obstacle called ``name``; TargetError listing the obstacles otherwise."""
        for o in self.obstacles:
            if o.name == name:
                return o
        raise TargetError(f"unknown obstacle {name!r}; obstacles: {format_choices(self.obstacle_names)}")

    # -- (de)serialisation ------------------------------------------------------------
    @classmethod
    def default(cls) -> "SceneSpec":
        """:data:`DEFAULT_SCENE`: cube at (0.5, -0.2), region ``goal`` at (0.5, 0.25),
        a 30 cm wall between them."""
        return DEFAULT_SCENE

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, root: str | Path | None = None) -> "SceneSpec":
        """Build from plain data (e.g. parsed YAML).

        ``d`` may hold ``objects``, ``regions``, ``obstacles`` (lists of mappings with the
        dataclass field names) and ``timestep``. Unknown keys raise :class:`TargetError`
        listing the valid ones. ``root`` is the workspace root that ``mesh`` paths of
        ``shape: mesh`` objects are relative to (:mod:`phyagentos.targets.mesh`); a mesh
        object without it raises :class:`TargetError`.
        """
        if not isinstance(d, Mapping):
            raise TargetError(f"scene must be a mapping, got {type(d).__name__}")
        unknown = set(d) - set(_SCENE_KEYS)
        if unknown:
            raise TargetError(
                f"scene: unknown key(s) {format_choices(unknown)}; valid keys: {format_choices(_SCENE_KEYS)}"
            )
        kwargs: dict[str, Any] = {}
        for kind in ("objects", "regions", "obstacles"):
            items = d.get(kind) or ()
            if isinstance(items, (str, bytes, Mapping)):
                raise TargetError(f"scene {kind} must be a list, got {type(items).__name__}")
            kwargs[kind] = tuple(_item_from_dict(kind, item, i, root) for i, item in enumerate(items))
        if "timestep" in d:
            kwargs["timestep"] = d["timestep"]
        if d.get("randomise") is not None:
            kwargs["randomise"] = d["randomise"]
        return cls(**kwargs)

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form (lists and floats) that :meth:`from_dict` reads back."""

        def conv(item) -> dict[str, Any]:
            out: dict[str, Any] = {}
            for k in item.__dataclass_fields__:
                v = getattr(item, k)
                if k in _DERIVED_KEYS:
                    continue
                if k in ("mesh", "scale") and getattr(item, "shape", None) != "mesh":
                    continue  # primitives: keep their plain-data form (and scene hashes) as before
                if k == "half_extents" and getattr(item, "shape", None) == "mesh":
                    continue  # derived from the file
                if k == "cls":
                    if v is not None:
                        out["class"] = v
                    continue
                out[k] = list(v) if isinstance(v, tuple) else v
            return out

        out = {
            "objects": [conv(o) for o in self.objects],
            "regions": [conv(r) for r in self.regions],
            "obstacles": [conv(o) for o in self.obstacles],
            "timestep": self.timestep,
        }
        if self.randomise:
            out["randomise"] = {k: list(v) if isinstance(v, tuple) else v for k, v in self.randomise}
        return out


DEFAULT_SCENE = SceneSpec(
    objects=(ObjectSpec(name="cube", half_extents=(0.02, 0.02, 0.02), position=(0.5, -0.2)),),
    regions=(RegionSpec(name="goal", center=(0.5, 0.25), half_extents=(0.08, 0.08)),),
    obstacles=(ObstacleSpec(name="wall", center=(0.5, 0.03, 0.15), half_extents=(0.2, 0.01, 0.15)),),
)


# ----------------------------------------------------------------------------- build


@lru_cache(maxsize=1)
def _wrapper_xml() -> str:
    p = franka_asset_dir()
    return f"""<mujoco model="phyagentos_panda_tabletop">
  <include file="{p / 'assets.xml'}"/>
  <compiler angle="radian" meshdir="{p / 'meshes'}" autolimits="true"/>
  <include file="{p / 'actuator.xml'}"/>
  <worldbody>
    <include file="{p / 'chain.xml'}"/>
  </worldbody>
</mujoco>"""

_OBJECT_GEOM = {"box": mujoco.mjtGeom.mjGEOM_BOX, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
                "sphere": mujoco.mjtGeom.mjGEOM_SPHERE}


def unseen_slot_name(i: int) -> str:
    """Body and geom name of spare box ``i`` (:data:`UNSEEN_SLOTS`)."""
    return f"unseen_slot{i}"


def _object_geom_size(o: ObjectSpec) -> list[float]:
    """MuJoCo geom size of ``o``: box half extents, cylinder (radius, half height), sphere radius."""
    hx, hy, hz = o.half_extents
    if o.shape == "cylinder":
        return [hx, hz, 0.0]
    if o.shape == "sphere":
        return [hx, 0.0, 0.0]
    return [hx, hy, hz]


def add_tabletop_world(ms: mujoco.MjSpec, spec: SceneSpec, *, legs: bool = False) -> None:
    """Add the floor, the table (top at z = 0), and ``spec``'s regions, obstacles and
    objects to ``ms``'s world body (shared by every tabletop robot). Objects get a free
    joint ``name:free``, one geom ``name`` of their shape, condim 4 and the stiff contact
    parameters of the module docstring."""
    wb = ms.worldbody
    wb.add_geom(name=FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3.0, 3.0, 0.1],
                pos=[0.0, 0.0, -_TABLE_HEIGHT_M], rgba=[0.25, 0.28, 0.32, 1.0])
    tx = 0.5 * (_TABLE_X[1] - _TABLE_X[0])
    ty = 0.5 * (_TABLE_Y[1] - _TABLE_Y[0])
    wb.add_geom(name=TABLE_GEOM, type=mujoco.mjtGeom.mjGEOM_BOX, size=[tx, ty, _TABLE_THICKNESS_M / 2.0],
                pos=[0.5 * (_TABLE_X[0] + _TABLE_X[1]), 0.5 * (_TABLE_Y[0] + _TABLE_Y[1]), -_TABLE_THICKNESS_M / 2.0],
                rgba=[0.72, 0.60, 0.45, 1.0], friction=[1.0, 0.005, 0.0001])
    if legs:
        leg_h = (_TABLE_HEIGHT_M - _TABLE_THICKNESS_M) / 2.0
        for i, (lx, ly) in enumerate(
            [(_TABLE_X[0] + 0.05, _TABLE_Y[0] + 0.05), (_TABLE_X[0] + 0.05, _TABLE_Y[1] - 0.05),
             (_TABLE_X[1] - 0.05, _TABLE_Y[0] + 0.05), (_TABLE_X[1] - 0.05, _TABLE_Y[1] - 0.05)]
        ):
            wb.add_geom(name=f"table_leg{i}", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.03, leg_h],
                        pos=[lx, ly, -_TABLE_THICKNESS_M - leg_h], rgba=[0.55, 0.45, 0.35, 1.0],
                        contype=0, conaffinity=0)
    for r in spec.regions:
        wb.add_geom(name=region_geom_name(r.name), type=mujoco.mjtGeom.mjGEOM_BOX,
                    size=[r.half_extents[0], r.half_extents[1], _REGION_THICKNESS_M],
                    pos=[r.center[0], r.center[1], _REGION_THICKNESS_M], rgba=list(r.rgba),
                    contype=0, conaffinity=0, mass=0.0)
    for ob in spec.obstacles:
        wb.add_geom(name=obstacle_geom_name(ob.name), type=mujoco.mjtGeom.mjGEOM_BOX, size=list(ob.half_extents),
                    pos=list(ob.center), rgba=list(ob.rgba))
    for o in spec.objects:
        body = wb.add_body(name=o.name, pos=[o.position[0], o.position[1], o.rest_z], quat=yaw_quat(o.yaw))
        body.add_freejoint(name=object_joint_name(o.name))
        # matte material: MuJoCo's default specular (0.5) puts white highlights on the top
        # face that split one object into two colour clusters in perception (measured: 4 of
        # 12 seeds at the home pose); painted matte objects are the nominal world
        ms.add_material(name=f"material:{o.name}", specular=0.05, shininess=0.1, rgba=list(o.rgba))
        if o.shape == "mesh":
            md = o.mesh_data
            ms.assets = {**ms.assets, md.asset_name: md.data}  # the checked bytes, never re-read
            ms.add_mesh(name=f"mesh:{o.name}", file=md.asset_name, scale=[md.scale] * 3)
            # body origin = bounding-box centre: shift the file's frame by -centre
            g = body.add_geom(name=o.name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"mesh:{o.name}",
                              pos=[-c for c in md.center], rgba=list(o.rgba),
                              friction=[o.friction, 0.005, 0.0001], condim=4, solref=[0.004, 1.0],
                              solimp=[0.95, 0.99, 0.001, 0.5, 2.0], material=f"material:{o.name}")
        else:
            g = body.add_geom(name=o.name, type=_OBJECT_GEOM[o.shape], size=_object_geom_size(o), rgba=list(o.rgba),
                              friction=[o.friction, 0.005, 0.0001], condim=4, solref=[0.004, 1.0],
                              solimp=[0.95, 0.99, 0.001, 0.5, 2.0], material=f"material:{o.name}")
        g.mass = o.mass
    for i in range(UNSEEN_SLOTS):
        # under the table, within the scene's bounds: a body outside them would widen the model's extent,
        # and with it the cameras' near clipping plane (MuJoCo scales znear by stat.extent)
        body = wb.add_body(name=unseen_slot_name(i), mocap=True, pos=[0.4, 0.0, -0.5 * _TABLE_HEIGHT_M])
        body.add_geom(name=unseen_slot_name(i), type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.01, 0.01, 0.01],
                      rgba=[0.0, 0.0, 0.0, 0.0], group=5, contype=UNSEEN_SLOT_BIT, conaffinity=0, mass=0.0)


def _add_wrist_sensors(ms: mujoco.MjSpec) -> None:
    """Wrist force/torque sensors on :data:`FT_SITE` (link7's flange) and the wrist RGB-D
    camera :data:`WRIST_CAMERA` on the hand: 6 cm beside the tool axis (across the finger
    motion, so the fingers stay out of the middle of the image), 12 cm along link7, looking
    at the point 0.2 m beyond the tcp on the tool axis."""
    link7 = ms.body("panda0_link7")
    link7.add_site(name=FT_SITE, pos=[0.0, 0.0, _FLANGE_Z_M], size=[0.005, 0, 0], group=4)
    ms.add_sensor(name="wrist_force", type=mujoco.mjtSensor.mjSENS_FORCE, objtype=mujoco.mjtObj.mjOBJ_SITE,
                  objname=FT_SITE)
    ms.add_sensor(name="wrist_torque", type=mujoco.mjtSensor.mjSENS_TORQUE, objtype=mujoco.mjtObj.mjOBJ_SITE,
                  objname=FT_SITE)
    c, s_ = math.cos(-math.pi / 4.0), math.sin(-math.pi / 4.0)
    tool_x = np.array([c, s_, 0.0])  # tcp x axis in link7's frame (tcp yaw -pi/4)
    tool_y = np.array([-s_, c, 0.0])
    eye = 0.075 * tool_x + np.array([0.0, 0.0, 0.12])
    fwd = np.array([0.0, 0.0, _TCP_OFFSET_M + 0.2]) - eye
    fwd /= np.linalg.norm(fwd)
    up = -tool_x  # image "up" points away from the tool axis
    x = np.cross(fwd, up)
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.column_stack([x, y, -fwd]).flatten())
    del tool_y
    link7.add_camera(name=WRIST_CAMERA, pos=eye.tolist(), quat=q.tolist(), fovy=58.0)


def build_scene_spec(spec: SceneSpec) -> mujoco.MjSpec:
    """The editable :class:`mujoco.MjSpec` of ``spec`` (see :func:`build_scene`)."""
    if not isinstance(spec, SceneSpec):
        raise TargetError(f"build_scene expects a SceneSpec, got {type(spec).__name__}")
    try:
        ms = mujoco.MjSpec.from_string(_wrapper_xml())
    except Exception as exc:  # mujoco raises ValueError with the parser message
        raise TargetError(f"could not load the Franka assets: {exc}") from exc
    ms.meshdir = str(franka_asset_dir() / "meshes")

    # -- physics options: elliptic friction cones with a high impratio make the finger
    # pads hold a box without creeping; a few noslip iterations remove residual slip.
    opt = ms.option
    opt.timestep = spec.timestep
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.impratio = 10.0
    opt.noslip_iterations = 3
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    ms.visual.global_.offwidth = 1280
    ms.visual.global_.offheight = 960

    # -- robot: gravity compensated (as the real Panda's controller does), tcp site,
    # fingers coupled, adjacent links never in contact.
    for name in ROBOT_BODY_NAMES[1:]:
        ms.body(name).gravcomp = 1.0
    link7 = ms.body("panda0_link7")
    link7.add_site(
        name=TCP_SITE,
        pos=[0.0, 0.0, _TCP_OFFSET_M],
        quat=yaw_quat(-math.pi / 4.0),
        size=[0.006, 0, 0],
        rgba=[1.0, 0.6, 0.0, 0.6],
        group=4,
    )
    for a, b in zip(ROBOT_BODY_NAMES[:7], ROBOT_BODY_NAMES[1:8]):
        ms.add_exclude(bodyname1=a, bodyname2=b)
    eq = ms.add_equality(
        type=mujoco.mjtEq.mjEQ_JOINT,
        name="finger_coupling",
        name1=FINGER_JOINT_NAMES[0],
        name2=FINGER_JOINT_NAMES[1],
    )
    eq.data[:5] = [0.0, 1.0, 0.0, 0.0, 0.0]
    eq.solref = [0.005, 1.0]
    # Finger pads: firm, high friction, torsional friction so a held box cannot spin.
    for fname in FINGER_BODY_NAMES:
        for g in ms.body(fname).geoms:
            if g.contype:
                g.friction = [1.5, 0.02, 0.0001]
                g.condim = 4
                g.solref = [0.004, 1.0]
                g.solimp = [0.95, 0.99, 0.001, 0.5, 2.0]
                g.margin = 0.0
                g.priority = 1

    wb = ms.worldbody
    # -- environment
    wb.add_light(pos=[0.5, -0.8, 2.0], dir=[-0.1, 0.4, -1.0], diffuse=[0.6, 0.6, 0.6], castshadow=True)
    wb.add_light(pos=[1.5, 0.8, 2.0], dir=[-0.5, -0.4, -1.0], diffuse=[0.4, 0.4, 0.4], castshadow=False)
    # overview RGB-D camera: in front of the table, above it, the reachable table in view
    eye = [1.25, 0.0, 0.95]
    wb.add_camera(name="overview", pos=eye, quat=look_at_quat(eye, [0.5, 0.0, 0.0]), fovy=55.0)

    add_tabletop_world(ms, spec, legs=True)
    _add_wrist_sensors(ms)

    # -- keyframe 'home': arm ready, gripper open, objects at their spec poses.
    qpos: list[float] = list(HOME_QPOS) + [GRIPPER_MAX_OPENING_M, GRIPPER_MAX_OPENING_M]
    for o in spec.objects:
        qpos += [o.position[0], o.position[1], o.rest_z] + yaw_quat(o.yaw)
    ctrl = list(HOME_QPOS) + [GRIPPER_MAX_OPENING_M, GRIPPER_MAX_OPENING_M]
    ms.add_key(name="home", qpos=qpos, ctrl=ctrl)
    return ms


def build_scene(spec: SceneSpec) -> mujoco.MjModel:
    """Compile ``spec`` into a :class:`mujoco.MjModel` (see the module docstring for names).

    Raises :class:`TargetError` if the assets cannot be loaded or the model does not
    compile.
    """
    ms = build_scene_spec(spec)
    try:
        model = ms.compile()
    except Exception as exc:
        raise TargetError(f"scene does not compile: {exc}") from exc
    log.debug("built scene: nq=%d nv=%d ngeom=%d", model.nq, model.nv, model.ngeom)
    return model
