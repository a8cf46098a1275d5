"""Bench session compiler: (task, seed) pairs become episodes with pending sessions.

For every pair the compiler draws the episode's initial state (randomisation rules and,
at the suite's rate, one perturbation) from the episode RNG, creates the episode
workspace ``<bench run>/episodes/<task>-s<seed>/`` (TARGETS.md, SKILLRUNTIME.md and
safety.yaml copied from the bench workspace, memory per the memory mode), writes
``episode.yaml`` and lets the ordinary :class:`~phyagentos.agent.coordinator.AgentCoordinator`
compile the goal graph's ready nodes into pending sessions. Every session carries the
task source (``goal_graph``, ``node``), ``seed``, ``skill_runtime``, ``target``,
``accept`` and the ``evaluation`` block (suite, task, episode, split, memory,
protocol, perturbation).
"""

from __future__ import annotations

import copy
import logging
import math
import shutil
from pathlib import Path
from typing import Any, Mapping

from phyagentos.errors import BenchError
from phyagentos.yamlsource import read_yaml

from .episode import Episode, episode_graph, episode_graph_text, save_episode
from .perturb import apply_perturbation, draw_perturbation
from .suite import Suite, TaskSpec, episode_rng

__all__ = ["plan_episodes", "base_scene", "compile_episodes", "episode_template_dir"]

logger = logging.getLogger(__name__)

_CONFIG_DOCS = ("TARGETS.md", "SKILLRUNTIME.md", "safety.yaml")


def base_scene(task: TaskSpec) -> dict:
    """The scene block of the task's goal graph (plain data; ``{}`` when absent)."""
    raw = read_yaml(task.goal_graph, error=BenchError) or {}
    return copy.deepcopy(raw.get("scene") or {})


def _manipulated_object(task: TaskSpec) -> str | None:
    raw = read_yaml(task.goal_graph, error=BenchError) or {}
    for node in raw.get("nodes") or ():
        obj = (node.get("params") or {}).get("object")
        if obj:
            return str(obj)
    return None


def _randomize(scene: dict, task: TaskSpec, rng) -> tuple[dict, list[dict]]:
    scene = copy.deepcopy(scene)
    draws = []
    items = {item.get("name"): (kind, item) for kind in ("objects", "regions", "obstacles")
             for item in scene.get(kind, []) or []}
    for rule in task.randomize:
        dx = float(rng.uniform(-rule.xy[0], rule.xy[0])) if rule.xy[0] else 0.0
        dy = float(rng.uniform(-rule.xy[1], rule.xy[1])) if rule.xy[1] else 0.0
        dyaw = float(rng.uniform(-rule.yaw, rule.yaw)) if rule.yaw else 0.0
        for name in rule.names:
            if name not in items:
                raise BenchError(f"task {task.id!r}: randomize names {name!r}, which is not in the scene of "
                                 f"{task.goal_graph} (scene items: {sorted(items)})")
            kind, item = items[name]
            key = "position" if kind == "objects" else "center"
            pos = list(item.get(key, [0.0, 0.0]))
            pos[0] = round(float(pos[0]) + dx, 5)
            pos[1] = round(float(pos[1]) + dy, 5)
            item[key] = pos
            if kind == "objects" and dyaw:
                item["yaw"] = round(math.remainder(float(item.get("yaw", 0.0)) + dyaw, 2 * math.pi), 5)
        draws.append({"names": list(rule.names), "dxy_m": [round(dx, 5), round(dy, 5)], "dyaw_rad": round(dyaw, 5)})
    return scene, draws


