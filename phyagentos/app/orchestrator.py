"""Composition root: the one place allowed to import the Agent and Runtime planes together.

The planes meet only through the workspace. They run either as separate processes,

- ``phyagentos watch WS``  (Runtime plane: :meth:`WatchdogSupervisor.serve`),
- ``phyagentos agent WS``  (Agent plane: an AgentLoop over every active run, :func:`serve_agent`),
- ``phyagentos submit GRAPH --workspace WS`` (validate, register the run, compile its
  ready nodes: :func:`submit_goal_graph`),

or together in one process for convenience (``phyagentos run``, :func:`run_goal_graph`):
the agent's steps and the supervisor's alternate in one loop (:func:`drive_run`),
while the supervisor still runs each session in its own runner process.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from phyagentos.agent.agent_loop import AgentLoop, load_run_graph
from phyagentos.agent.coordinator import AgentCoordinator, SessionSummary
from phyagentos.agent.goal_graph import GoalGraph, load_goal_graph
from phyagentos.agent.session_compiler import new_run_id
from phyagentos.agent.verifier import SessionVerifier
from phyagentos.errors import GoalGraphError, ProtocolError, SupervisorError, format_choices
from phyagentos.protocol import LEASED_STATES, TERMINAL_STATES, RunRecord, Workspace, utc_now_iso
from phyagentos.resources import skill_dirs, tree_dirs
from phyagentos.runtime.skills import SkillRegistry
from phyagentos.runtime.supervisor import WatchdogSupervisor

if TYPE_CHECKING:
    from phyagentos.agent.reviser import Reviser
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime

__all__ = ["RunReport", "drive_run", "load_graph_for", "run_goal_graph", "submit_goal_graph", "serve_agent", "held_worlds",
           "skill_names"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunReport:
    """Outcome of one run: its id, per-session rows and whether every node succeeded."""

    run_id: str
    workspace: Path
    goal_graph: str
    succeeded: bool
    node_states: dict
    sessions: list[SessionSummary]
    wall_time_s: float

    def to_dict(self) -> dict:
        return {
            "run_id": self.run_id,
            "workspace": str(self.workspace),
            "goal_graph": self.goal_graph,
            "succeeded": self.succeeded,
            "wall_time_s": round(self.wall_time_s, 3),
            "nodes": self.node_states,
            "sessions": [s.to_dict() for s in self.sessions],
        }


def load_graph_for(workspace: Workspace, path: str | Path, runtime: "BuiltinSkillRuntime") -> GoalGraph:
    """Load and validate a goal graph against the workspace's targets and the skill registry."""
    targets = [t.name for t in workspace.read("TARGETS").data.targets]
    return load_goal_graph(path, skills=runtime.skills.names(), targets=targets)


def skill_names() -> list[str]:
    """Names of the skills in ``skills/`` (what a goal graph may use)."""
    return SkillRegistry(skill_dirs()).names()


