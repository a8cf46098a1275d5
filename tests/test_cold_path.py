"""What keeps work off the cold path and the hand-off of ``phyagentos run`` (issue 12).

The whole-graph check runs in a child of the runner's forkserver and gives the same
result and the same errors as in this process; the ``run`` process never imports the
motion stack; the coordinator wakes whoever runs its sessions as soon as it submits.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from phyagentos.errors import GoalGraphError
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

REPO = Path(__file__).resolve().parent.parent
PICK_AND_PLACE = goal_graphs_dir() / "pick_and_place.yaml"
HOLD = goal_graphs_dir() / "hold.yaml"


def _no_fallback(monkeypatch) -> None:
    """The check must come from the forked child: this process's fallback fails the test."""
    from phyagentos.app import graph_check_process

    def fail(*args, **kwargs):
        raise AssertionError("the graph check fell back to the calling process")

    monkeypatch.setattr(graph_check_process, "_check_here", fail)


def _in_process(path: Path, ws: Workspace):
    from phyagentos.app.graph_check import check_goal_graph
    from phyagentos.resources import skill_dirs, tree_dirs
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime

    return check_goal_graph(path, ws, BuiltinSkillRuntime.from_dirs(skill_dirs(), tree_dirs()))


def _assert_same_check(other, here) -> None:
    """``other`` (a check run elsewhere) found what the in-process check ``here`` found."""
    assert [n.id for n in other.graph.nodes] == [n.id for n in here.graph.nodes] == ["pick_cube", "place_cube"]
    assert other.poses_checked == here.poses_checked > 0
    assert other.implicit_edges == here.implicit_edges


@pytest.mark.sim
def test_the_forked_graph_check_returns_what_the_in_process_check_returns(tmp_path, monkeypatch):
    from phyagentos.app.graph_check_process import check_goal_graph_forked

    ws = Workspace.create(tmp_path / "ws")
    with monkeypatch.context() as m:
        _no_fallback(m)
        forked = check_goal_graph_forked(PICK_AND_PLACE, ws.root, fork=True)
    _assert_same_check(forked, _in_process(PICK_AND_PLACE, ws))


@pytest.mark.sim
def test_the_forked_graph_check_raises_the_same_located_error(tmp_path, monkeypatch):
    from phyagentos.app.graph_check_process import check_goal_graph_forked

    ws = Workspace.create(tmp_path / "ws")
    bad = tmp_path / "bad.yaml"
    bad.write_text(PICK_AND_PLACE.read_text().replace("params: {object: cube}", "params: {object: sphere}"))
    with monkeypatch.context() as m, pytest.raises(GoalGraphError) as forked:
        _no_fallback(m)
        check_goal_graph_forked(bad, ws.root, fork=True)
    with pytest.raises(GoalGraphError) as here:
        _in_process(bad, ws)
    assert str(forked.value) == str(here.value)
    assert "sphere" in str(forked.value) and forked.value.line == here.value.line is not None
    assert forked.value.path == here.value.path == bad


