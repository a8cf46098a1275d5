"""Seeded perturbations of a benchmark episode.

The bench compiler draws at most one perturbation per episode (at the suite's rate)
and writes it into the episode's initial scene *before* any session exists, so it is
part of the session contract (``scene``) and recorded in ``evaluation.perturbation``.
Two families:

- **target-native** (:mod:`phyagentos.targets.perturbations`, applied by the target
  during the session): ``perception_noise``, ``low_friction``, ``displaced``,
  ``heavy_object``. The compiler appends ``{kind, object, seed}`` to the scene's
  ``perturbations`` list with the episode seed; magnitudes are the target module's
  documented defaults, drawn reproducibly from that seed.
- **scene composition** (applied here): ``adjacent_box``, a 6 cm tall box placed next to
  the manipulated object on one of its four sides (uniform) with a 5-20 mm gap
  (uniform); on the side the fingers close towards, a top-down grasp hits it.

The *manipulated object* is the first goal-graph node's ``object`` parameter.
"""

from __future__ import annotations

import copy
import math
from typing import Any, Callable, Mapping

import numpy as np

from phyagentos.errors import BenchError

__all__ = ["PERTURBATIONS", "TARGET_NATIVE", "apply_perturbation", "draw_perturbation"]

Perturbation = Callable[[dict, str, np.random.Generator, int], tuple[dict, dict]]


def _target_native_kinds() -> tuple[str, ...]:
    from phyagentos.targets.perturbations import KINDS  # noqa: PLC0415

    return tuple(KINDS)


#: Kinds the target applies itself (see :mod:`phyagentos.targets.perturbations`).
TARGET_NATIVE: tuple[str, ...] = _target_native_kinds()


def _find_object(scene: dict, name: str) -> dict:
    for o in scene.get("objects", []):
        if o.get("name") == name:
            return o
    raise BenchError(f"perturbation needs object {name!r} in the scene; objects: "
                     f"{[o.get('name') for o in scene.get('objects', [])]}")


def _adjacent_box(scene: dict, name: str, rng: np.random.Generator, seed: int) -> tuple[dict, dict]:
    obj = _find_object(scene, name)
    he = obj.get("half_extents", [0.02, 0.02, 0.02])
    x, y = (float(v) for v in obj.get("position", [0.5, 0.0]))
    yaw = float(obj.get("yaw", 0.0))
    side = int(rng.integers(4))  # 0 +x, 1 +y, 2 -x, 3 -y in the object's frame
    gap = float(rng.uniform(0.005, 0.020))
    box_he = (0.02, 0.02, 0.03)
    axis = side % 2
    reach = he[axis] + box_he[axis] + gap
    local = [0.0, 0.0]
    local[axis] = reach if side < 2 else -reach
    c, s = math.cos(yaw), math.sin(yaw)
    px, py = round(x + c * local[0] - s * local[1], 5), round(y + s * local[0] + c * local[1], 5)
    box = {"name": "adjacent_box", "half_extents": list(box_he), "position": [px, py], "yaw": yaw,
           "rgba": [0.45, 0.45, 0.45, 1.0]}
    scene.setdefault("objects", []).append(box)
    return scene, {"side": ["+x", "+y", "-x", "-y"][side], "gap_m": round(gap, 4), "position": [px, py]}


def _native(kind: str) -> Perturbation:
    def apply(scene: dict, name: str, rng: np.random.Generator, seed: int) -> tuple[dict, dict]:
        _find_object(scene, name)
        scene.setdefault("perturbations", []).append({"kind": kind, "object": name, "seed": int(seed)})
        return scene, {"applied_by": "target", "seed": int(seed)}

    return apply


#: Perturbation name -> function (see the module docstring for each effect).
PERTURBATIONS: Mapping[str, Perturbation] = {
    **{k: _native(k) for k in TARGET_NATIVE},
    "adjacent_box": _adjacent_box,
}


def draw_perturbation(rng: np.random.Generator, *, rate: float, kinds: tuple[str, ...]) -> str | None:
    """``None`` with probability ``1 - rate``, else one of ``kinds`` (uniform)."""
    if rate <= 0 or not kinds:
        return None
    if rng.uniform() >= rate:
        return None
    return kinds[int(rng.integers(len(kinds)))]


def apply_perturbation(kind: str, scene: Mapping[str, Any], object_name: str, rng: np.random.Generator, *,
                       seed: int) -> tuple[dict, dict]:
    """Return ``(perturbed copy of scene, details)``; raises BenchError for an unknown kind."""
    fn = PERTURBATIONS.get(kind)
    if fn is None:
        raise BenchError(f"unknown perturbation {kind!r}; valid: {sorted(PERTURBATIONS)}")
    out, details = fn(copy.deepcopy(dict(scene)), object_name, rng, seed)
    return out, {"kind": kind, "object": object_name, **details}