def drive_run(agent: AgentCoordinator, supervisor: WatchdogSupervisor, *,
              progress: Callable[[str], None] | None = None) -> None:
    """Run the Agent loop and the supervisor until every node of ``agent``'s run is terminal.

    The one execution loop shared by ``phyagentos run`` and ``phyagentos bench``: the
    agent compiles ready nodes, verifies and replans; the supervisor claims, preflights
    and runs whatever is pending in the workspace. Both planes are event-driven, as in
    two-process mode but without process start-up: the supervisor runs in a thread of
    this process (its runner is still a separate, killable process), woken by its
    workspace watcher and the runner's pipe, and wakes the agent whenever it acted; the
    agent wakes the supervisor as soon as it submitted a session. Nothing sleeps on the
    path from a verdict to the next session's claim. The two views the hand-off would
    rewrite (TASK.md and SESSIONS.md, neither fsynced) are brought up to date once the
    next session has started (or the supervisor is paused, or a poll interval passes
    quietly), and before this returns. While the supervisor is paused or e-stopped, or
    another process holds a session of the run, the loop waits.

    Raises:
        SupervisorError: neither side can make progress and nothing of the run is in
            anyone's hands.
    """
    say = progress or (lambda msg: None)
    if supervisor.workspace is agent.workspace:
        # One Workspace object per thread: its index caches are not shared between threads.
        supervisor.workspace = Workspace.open(agent.workspace.root)
    wake = threading.Event()
    stop = threading.Event()
    failure: list[BaseException] = []

    # SESSIONS.md (a view, never fsynced) is brought up to date when the agent would
    # otherwise wait, in one rewrite for both threads' session writes, not by every
    # session write on the path from a verdict to the next session's start.
    agent.workspace.defer_index = True
    supervisor.workspace.share_index_deferral(agent.workspace)

    def runtime_plane() -> None:
        try:
            while not stop.is_set():
                if supervisor.step():
                    wake.set()
        except BaseException as exc:  # noqa: BLE001 - re-raised in the agent's thread
            failure.append(exc)
            wake.set()

    def views_stale() -> bool:  # (a stand-in coordinator may know no deferred views)
        return getattr(agent, "task_view_stale", False) or agent.workspace.index_pending

    def catch_up_views() -> None:
        if getattr(agent, "task_view_stale", False):
            agent.write_task()
        agent.workspace.flush_index()

    thread = threading.Thread(target=runtime_plane, name="phyagentos-supervisor", daemon=True)
    thread.start()
    agent.on_submit = supervisor.watcher.notify  # claim at once, before the agent rewrites TASK.md
    agent.defer_task_view = True  # ... and rewrite it once the session has started (below)
    last_states: dict | None = None
    try:
        idle_checked = False
        force_step = True
        while True:
            wake.clear()
            # The supervisor's claim, start, heartbeat... may have changed nothing the agent
            # acts on: then no step (which lists and parses the run's sessions) competes
            # with the supervisor thread for the interpreter on the hand-off path.
            stepped = force_step or _agent_has_work(agent)
            acted = agent.step() if stepped else 0
            force_step = False
            if failure:
                raise failure[0]
            if acted:
                supervisor.watcher.notify()  # claim at once, without waiting for inotify
            # the sessions as the step left them: terminal states do not change, so done() is exact
            sessions = getattr(agent, "last_sessions", None)
            if stepped or sessions is None or last_states is None:
                # Node states are a function of the step's listing: without a step they are
                # what the last check found (and the run was not done), so they are not
                # computed again while the supervisor works.
                states = agent.node_states(sessions)
                if states != last_states and progress is not None:
                    say("nodes: " + ", ".join(f"{n}={s}" for n, s in states.items()))
                last_states = states
                if agent.done(sessions) if sessions is not None else agent.done():
                    catch_up_views()
                    return
            if acted:
                idle_checked = False
                continue
            active = agent.workspace.active_sessions(run_id=agent.run_id)
            waiting = [sid for sid, state, _ in active if state == "pending" or state in LEASED_STATES]
            if views_stale() and (
                    supervisor.paused or supervisor.estopped
                    or not any(state in _HANDOFF_STATES for _, state, _ in active)):
                # The hand-off is over (the supervisor waits for the runner), or cannot go on
                # now: the views the last step deferred no longer compete with a claim.
                catch_up_views()
            if not waiting and not supervisor.busy:
                # Nothing is in anyone's hands: one more step sees every change made so far.
                if idle_checked:
                    raise SupervisorError(f"run {agent.run_id} stalled: node states {states}")
                idle_checked = True
                force_step = True
                continue
            idle_checked = False
            if supervisor.paused or supervisor.estopped:
                say("supervisor " + ("e-stopped" if supervisor.estopped else "paused") + "; waiting")
            if not wake.wait(supervisor.config.poll_interval_s):
                catch_up_views()  # a quiet interval: whatever holds the hand-off up, the views are current
    finally:
        agent.on_submit = None
        agent.defer_task_view = False
        owed_log = getattr(agent, "append_owed_log", None)  # (a stand-in coordinator owes none)
        if owed_log is not None:
            owed_log(quiet=True)  # verdict lines a deferred step left, if the run ends by an error
        stop.set()
        supervisor.watcher.notify()
        thread.join()
        agent.workspace.defer_index = supervisor.workspace.defer_index = False
        agent.workspace.flush_index_quietly()  # the entries of both threads (a failure must not hide the run's)


#: Session states of a hand-off in progress: submitted, claimed, being preflighted.
_HANDOFF_STATES = frozenset({"pending", "claimed", "preflight_checking"})

#: Session states in which the Agent plane has something to do (verify, revise, or take
#: over a verification whose verifier died).
_AGENT_STATES = frozenset({"awaiting_verification", "awaiting_replan", "verifying"})


def _agent_has_work(agent: AgentCoordinator) -> bool:
    """Whether a step of ``agent`` could act now, from the state index alone (no session
    file is read): a session of the run awaits the agent, or the run's active sessions
    are no longer those the last step saw (one ended, or a new one appeared). Node
    readiness changes only when a session ends, so a claim, a start or a renewed lease
    alone never needs a step."""
    seen = agent.last_sessions
    if seen is None:
        return True
    active = agent.workspace.active_sessions(run_id=agent.run_id)
    if any(state in _AGENT_STATES for _, state, _ in active):
        return True
    return {sid for sid, _, _ in active} != {s.session_id for s in seen if s.state not in TERMINAL_STATES}