@pytest.mark.sim
def test_the_run_process_never_imports_the_motion_stack(tmp_path):
    code = (
        "import sys\n"
        "from phyagentos.cli import main\n"
        f"rc = main(['run', {str(HOLD)!r}, '--workspace', {str(tmp_path / 'ws')!r}, '--json'])\n"
        "heavy = [m for m in ('mujoco', 'mink', 'toppra', 'phyagentos.motion', 'phyagentos.primitives',"
        " 'phyagentos.targets') if m in sys.modules]\n"
        "print('HEAVY', heavy, 'RC', rc)\n"
    )
    # a script run as __main__ is re-imported by forkserver children: keep it guarded
    script = tmp_path / "run_it.py"
    script.write_text("if __name__ == '__main__':\n" + "".join(f"    {line}\n" for line in code.splitlines()))
    out = subprocess.run([sys.executable, str(script)], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert "HEAVY [] RC 0" in out.stdout, out.stdout[-2000:] + out.stderr[-3000:]


def test_the_coordinator_wakes_the_supervisor_before_it_rewrites_task_md(tmp_path):
    from phyagentos.agent.agent_loop import load_run_graph
    from phyagentos.agent.coordinator import AgentCoordinator
    from phyagentos.app.orchestrator import _register_run, skill_names

    ws = Workspace.create(tmp_path / "ws")
    run = _register_run(ws, HOLD, seed=0, target=None)
    agent = AgentCoordinator(ws, load_run_graph(ws, run.run_id, skills=skill_names()), run_id=run.run_id)
    seen: list[tuple[int, bool]] = []

    def on_submit() -> None:
        pending = [sid for sid, state, _ in ws.active_sessions(run_id=run.run_id) if state == "pending"]
        seen.append((len(pending), ws.read("TASK").data.run_id == run.run_id))

    agent.on_submit = on_submit
    assert agent.step() == 1  # the one node of hold.yaml
    assert seen == [(1, False)]  # the session is submitted; TASK.md not yet rewritten
    assert ws.read("TASK").data.run_id == run.run_id  # ... and is once the step ends
    assert agent.last_sessions is not None and len(agent.last_sessions) == len(seen)
    assert agent.step() == 0 and len(seen) == 1  # nothing new: no wake-up


@pytest.mark.parametrize("situation", ["runtime_imported", "idle_runner", "neither"])
def test_a_process_that_adapted_the_check_runs_it_itself_as_it_adapted_it(tmp_path, monkeypatch, situation):
    # Whatever this process imported before and whether a runner is idle: the replaced
    # check is the one that runs (CI once forked the original after an earlier test).
    import phyagentos.app.graph_check as graph_check
    from phyagentos.app import graph_check_process
    from phyagentos.app.graph_check_process import check_goal_graph_forked
    from phyagentos.runtime import worker

    ws = Workspace.create(tmp_path / "ws")
    calls = []
    monkeypatch.setattr(graph_check, "check_goal_graph", lambda *a, **k: calls.append(k) or "checked here")
    monkeypatch.setattr(graph_check_process, "_runtime_loaded_here", lambda: situation == "runtime_imported")
    idle = object()
    monkeypatch.setattr(worker, "borrow_runner", lambda *dirs: idle if situation == "idle_runner" else None)
    monkeypatch.setattr(worker, "park_runner", lambda runner: None)

    def no_fork():
        raise AssertionError("the check was forked: the child runs the original")

    monkeypatch.setattr(worker, "forkserver_context", no_fork)
    assert check_goal_graph_forked(HOLD, ws.root, target="franka_tabletop") == "checked here"
    assert [call["target"] for call in calls] == ["franka_tabletop"]
    assert ("checks" in calls[0]) == (situation == "idle_runner")  # runtime steps go to the idle runner


def _freeze_count(conn) -> None:
    import gc

    conn.send(gc.get_freeze_count())
    conn.close()


def test_children_of_the_runner_forkserver_start_with_its_imports_frozen():
    # gc.freeze() after the preload: a forked runner's collections never walk (and so
    # never copy) the forkserver's pages of MuJoCo, SciPy and the primitives.
    from phyagentos.runtime.worker import forkserver_context

    ctx = forkserver_context()
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_freeze_count, args=(child,), daemon=True)
    proc.start()
    child.close()
    try:
        assert parent.poll(120), "the forkserver child did not answer"
        frozen = parent.recv()
    finally:
        proc.join(timeout=10)
    assert frozen > 100_000  # the runtime's imports: several hundred thousand objects


def test_closing_a_watcher_does_not_wait_out_watchdogs_move_pairing_delay(tmp_path, monkeypatch):
    # A session file archived out of a watched directory leaves watchdog an unmatched
    # IN_MOVED_FROM that its emitter holds for 0.5 s before stop() can join it; close()
    # hands that join to a daemon thread, which still finishes it. The stop is held on a
    # gate here, so close() is seen to return while it is pending (without the gate the
    # stop can finish before the threads are listed: CI saw that).
    import os
    import threading

    from phyagentos.protocol import watch
    from phyagentos.protocol.watch import WorkspaceWatcher

    gate = threading.Event()
    real_stop = watch._stop_observer

    def gated_stop(observer) -> None:
        gate.wait(10)
        real_stop(observer)

    monkeypatch.setattr(watch, "_stop_observer", gated_stop)
    (tmp_path / "archive").mkdir()
    watcher = WorkspaceWatcher(tmp_path, dirs=("sessions",))
    assert watcher.mode == "inotify"
    observer = watcher._observer
    (tmp_path / "sessions" / "s.md").write_text("x")
    assert watcher.wait(5.0)
    os.rename(tmp_path / "sessions" / "s.md", tmp_path / "archive" / "s.md")

    watcher.close()
    stoppers = [t for t in threading.enumerate() if t.name == "phyagentos-watch-stop"]
    assert watcher._observer is None and len(stoppers) == 1 and stoppers[0].is_alive()
    assert observer.is_alive()  # close() returned before the stop
    gate.set()
    stoppers[0].join(timeout=10)
    assert not observer.is_alive()
    watcher.notify()  # a late event after close is dropped, not an error

    waited = WorkspaceWatcher(tmp_path, dirs=("sessions",))
    observer = waited._observer
    waited.close(wait=True)
    assert not observer.is_alive()


