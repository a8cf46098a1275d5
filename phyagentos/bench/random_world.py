"""Randomised tabletop episodes for the verifier-accuracy and memory benchmarks.

Every episode is a pick-and-place goal graph over the wall of
``goal_graphs/pick_and_place.yaml`` whose scene is drawn from the episode seed alone
(issue 9, part 7's distribution):

- the target object: shape box | cylinder | sphere (uniform), size 2-7 cm (uniform per
  axis for a box; radius and height for a cylinder; a sphere's diameter), yaw uniform,
  mass 0.02-1.5 kg (log-uniform), sliding friction 0.1-1.2 (uniform), position uniform
  over the reachable table on the near side of the wall (x 0.38-0.62 m, y -0.34 to
  -0.12 m), colour red;
- 0-4 distractors (uniform count) of the same size, mass and friction ranges in other
  colours: each either touching the target (gap 0-2 mm on a random side, probability 1/2)
  or anywhere else on the near side, never overlapping anything;
- the goal region 16 x 16 cm on the far side, its centre jittered by +-3 cm.

The draw is recorded in the graph's scene (so the simulator builds it and the runner
copies it into ``ground_truth.yaml``'s ``scene_record``); the Agent plane reads only the
declared descriptors of it (name, shape, colour, size). This generator stands in for
the runtime's own randomised world until that lands; it is deterministic per seed.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from phyagentos.self_evolution import Episode

__all__ = ["random_scene", "random_episodes", "with_defaults", "SIZE_M", "MASS_KG", "FRICTION"]

SIZE_M = (0.02, 0.07)
MASS_KG = (0.02, 1.5)
FRICTION = (0.1, 1.2)
_NEAR_X, _NEAR_Y = (0.38, 0.62), (-0.34, -0.12)
_COLOURS = [[0.15, 0.3, 0.85, 1], [0.95, 0.85, 0.1, 1], [0.6, 0.2, 0.7, 1], [0.1, 0.75, 0.75, 1]]
_WALL = {"name": "wall", "center": [0.5, 0.03, 0.15], "half_extents": [0.2, 0.01, 0.15]}
_PICK_ACCEPT = {"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}}
_PLACE_ACCEPT = {"inside": {"object": "cube", "region": "goal"}, "released": "cube"}


def _object(rng: np.random.Generator, name: str, rgba) -> dict[str, Any]:
    shape = str(rng.choice(["box", "cylinder", "sphere"]))
    lo, hi = SIZE_M
    if shape == "box":
        he = [float(rng.uniform(lo, hi)) / 2 for _ in range(3)]
    elif shape == "cylinder":
        r, h = float(rng.uniform(lo, hi)) / 2, float(rng.uniform(lo, hi)) / 2
        he = [r, r, h]
    else:
        r = float(rng.uniform(lo, hi)) / 2
        he = [r, r, r]
    mass = float(math.exp(rng.uniform(math.log(MASS_KG[0]), math.log(MASS_KG[1]))))
    return {"name": name, "shape": shape, "half_extents": [round(h, 4) for h in he],
            "yaw": round(float(rng.uniform(-math.pi, math.pi)), 4) if shape != "sphere" else 0.0,
            "mass": round(mass, 4), "friction": round(float(rng.uniform(*FRICTION)), 3), "rgba": rgba}


def _radius(o: Mapping[str, Any]) -> float:
    return math.hypot(o["half_extents"][0], o["half_extents"][1])


def random_scene(seed: int) -> dict[str, Any]:
    """The scene of episode ``seed`` (see the module docstring); deterministic per seed."""
    rng = np.random.default_rng([int(seed), 90210])
    cube = _object(rng, "cube", [0.85, 0.12, 0.1, 1])
    cube["position"] = [round(float(rng.uniform(*_NEAR_X)), 4), round(float(rng.uniform(*_NEAR_Y)), 4)]
    placed = [cube]
    for k in range(int(rng.integers(0, 5))):
        d = _object(rng, f"distractor_{k}", _COLOURS[k])
        for _ in range(50):
            if rng.uniform() < 0.5:  # touching the target: along a random side, gap 0-2 mm (bounding circles)
                ang = float(rng.uniform(-math.pi, math.pi))
                dist = _radius(cube) + _radius(d) + float(rng.uniform(0.0, 0.002))
                xy = [cube["position"][0] + dist * math.cos(ang), cube["position"][1] + dist * math.sin(ang)]
            else:
                xy = [float(rng.uniform(*_NEAR_X)), float(rng.uniform(*_NEAR_Y))]
            if not (_NEAR_X[0] - 0.04 <= xy[0] <= _NEAR_X[1] + 0.04 and -0.40 <= xy[1] <= -0.06):
                continue
            if all(math.dist(xy, o["position"]) >= _radius(o) + _radius(d) for o in placed):
                d["position"] = [round(xy[0], 4), round(xy[1], 4)]
                placed.append(d)
                break
    goal = {"name": "goal", "center": [round(0.5 + float(rng.uniform(-0.03, 0.03)), 4),
                                       round(0.25 + float(rng.uniform(-0.03, 0.03)), 4)], "half_extents": [0.08, 0.08]}
    return {"objects": placed, "regions": [goal], "obstacles": [dict(_WALL)]}


def random_episodes(seeds: Sequence[int], *, place: bool = True) -> list[Episode]:
    """Pick (and place) episodes over :func:`random_scene` for each seed; ``kind`` is the
    target's shape (for per-shape tables)."""
    out = []
    for seed in seeds:
        scene = random_scene(seed)
        nodes = [{"id": "pick_cube", "skill": "pick", "params": {"object": "cube"}, "accept": _PICK_ACCEPT,
                  "limits": {"execution_timeout_s": 120}}]
        if place:
            nodes.append({"id": "place_cube", "skill": "place", "params": {"object": "cube", "region": "goal"},
                          "accept": _PLACE_ACCEPT, "depends_on": ["pick_cube"], "limits": {"execution_timeout_s": 120}})
        name = f"world-s{seed}"
        graph = {"version": 1, "name": name, "description": f"randomised tabletop world, seed {seed}",
                 "defaults": {"target": "franka_tabletop"}, "scene": scene, "nodes": nodes}
        out.append(Episode(episode_id=name, kind=scene["objects"][0]["shape"], seed=int(seed), graph=graph))
    return out


def with_defaults(episodes: Sequence[Episode], defaults: Mapping[str, Mapping[str, Any]]) -> list[Episode]:
    """``episodes`` with fixed per-skill parameters ``defaults`` (skill -> {param: value})
    written into every node (the "best fixed defaults" baseline of the memory benchmark)."""
    out = []
    for ep in episodes:
        graph = {**ep.graph, "nodes": [{**n, "params": {**(defaults.get(n["skill"]) or {}), **n["params"]}}
                                       for n in ep.graph["nodes"]]}
        out.append(Episode(episode_id=ep.episode_id, kind=ep.kind, seed=ep.seed, graph=graph))
    return out
