"""The Agent plane as a process: drive every active run of a workspace.

``phyagentos agent WORKSPACE`` runs an :class:`AgentLoop`. Everything it needs is in
the workspace, so it can stop and restart at any time: the active runs are
``runs/.active/``, each run's graph is the copy made at submit
(``runs/<run_id>/goal_graph.yaml``) and its seed and target override are in
``runs/<run_id>/RUN.md``; the state of every node is derived from the run's sessions.
Each step of a run (verify, replan, compile ready nodes, write TASK.md) happens under
the run's lock, so two agent processes never act on one run at the same time. A run
whose nodes are all terminal is marked finished and leaves the active list.

The loop sleeps until the workspace changes (inotify on ``sessions/``,
``sessions/.index/`` and ``runs/.active/``) with a bounded polling fallback.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Callable, Collection

from phyagentos.errors import GoalGraphError, PhyAgentOSError
from phyagentos.protocol import Workspace, WorkspaceWatcher

from .coordinator import AgentCoordinator
from .goal_graph import GoalGraph, load_goal_graph
from .gripper_resources import gripper_effects, serialise_gripper_use

__all__ = ["AgentLoop", "load_run_graph"]

logger = logging.getLogger(__name__)


def load_run_graph(workspace: Workspace, run_id: str, *, skills: Collection[str]) -> GoalGraph:
    """The validated goal graph of a submitted run, with its target override applied.

    Raises:
        GoalGraphError: the stored graph no longer validates (e.g. a skill was removed).
        ProtocolError: unknown run.
    """
    record = workspace.runs.load(run_id)
    targets = [t.name for t in workspace.read("TARGETS").data.targets]
    graph = load_goal_graph(workspace.runs.graph_path(run_id), skills=skills, targets=targets)
    if record.target is not None:
        graph = replace(graph, nodes=tuple(replace(n, target=record.target) for n in graph.nodes))
    # One arm holds one object: the same implicit edges `validate` shows.
    graph, _ = serialise_gripper_use(graph, gripper_effects())
    return graph


class AgentLoop:
    """Steps the AgentCoordinator of every active run.

    Args:
        workspace: the protocol workspace.
        skills: skill names a graph may use (the skill registry's names).
        run_id: drive only this run (``submit --follow``).
        poll_interval_s: longest sleep between steps (bounds a missed wake-up), s.
        inotify: False forces polling.
        coordinator_factory: builds the coordinator of a run (default: AgentCoordinator
            with the run's seed).
    """

    def __init__(self, workspace: Workspace, *, skills: Collection[str], run_id: str | None = None,
                 poll_interval_s: float = 1.0, inotify: bool = True,
                 coordinator_factory: Callable[[Workspace, GoalGraph, str, int | None], AgentCoordinator] | None = None):
        self.workspace = workspace
        self.skills = list(skills)
        self.run_id = run_id
        self.poll_interval_s = poll_interval_s
        self.watcher = WorkspaceWatcher(workspace.root, dirs=("sessions", "sessions/.index", "runs/.active"),
                                        inotify=inotify)
        self._factory = coordinator_factory or (
            lambda ws, graph, rid, seed: AgentCoordinator(ws, graph, run_id=rid, seed=seed))
        self._coordinators: dict[str, AgentCoordinator] = {}
        self._broken: set[str] = set()
        self._stop = False
        #: run id -> whether every node succeeded, for runs this loop finished.
        self.finished: dict[str, bool] = {}

    def request_stop(self) -> None:
        """Finish the current step and return from :meth:`serve` (safe from a signal handler)."""
        self._stop = True
        self.watcher.notify()

    def coordinator(self, run_id: str) -> AgentCoordinator | None:
        """The (cached) coordinator of ``run_id``; None if its graph cannot be loaded."""
        coord = self._coordinators.get(run_id)
        if coord is None and run_id not in self._broken:
            try:
                graph = load_run_graph(self.workspace, run_id, skills=self.skills)
                seed = self.workspace.runs.load(run_id).seed
            except (GoalGraphError, PhyAgentOSError) as exc:
                logger.error("run %s cannot be driven: %s", run_id, exc)
                self._broken.add(run_id)
                return None
            coord = self._coordinators[run_id] = self._factory(self.workspace, graph, run_id, seed)
        return coord

    def step(self) -> int:
        """One step of every active run whose lock is free; returns actions taken."""
        acted = 0
        for run_id in self.workspace.runs.active_ids():
            if self.run_id is not None and run_id != self.run_id:
                continue
            lock = self.workspace.run_lock(run_id)
            try:
                lock.acquire(timeout=0)
            except TimeoutError:
                continue  # another agent is stepping this run
            try:
                coord = self.coordinator(run_id)
                if coord is None:
                    continue
                acted += coord.step()
                if coord.done():
                    succeeded = coord.succeeded()
                    self.workspace.runs.finish(run_id, succeeded=succeeded)
                    self.finished[run_id] = succeeded
                    self._coordinators.pop(run_id, None)
                    logger.info("run %s finished: %s", run_id, "succeeded" if succeeded else "not every node succeeded")
                    acted += 1
            finally:
                lock.release()
        return acted

    def serve(self) -> None:
        """Step until :meth:`request_stop`, or until the run given as ``run_id`` finished."""
        while not self._stop:
            self.watcher.clear()
            acted = self.step()
            if self.run_id is not None and self.run_id in self.finished:
                return
            if self.run_id is not None and self.run_id not in self.workspace.runs.active_ids():
                return  # finished by another agent process
            if not acted:
                self.watcher.wait(self.poll_interval_s)

    def close(self) -> None:
        self.watcher.close()