def _register_run(workspace: Workspace, goal_graph: str | Path, *, seed: int | None, target: str | None,
                  submitted_by: str = "") -> RunRecord:
    text = Path(goal_graph).read_text(encoding="utf-8")
    for _ in range(20):
        record = RunRecord(run_id=new_run_id(), goal_graph=str(goal_graph), graph_file="", seed=seed, target=target,
                           submitted_at=utc_now_iso(), submitted_by=submitted_by)
        try:
            return workspace.register_run(record, text)
        except ProtocolError as exc:
            if "already exists" not in str(exc):
                raise
    raise ProtocolError("could not allocate a unique run id")  # pragma: no cover


def _check_target(workspace: Workspace, target: str | None) -> None:
    names = [t.name for t in workspace.read("TARGETS").data.targets]
    if target is not None and target not in names:
        raise GoalGraphError(f"unknown target {target!r} for --target; valid targets: {format_choices(names)}")


def held_worlds(workspace: Workspace, targets) -> dict[str, str]:
    """Target -> the other active run whose world it holds now (a new run would queue)."""
    return {t: owner for t in sorted(targets) if (owner := workspace.runs.world_owner(t)) is not None}


def _refuse_held_worlds(workspace: Workspace, targets) -> None:
    """``phyagentos run`` drives one run in-process: it refuses, rather than waits for, a
    target whose world another active run holds (that run would otherwise be reset)."""
    held = held_worlds(workspace, targets)
    if held:
        which = "; ".join(f"target {t!r} holds the world of active run {r!r}" for t, r in held.items())
        raise SupervisorError(f"{which}: a target's world belongs to one run at a time. Let it finish (`phyagentos "
                              f"agent {workspace.root} --run RUN` with `phyagentos watch {workspace.root}`), or "
                              f"submit this graph with `phyagentos submit` to queue behind it")


def submit_goal_graph(goal_graph: str | Path, workspace_dir: str | Path, *, seed: int | None = 0,
                      target: str | None = None, submitted_by: str = "") -> RunRecord:
    """Validate ``goal_graph``, register it as a run and compile its ready nodes; returns the run.

    The Agent plane's compile step, through the one validated submit path
    (:meth:`Workspace.submit_session`). ``phyagentos agent`` (or ``submit --follow``)
    then keeps verifying and compiling until every node is terminal.

    Raises:
        GoalGraphError: the goal graph (or the target override) is invalid.
        DocumentError: a protocol document in the workspace is malformed.
    """
    from phyagentos.app.graph_check import check_goal_graph  # noqa: PLC0415
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: PLC0415

    workspace = Workspace.create(workspace_dir)
    from phyagentos.deploy_check import check_deploy_files  # noqa: PLC0415

    check_deploy_files(workspace.root)  # the deploy-time files first (file:line)
    skills = skill_names()
    # The whole graph before anything is registered: errors name the user's file.
    check_goal_graph(goal_graph, workspace, BuiltinSkillRuntime.from_dirs(skill_dirs(), tree_dirs()), target=target)
    run = _register_run(workspace, goal_graph, seed=seed, target=target, submitted_by=submitted_by)
    graph = load_run_graph(workspace, run.run_id, skills=skills)
    with workspace.run_lock(run.run_id):
        AgentCoordinator(workspace, graph, run_id=run.run_id, seed=seed).step()
    logger.info("submitted run %s (%d nodes) from %s", run.run_id, len(graph.nodes), goal_graph)
    return run


def serve_agent(workspace_dir: str | Path, *, run_id: str | None = None, poll_interval_s: float = 1.0,
                inotify: bool = True, on_loop: Callable[[AgentLoop], None] | None = None) -> AgentLoop:
    """Run the Agent plane on ``workspace_dir`` until stopped (or until ``run_id`` finished).

    ``on_loop`` receives the loop before it starts (e.g. to install signal handlers
    that call :meth:`AgentLoop.request_stop`). Returns the loop (``loop.finished``).
    """
    workspace = Workspace.open(workspace_dir)
    loop = AgentLoop(workspace, skills=skill_names(), run_id=run_id, poll_interval_s=poll_interval_s, inotify=inotify)
    if on_loop is not None:
        on_loop(loop)
    try:
        loop.serve()
    finally:
        loop.close()
    return loop



