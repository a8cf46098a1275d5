"""A randomised tabletop world drawn from the episode seed (issue 9 part 7: failures nobody scripted).

A scene may ask for it with ``randomise``::

    scene:
      objects:
        - {name: cube, rgba: [0.85, 0.12, 0.1, 1]}   # what the user declares: name, colour, class
      regions: [...]
      obstacles: [...]
      randomise: {seed: 17}                          # optional: distractors: [0, 4]

:func:`draw_world` then replaces every declared object's physical properties, and adds
distractors, from that seed alone (nothing is tuned to make a skill fail):

- shape: box | cylinder | sphere, uniform;
- size 2-7 cm: a box's three edges, a cylinder's diameter and height, a sphere's diameter,
  each uniform in [2, 7] cm;
- mass 0.02-1.5 kg, log-uniform; sliding friction 0.1-1.2, uniform; yaw uniform;
- position uniform over the reachable table: 0.35-0.70 m from the robot base, x >= 0.25 m,
  |y| <= 0.5 m, at least 3 cm clear of obstacles and regions and never overlapping another
  object (bounding circles);
- 0-4 distractors (uniform count; other colours; not declared, so perception sees them as
  ``unknown``), each with probability 1/2 touching a declared object (bounding circles
  0-2 mm apart), otherwise anywhere else on the reachable table.

Camera noise and lighting come from the same episode seed through the target's
``reset(seed=...)`` (:mod:`phyagentos.targets.camera_noise`). The draw is recorded in
``ground_truth.yaml`` (``scene_record.draw``) only; the Agent plane sees the declared
scene (names, colours, classes and the ``randomise`` seed).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from phyagentos.errors import TargetError

from .scene import OBJECT_SHAPES, ObjectSpec, SceneSpec

__all__ = ["draw_world", "SIZE_M", "MASS_KG", "FRICTION", "REACH_M", "DISTRACTORS"]

#: Full size range of an object's edges / diameters, m.
SIZE_M = (0.02, 0.07)
#: Mass range, kg (log-uniform).
MASS_KG = (0.02, 1.5)
#: Sliding friction range (uniform).
FRICTION = (0.1, 1.2)
#: Distance from the robot base of object centres, m (the Panda reaches 0.855 m; a top-down
#: grasp with the wrist above it works to about 0.7 m).
REACH_M = (0.35, 0.70)
#: Default distractor count range (inclusive).
DISTRACTORS = (0, 4)
_X_MIN, _Y_ABS = 0.25, 0.5
_CLEAR_M = 0.03
_PALETTE = ((0.15, 0.3, 0.85, 1.0), (0.95, 0.85, 0.1, 1.0), (0.6, 0.2, 0.7, 1.0), (0.1, 0.75, 0.75, 1.0),
            (0.95, 0.5, 0.1, 1.0), (0.9, 0.9, 0.9, 1.0))
_RANDOMISE_KEYS = ("seed", "distractors")


def _body(rng: np.random.Generator) -> tuple[str, tuple[float, float, float]]:
    shape = str(OBJECT_SHAPES[int(rng.integers(len(OBJECT_SHAPES)))])
    lo, hi = SIZE_M
    if shape == "box":
        he = tuple(float(rng.uniform(lo, hi)) / 2.0 for _ in range(3))
    elif shape == "cylinder":
        r, h = float(rng.uniform(lo, hi)) / 2.0, float(rng.uniform(lo, hi)) / 2.0
        he = (r, r, h)
    else:
        r = float(rng.uniform(lo, hi)) / 2.0
        he = (r, r, r)
    return shape, he  # type: ignore[return-value]


def _physics(rng: np.random.Generator) -> dict[str, float]:
    return {"mass": float(math.exp(rng.uniform(math.log(MASS_KG[0]), math.log(MASS_KG[1])))),
            "friction": float(rng.uniform(*FRICTION)), "yaw": float(rng.uniform(-math.pi, math.pi))}


def _radius(he) -> float:
    return math.hypot(he[0], he[1])


def _free(xy, r: float, scene: SceneSpec, placed: list[tuple[tuple[float, float], float]]) -> bool:
    x, y = xy
    d = math.hypot(x, y)
    if not (REACH_M[0] <= d <= REACH_M[1] and x >= _X_MIN and abs(y) <= _Y_ABS):
        return False
    for box in [*((ob.center[:2], ob.half_extents[:2]) for ob in scene.obstacles),
                *((rg.center, rg.half_extents) for rg in scene.regions)]:
        (cx, cy), (hx, hy) = box
        if abs(x - cx) < hx + r + _CLEAR_M and abs(y - cy) < hy + r + _CLEAR_M:
            return False
    return all(math.hypot(x - px, y - py) >= r + pr for (px, py), pr in placed)


def _uniform_xy(rng: np.random.Generator) -> tuple[float, float]:
    d = float(rng.uniform(*REACH_M))
    a = float(rng.uniform(-math.pi / 2, math.pi / 2))
    return d * math.cos(a), d * math.sin(a)


def draw_world(scene: SceneSpec) -> tuple[SceneSpec, dict[str, Any]]:
    """The physical scene drawn from ``scene.randomise`` (see the module docstring) and the
    record of the draw (YAML-ready). A scene without ``randomise`` is returned unchanged
    with an empty record.

    Raises:
        TargetError: a malformed ``randomise`` block, or no free place for an object
            (after 400 tries).
    """
    if not scene.randomise:
        return scene, {}
    spec = dict(scene.randomise)
    unknown = set(spec) - set(_RANDOMISE_KEYS)
    if unknown or "seed" not in spec:
        raise TargetError(f"scene randomise needs 'seed' (an integer); valid keys: {', '.join(_RANDOMISE_KEYS)}; "
                          f"got {sorted(spec)}")
    seed = spec["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise TargetError(f"scene randomise.seed must be an integer >= 0, got {seed!r}")
    lo_n, hi_n = spec.get("distractors", DISTRACTORS)
    if not (isinstance(lo_n, int) and isinstance(hi_n, int) and 0 <= lo_n <= hi_n <= 8):
        raise TargetError(f"scene randomise.distractors must be [min, max] with 0 <= min <= max <= 8, got "
                          f"{spec.get('distractors')!r}")
    rng = np.random.default_rng([int(seed), 0x9A11])
    placed: list[tuple[tuple[float, float], float]] = []
    objects: list[ObjectSpec] = []
    record: dict[str, Any] = {"seed": int(seed), "objects": {}, "distractors": []}

    def place(he, near=None) -> tuple[float, float]:
        r = _radius(he)
        for _ in range(400):
            if near is not None:
                (nx, ny), nr = near
                a = float(rng.uniform(-math.pi, math.pi))
                dist = nr + r + float(rng.uniform(0.0, 0.002))
                xy = (nx + dist * math.cos(a), ny + dist * math.sin(a))
            else:
                xy = _uniform_xy(rng)
            if _free(xy, r, scene, placed):
                placed.append((xy, r))
                return xy
        raise TargetError(f"randomised world (seed {seed}): no free place for an object of radius {r:.3f} m")

    for o in scene.objects:
        shape, he = _body(rng)
        if o.shape == "mesh":  # a mesh keeps its file's shape and size (the draw is still consumed)
            shape, he = o.shape, o.half_extents
        phys = _physics(rng)
        xy = place(he)
        new = dataclasses.replace(o, shape=shape, half_extents=he, position=xy,
                                  yaw=0.0 if shape == "sphere" else phys["yaw"], mass=phys["mass"],
                                  friction=phys["friction"])
        objects.append(new)
        record["objects"][o.name] = {"shape": shape, "half_extents": [round(h, 5) for h in he],
                                     "position": [round(c, 5) for c in xy], "yaw": round(new.yaw, 5),
                                     "mass_kg": round(new.mass, 5), "friction": round(new.friction, 4)}
    used = {tuple(round(c, 2) for c in o.rgba) for o in scene.objects}
    palette = [c for c in _PALETTE if tuple(round(v, 2) for v in c) not in used]
    n = int(rng.integers(lo_n, hi_n + 1))
    for k in range(n):
        shape, he = _body(rng)
        phys = _physics(rng)
        touching = bool(objects) and bool(rng.uniform() < 0.5)
        target = objects[int(rng.integers(len(objects)))] if touching else None
        near = (target.position, _radius(target.half_extents)) if target is not None else None
        try:
            xy = place(he, near)
        except TargetError:
            if near is None:
                raise
            touching, target = False, None
            xy = place(he)
        name = f"distractor_{k}"
        if name in {o.name for o in scene.objects} or name in scene.region_names or name in scene.obstacle_names:
            name = f"randomised_distractor_{k}"
        objects.append(ObjectSpec(name=name, half_extents=he, position=xy, shape=shape,
                                  yaw=0.0 if shape == "sphere" else phys["yaw"], mass=phys["mass"],
                                  friction=phys["friction"], rgba=palette[k % len(palette)]))
        record["distractors"].append({"name": name, "shape": shape, "half_extents": [round(h, 5) for h in he],
                                      "position": [round(c, 5) for c in xy], "mass_kg": round(phys["mass"], 5),
                                      "friction": round(phys["friction"], 4),
                                      "touching": target.name if target is not None else None})
    drawn = dataclasses.replace(scene, objects=tuple(objects), randomise=None)
    return drawn, record
