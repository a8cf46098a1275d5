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

import json
import logging
import os
import socket
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, Collection

from phyagentos.errors import DocumentError, GoalGraphError, PhyAgentOSError, VerifierError
from phyagentos.protocol import Workspace, WorkspaceWatcher

from .coordinator import AgentCoordinator
from .goal_graph import GoalGraph, load_goal_graph
from .gripper_resources import gripper_effects, serialise_gripper_use

__all__ = ["AgentLoop", "load_run_graph", "read_agents", "AGENTS_DIR"]

#: Each serving AgentLoop keeps ``<workspace>/.agents/<host>-<pid>.json`` while it runs
#: (``submit`` says when none does).
AGENTS_DIR = ".agents"

logger = logging.getLogger(__name__)


def read_agents(workspace_root) -> list[dict]:
    """Presence records of the agents serving a workspace, each with ``alive``."""
    out = []
    directory = Path(workspace_root) / AGENTS_DIR
    try:
        files = sorted(directory.glob("*.json"))
    except OSError:
        return out
    for path in files:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            pid = int(data.get("pid", -1))
        except (OSError, ValueError, AttributeError):
            continue
        alive = data.get("host") != socket.gethostname()  # another host's agent: assume alive
        if not alive:
            try:
                os.kill(pid, 0)
                alive = True
            except PermissionError:
                alive = True
            except (OSError, OverflowError):
                alive = False
        out.append({**data, "alive": alive})
    return out


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
        #: run id -> why this loop set it aside (a stored document no longer validates).
        self.set_aside_runs: dict[str, str] = {}

    def set_aside(self, run_id: str, exc: BaseException) -> None:
        """End ``run_id`` as failed because a stored document of it no longer validates
        (:meth:`RunRegistry.set_aside`); every other run goes on."""
        message = str(exc)
        logger.warning("run %s set aside (failed): %s", run_id, message)
        self._broken.add(run_id)
        self.set_aside_runs[run_id] = message
        try:
            self.workspace.runs.set_aside(run_id, message)
        except (PhyAgentOSError, OSError) as err:  # e.g. a read-only runs/ directory
            logger.error("run %s could not be marked failed: %s", run_id, err)

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
                self.set_aside(run_id, exc)
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
                try:
                    acted += coord.step()
                except (DocumentError, GoalGraphError, VerifierError) as exc:
                    # one hand-edited or corrupted document ends its own run, nothing else
                    self.set_aside(run_id, exc)
                    self._coordinators.pop(run_id, None)
                    acted += 1
                    continue
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
        presence = self.workspace.root / AGENTS_DIR / f"{socket.gethostname()}-{os.getpid()}.json"
        try:
            presence.parent.mkdir(exist_ok=True)
            presence.write_text(json.dumps({"host": socket.gethostname(), "pid": os.getpid(), "run": self.run_id,
                                            "started": time.time()}), encoding="utf-8")
        except OSError as exc:
            logger.debug("no presence file: %s", exc)
        try:
            self._serve()
        finally:
            presence.unlink(missing_ok=True)

    def _serve(self) -> None:
        # SESSIONS.md (a view of the session files, never fsynced) is rewritten before
        # this loop waits, once for all of a step's session writes, not by each verdict
        # and submission on the path to the next session's claim.
        self.workspace.defer_index = True
        try:
            while not self._stop:
                self.watcher.clear()
                acted = self.step()
                if self.run_id is not None and (self.run_id in self.finished or self.run_id in self.set_aside_runs):
                    return
                if self.run_id is not None and self.run_id not in self.workspace.runs.active_ids():
                    return  # finished by another agent process
                if not acted:
                    self.workspace.flush_index_quietly()
                    self.watcher.wait(self.poll_interval_s)
        finally:
            self.workspace.defer_index = False
            self.workspace.flush_index_quietly()

    def close(self) -> None:
        self.watcher.close()