def _warm_targets(goal_graph: str | Path, workspace: Workspace, *, target: str | None) -> bool:
    """Ask the idle runner (:func:`~phyagentos.runtime.worker.prestart_runner`) to build the
    targets ``goal_graph`` names, with its scene, while the whole-graph check runs: the
    first session then finds its target built and its cameras open instead of paying
    for them between its ``start`` and its first tick. Best effort and read-only: a
    file that does not parse is left to the check to report (nothing is warmed).
    Returns True if a warm-up was requested."""
    from phyagentos.runtime.worker import warm_runner  # noqa: PLC0415
    from phyagentos.yamlsource import load_yaml  # noqa: PLC0415

    try:
        doc = load_yaml(Path(goal_graph).read_text(encoding="utf-8"), path=goal_graph, error=GoalGraphError)
    except (OSError, UnicodeDecodeError, GoalGraphError):
        return False
    if not isinstance(doc, dict) or not isinstance(doc.get("nodes"), list):
        return False
    default = (doc.get("defaults") or {}).get("target") if isinstance(doc.get("defaults"), dict) else None
    names = {target} if target else {(n.get("target") or default) for n in doc["nodes"] if isinstance(n, dict)}
    scene = doc.get("scene") if isinstance(doc.get("scene"), dict) else None
    targets = [{"name": n, "scene": scene} for n in sorted(x for x in names if isinstance(x, str))]
    return bool(targets) and warm_runner(workspace.root, targets)


def run_goal_graph(
    goal_graph: str | Path,
    workspace_dir: str | Path,
    *,
    seed: int | None = 0,
    target: str | None = None,
    progress: Callable[[str], None] | None = None,
    use_memory: bool = True,
    consolidate: bool = True,
    keep_success_images: bool = False,
    reviser: "Reviser | None" = None,
) -> RunReport:
    """Run ``goal_graph`` to completion in ``workspace_dir`` (created if needed).

    Args:
        goal_graph: path of the goal-graph YAML.
        workspace_dir: the workspace directory.
        seed: base seed of the run's sessions.
        target: if given, overrides every node's target (same graph, another embodiment).
        progress: called with a one-line message as sessions move.
        use_memory: retrieve lessons, knowledge and procedures for new sessions.
        consolidate: write verified outcomes into memory (``False``: frozen memory).
        keep_success_images: keep the evidence images of successful sessions too.
        reviser: proposes the revision of a ``replan`` verdict (default: the
            AgentCoordinator's rule ladder, which leaves out what a node's target cannot act on).

    Raises:
        GoalGraphError: the goal graph is invalid.
        DocumentError: a protocol document or a deploy-time file (``sensors.yaml``,
            ``perception.yaml``, ``safety.yaml``) in the workspace is malformed (left untouched).
        LLMError, FleetError: ``llm.yaml`` or ``fleet.yaml`` is malformed (``file:line``).
        SupervisorError: the run stopped making progress before completing.
    """
    started = time.perf_counter()
    workspace = Workspace.create(workspace_dir)
    from phyagentos.app.graph_check_process import check_goal_graph_forked  # noqa: PLC0415
    from phyagentos.deploy_check import check_deploy_files  # noqa: PLC0415

    # Every deploy-time file (sensors.yaml, perception.yaml, safety.yaml, llm.yaml, fleet.yaml)
    # before any target is built: a malformed one is reported with file:line, never repaired.
    check_deploy_files(workspace.root)

    # The runner builds the graph's targets (model, cameras) while the check runs.
    _warm_targets(goal_graph, workspace, target=target)
    # The whole graph before anything is registered or moves: errors name the user's file.
    # It runs in a child of the runner's forkserver (started in the background by
    # prestart_runner), which has the primitives and the motion stack imported already.
    checked = check_goal_graph_forked(goal_graph, workspace.root, target=target)
    _refuse_held_worlds(workspace, {n.target for n in checked.graph.nodes})
    supervisor = WatchdogSupervisor(workspace)
    try:
        run = _register_run(workspace, goal_graph, seed=seed, target=target)
        graph = load_run_graph(workspace, run.run_id, skills=skill_names())
    except BaseException:
        supervisor.close()
        raise
    agent = AgentCoordinator(workspace, graph, run_id=run.run_id, seed=seed, use_memory=use_memory,
                             consolidate=consolidate, keep_success_images=keep_success_images,
                             verifier=SessionVerifier(recovery=reviser) if reviser is not None else None)
    say = progress or (lambda msg: None)
    say(f"run {agent.run_id}: {len(graph.nodes)} node(s) from {goal_graph}")
    with workspace.run_lock(run.run_id):
        try:
            drive_run(agent, supervisor, progress=say)
        finally:
            supervisor.close()
        workspace.runs.finish(run.run_id, succeeded=agent.succeeded())
    return RunReport(
        run_id=agent.run_id,
        workspace=workspace.root,
        goal_graph=str(goal_graph),
        succeeded=agent.succeeded(),
        node_states=agent.node_states(),
        sessions=agent.summary(),
        wall_time_s=time.perf_counter() - started,
    )