def plan_episodes(suite: Suite, *, bench_id: str, seeds: tuple[int, ...], split: str, memory: str,
                  protocol: str, tasks: tuple[str, ...] | None = None,
                  limits: dict | None = None) -> list[Episode]:
    """Decide every episode of the run (pure: no files written). ``limits``: session
    limits written into every node (see :class:`~phyagentos.bench.episode.Episode`).

    Raises:
        BenchError: unknown task id, or a randomisation rule naming a missing scene item.
    """
    chosen = [suite.task(t) for t in tasks] if tasks else list(suite.tasks)
    episodes = []
    for task in chosen:
        index = suite.task_ids.index(task.id)
        scene0 = base_scene(task)
        obj = _manipulated_object(task)
        for seed in seeds:
            rng = episode_rng(suite, index, seed)
            scene, draws = _randomize(scene0, task, rng)
            if task.seed_to_scene:
                scene[task.seed_to_scene] = int(seed)
            if task.random_world is not None:
                # the target draws the world from this seed; only the seed is in the scene
                scene["randomise"] = {"seed": int(rng.integers(0, 2 ** 31 - 1)), **task.random_world}
            kind = draw_perturbation(rng, rate=suite.perturbations.rate, kinds=suite.perturbations.kinds)
            perturbation = None
            if kind is not None:
                if obj is None:
                    raise BenchError(f"task {task.id!r}: perturbation {kind!r} needs a node with an 'object' parameter")
                scene, perturbation = apply_perturbation(kind, scene, obj, rng, seed=seed)
            episode_id = f"{task.id}-s{seed}"
            evaluation: dict[str, Any] = {
                "bench_id": bench_id, "suite": suite.name, "suite_file": str(suite.path), "task": task.id,
                "episode": episode_id, "seed": seed, "split": split, "memory": memory, "protocol": protocol,
                "randomization": draws, "perturbation": perturbation,
                "perturbation_rate": suite.perturbations.rate,
            }
            episodes.append(Episode(episode_id=episode_id, run_id=f"{bench_id}-{episode_id}", task=task.id, seed=seed,
                                    split=split, goal_graph=str(task.goal_graph), target=task.target, scene=scene,
                                    evaluation=evaluation, limits=dict(limits or {})))
    return episodes


def episode_template_dir(bench_root: Path, run_dir: Path, memory_files: dict[str, Path],
                         safety: dict | None = None, *, name: str = "template") -> Path:
    """A template directory ``run_dir/name`` for episode workspaces: package templates,
    overlaid with the bench workspace's configuration documents, the memory documents of
    the mode and the ``safety`` overrides (the suite's, or a task's over the suite's;
    merged into safety.yaml and validated).

    Raises:
        BenchError: the merged safety configuration is invalid.
    """
    from phyagentos.resources import templates_dir  # noqa: PLC0415

    out = run_dir / name
    out.mkdir(parents=True, exist_ok=True)
    for src in templates_dir().iterdir():
        if src.is_file():
            shutil.copy2(src, out / src.name)
    for name in _CONFIG_DOCS:
        shutil.copy2(bench_root / name, out / name)
    for key, path in memory_files.items():
        shutil.copy2(path, out / f"{key}.md")
    if safety:
        from phyagentos.protocol import SafetyConfig, dump_yaml  # noqa: PLC0415

        merged = {**(read_yaml(out / "safety.yaml", error=BenchError) or {}), **safety}
        try:
            SafetyConfig.model_validate(merged)
        except Exception as exc:  # noqa: BLE001 - pydantic ValidationError: name the suite's key
            raise BenchError(f"suite safety overrides give an invalid safety.yaml: {exc}") from None
        (out / "safety.yaml").write_text("# bench episode safety: bench workspace safety.yaml + suite overrides\n"
                                         + dump_yaml(merged), encoding="utf-8")
    return out


def compile_episodes(episodes: list[Episode], *, run_dir: Path, template: Path,
                     task_templates: Mapping[str, Path] | None = None) -> list[Path]:
    """Create each episode's workspace and pending sessions; returns the directories.

    Each episode's workspace is made from ``task_templates[episode.task]`` where its task
    has its own template (its own safety overrides), else from ``template``.

    Raises:
        BenchError: an episode directory exists already (a bench run is never
            compiled twice into the same place).
    """
    from phyagentos.agent.coordinator import AgentCoordinator  # noqa: PLC0415
    from phyagentos.app.orchestrator import skill_names  # noqa: PLC0415
    from phyagentos.protocol import RunRecord, Workspace, utc_now_iso  # noqa: PLC0415

    skills = skill_names()
    root = run_dir / "episodes"
    dirs = []
    for ep in episodes:
        directory = root / ep.episode_id
        if directory.exists():
            raise BenchError(f"episode directory {directory} already exists; use a new bench run")
        ws = Workspace.create(directory, templates=(task_templates or {}).get(ep.task, template))
        save_episode(directory, ep)
        # Registered like `phyagentos submit`: the run's own copy of its graph is the task
        # source with the episode's initial scene.
        ws.register_run(RunRecord(run_id=ep.run_id, goal_graph=ep.goal_graph, graph_file="", seed=ep.seed,
                                  target=ep.target, submitted_at=utc_now_iso(),
                                  submitted_by=f"bench {ep.evaluation.get('bench_id')}"), episode_graph_text(ep))
        graph = episode_graph(ws, ep, skills)
        with ws.run_lock(ep.run_id):
            # compiles the ready nodes into pending sessions and writes TASK.md
            AgentCoordinator(ws, graph, run_id=ep.run_id, seed=ep.seed, evaluation=ep.evaluation).step()
        dirs.append(directory)
    logger.info("compiled %d episodes into %s", len(dirs), root)
    return dirs
