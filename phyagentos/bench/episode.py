"""One benchmark episode: a (task, seed) pair run as one goal-graph run in its own workspace.

The bench compiler writes ``episode.yaml`` (this module's :class:`Episode`) and the
episode's first pending sessions; a worker later re-opens the workspace and drives the
run to completion through :func:`phyagentos.app.orchestrator.drive_run`, the same loop as
``phyagentos run`` (AgentCoordinator + WatchdogSupervisor + SessionRunner +
SessionVerifier). Nothing here judges success: the verdicts in the session files do.
"""

from __future__ import annotations

import logging
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import yaml

from phyagentos.errors import BenchError
from phyagentos.protocol import dump_yaml
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.yamlsource import read_yaml

__all__ = ["Episode", "EpisodeOutcome", "EPISODE_FILE", "OUTCOME_FILE", "load_episode", "save_episode",
           "episode_graph", "episode_graph_text", "run_episode"]

logger = logging.getLogger(__name__)

EPISODE_FILE = "episode.yaml"
OUTCOME_FILE = "outcome.yaml"


@dataclass(frozen=True)
class Episode:
    """What the compiler decided for one (task, seed) pair.

    Attributes:
        episode_id: ``<task>-s<seed>``, unique within a bench run (also the directory name).
        run_id: the goal-graph run id of the episode's sessions.
        task: suite task id.
        seed: episode seed (initial-state draw, session seeds, planner seeds).
        split: ``measurement`` or ``heldout``.
        goal_graph: absolute path of the task's goal graph (the task source).
        target: target override for every node, or ``None`` (the graph's own targets).
        scene: the episode's initial scene (randomised and perturbed), as plain data.
        evaluation: the evaluation block written into every session.
        limits: session ``limits`` written into every node of the episode's graph
            (e.g. ``{"heartbeat_timeout_s": 60}`` on a loaded machine); empty: the
            graph's own limits.
    """

    episode_id: str
    run_id: str
    task: str
    seed: int
    split: str
    goal_graph: str
    target: str | None
    scene: dict
    evaluation: dict
    limits: dict = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class EpisodeOutcome:
    """How the episode's execution ended (infrastructure view, not a verdict).

    Attributes:
        episode_id: the episode.
        status: ``completed`` (every node reached a terminal state) or ``error`` (the
            harness itself failed; the report lists these, never drops them).
        wall_time_s: wall time of the whole episode in the worker, s.
        worker: ``host:pid`` of the worker process.
        error: traceback text when ``status == 'error'``.
    """

    episode_id: str
    status: str
    wall_time_s: float
    worker: str
    error: str = ""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def save_episode(directory: Path, episode: Episode) -> None:
    atomic_write_text(directory / EPISODE_FILE, dump_yaml(episode.to_dict()))


def load_episode(directory: Path) -> Episode:
    """Read ``episode.yaml``; raises BenchError if missing or malformed."""
    path = Path(directory) / EPISODE_FILE
    try:
        return Episode(**read_yaml(path, error=BenchError))
    except (OSError, TypeError, BenchError) as exc:
        raise BenchError(f"episode file {path} unreadable: {exc}") from None


def episode_graph_text(episode: Episode) -> str:
    """The episode's goal graph as YAML: the task source with the episode's initial scene.

    This is what the episode's run is registered with (``runs/<run_id>/``), so the run
    is self-contained: any Agent process can continue it and a reader sees exactly the
    initial state the episode started from.
    """
    raw = read_yaml(episode.goal_graph, error=BenchError)
    raw["scene"] = episode.scene
    if episode.limits:
        for node in raw.get("nodes") or ():
            node["limits"] = {**(node.get("limits") or {}), **episode.limits}
    header = (f"# Episode {episode.episode_id} of bench run {episode.evaluation.get('bench_id')}: "
              f"{episode.goal_graph} with the episode's initial scene (seed {episode.seed}).\n")
    return header + yaml.safe_dump(raw, sort_keys=False, allow_unicode=True)


def episode_graph(workspace, episode: Episode, skills):
    """The episode's registered goal graph (target override applied), as the Agent loads it."""
    from phyagentos.agent.agent_loop import load_run_graph  # noqa: PLC0415

    return load_run_graph(workspace, episode.run_id, skills=skills)


_RUNTIME = None


def _runtime():
    # One skill/tree registry per worker process: loading YAML per episode is waste.
    global _RUNTIME
    if _RUNTIME is None:
        from phyagentos.resources import skills_dir, trees_dir  # noqa: PLC0415
        from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: PLC0415

        _RUNTIME = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    return _RUNTIME


def run_episode(directory: str | Path, *, memory=None) -> EpisodeOutcome:
    """Drive the episode in ``directory`` to completion; writes and returns its outcome.

    Args:
        directory: the episode workspace (holds ``episode.yaml`` and pending sessions).
        memory: optional :class:`~phyagentos.bench.memory.MemoryPolicy` hooks called
            before and after the run (``learn`` mode syncs LESSONS/KNOWLEDGE).

    Never raises for a failing episode: harness errors become ``status='error'`` with
    the traceback, so the report can count them instead of silently losing episodes.
    """
    import os  # noqa: PLC0415
    import socket  # noqa: PLC0415

    from phyagentos.agent.coordinator import AgentCoordinator  # noqa: PLC0415
    from phyagentos.app.orchestrator import drive_run  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415
    from phyagentos.runtime.supervisor import WatchdogSupervisor  # noqa: PLC0415

    directory = Path(directory)
    worker = f"{socket.gethostname()}:{os.getpid()}"
    started = time.perf_counter()
    episode_id = directory.name
    try:
        episode = load_episode(directory)
        episode_id = episode.episode_id
        workspace = Workspace.open(directory)
        if memory is not None:
            memory.before_episode(workspace)
        runtime = _runtime()
        graph = episode_graph(workspace, episode, runtime.skills.names())
        mode = memory.mode if memory is not None else "off"
        agent = AgentCoordinator(workspace, graph, run_id=episode.run_id, seed=episode.seed,
                                 evaluation=episode.evaluation, use_memory=mode != "off",
                                 consolidate=mode == "learn")
        supervisor = WatchdogSupervisor(workspace, runtime)
        with workspace.run_lock(episode.run_id):
            try:
                drive_run(agent, supervisor)
            finally:
                supervisor.close()
            workspace.runs.finish(episode.run_id, succeeded=agent.succeeded())
        if memory is not None:
            memory.after_episode(workspace)
        outcome = EpisodeOutcome(episode_id=episode_id, status="completed",
                                 wall_time_s=time.perf_counter() - started, worker=worker)
    except Exception:  # noqa: BLE001 - an episode must never vanish; record why it broke
        logger.exception("episode %s: harness error", episode_id)
        outcome = EpisodeOutcome(episode_id=episode_id, status="error", wall_time_s=time.perf_counter() - started,
                                 worker=worker, error=traceback.format_exc())
    atomic_write_text(directory / OUTCOME_FILE, dump_yaml(outcome.to_dict()))
    return outcome
