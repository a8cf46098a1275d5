"""Randomised tabletop episodes for the verifier-accuracy and memory benchmarks.

Every episode is a pick-and-place goal graph over the wall of
``phyagentos/data/goal_graphs/pick_and_place.yaml`` whose scene *declares* only what a user would (the
object's name and colour, the goal region, the wall) and asks the target for a
randomised world with ``randomise: {seed: <episode seed>}``: the target draws the
object's shape, size (2-7 cm), mass (0.02-1.5 kg), friction (0.1-1.2), yaw, position over
the reachable table and 0-4 distractors, some touching, plus camera noise and lighting
(:mod:`phyagentos.targets.world`, issue 9 part 7). The draw is recorded only in
``ground_truth.yaml``; nothing is tuned to make a skill fail.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

from phyagentos.bench.self_evolution import Episode

__all__ = ["random_scene", "random_episodes", "with_defaults", "with_limits"]

_WALL = {"name": "wall", "center": [0.5, 0.03, 0.15], "half_extents": [0.2, 0.01, 0.15]}
_GOAL = {"name": "goal", "center": [0.5, 0.25], "half_extents": [0.08, 0.08]}
_PICK_ACCEPT = {"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}}
_PLACE_ACCEPT = {"inside": {"object": "cube", "region": "goal"}, "released": "cube"}


def random_scene(seed: int, *, distractors: tuple[int, int] = (0, 4)) -> dict[str, Any]:
    """The declared scene of episode ``seed``: the red object, the goal, the wall and the
    randomise request (the target draws the rest from ``seed``)."""
    return {"objects": [{"name": "cube", "rgba": [0.85, 0.12, 0.1, 1]}], "regions": [dict(_GOAL)],
            "obstacles": [dict(_WALL)], "randomise": {"seed": int(seed), "distractors": list(distractors)}}


def random_episodes(seeds: Sequence[int], *, place: bool = True) -> list[Episode]:
    """Pick (and place) episodes over :func:`random_scene` for each seed."""
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
        out.append(Episode(episode_id=name, kind="random_world", seed=int(seed), graph=graph))
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


def with_limits(episodes: Sequence[Episode], **limits: float) -> list[Episode]:
    """``episodes`` with the session ``limits`` (e.g. ``heartbeat_timeout_s=60``) written
    into every node: a benchmark on a loaded, shared machine raises the runner's heartbeat
    timeout so that load does not end sessions the world did not fail."""
    out = []
    for ep in episodes:
        graph = {**ep.graph, "nodes": [{**n, "limits": {**(n.get("limits") or {}), **limits}}
                                       for n in ep.graph["nodes"]]}
        out.append(Episode(episode_id=ep.episode_id, kind=ep.kind, seed=ep.seed, graph=graph))
    return out