def _with_idle_runner(monkeypatch):
    """An idle runner in this process's pool (as ``run`` prestarts one), and no way to
    check other than with it: the forkserver child and this process's fallback fail."""
    from phyagentos.app import graph_check_process
    from phyagentos.resources import skill_dirs, tree_dirs
    from phyagentos.runtime import worker

    def fail(*args, **kwargs):
        raise AssertionError("the graph check did not use the idle runner")

    worker.prestart_runner(skill_dirs(), tree_dirs())
    monkeypatch.setattr(worker, "forkserver_context", fail)
    monkeypatch.setattr(graph_check_process, "_check_here", fail)


@pytest.mark.sim
def test_the_check_with_the_idle_runner_returns_what_the_in_process_check_returns(tmp_path, monkeypatch):
    from phyagentos.app.graph_check_process import check_goal_graph_forked

    ws = Workspace.create(tmp_path / "ws")
    with monkeypatch.context() as m:
        _with_idle_runner(m)
        remote = check_goal_graph_forked(PICK_AND_PLACE, ws.root, fork=True)
    _assert_same_check(remote, _in_process(PICK_AND_PLACE, ws))


@pytest.mark.sim
@pytest.mark.parametrize("change", [
    ("params: {object: cube}", "params: {object: sphere}"),  # a scene name (the runner's scene step)
    ("position: [0.5, -0.2]", "position: [1.5, -0.2]"),  # out of reach (its IK step)
])
def test_the_check_with_the_idle_runner_raises_the_same_located_error(tmp_path, monkeypatch, change):
    from phyagentos.app.graph_check_process import check_goal_graph_forked

    ws = Workspace.create(tmp_path / "ws")
    bad = tmp_path / "bad.yaml"
    text = PICK_AND_PLACE.read_text()
    assert change[0] in text
    bad.write_text(text.replace(*change))
    with monkeypatch.context() as m, pytest.raises(GoalGraphError) as remote:
        _with_idle_runner(m)
        check_goal_graph_forked(bad, ws.root, fork=True)
    with pytest.raises(GoalGraphError) as here:
        _in_process(bad, ws)
    assert str(remote.value) == str(here.value)
    assert remote.value.line == here.value.line is not None and remote.value.path == here.value.path == bad


@pytest.mark.sim
def test_the_idle_runner_is_out_of_the_pool_while_the_check_uses_it_and_back_after(tmp_path, monkeypatch):
    # Another thread's supervisor taking the same runner mid-check would read its replies.
    from phyagentos.app import graph_check_process
    from phyagentos.app.graph_check_process import check_goal_graph_forked
    from phyagentos.runtime import worker

    ws = Workspace.create(tmp_path / "ws")
    seen = []
    ask = graph_check_process._RunnerChecks._ask

    def spy(self, stage, items):
        seen.append((stage, self.runner in worker._IDLE_RUNNERS))
        return ask(self, stage, items)

    with monkeypatch.context() as m:
        _with_idle_runner(m)
        runner = worker._IDLE_RUNNERS[-1]
        m.setattr(graph_check_process._RunnerChecks, "_ask", spy)
        check_goal_graph_forked(HOLD, ws.root, fork=True)
    assert [stage for stage, _ in seen] == ["trees", "scenes", "reach"]
    assert not any(in_pool for _, in_pool in seen)
    assert worker._IDLE_RUNNERS[-1] is runner
