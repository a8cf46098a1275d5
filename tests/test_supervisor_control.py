"""Timeouts, cancellation, pause/resume, e-stop and shutdown, end to end with ``phyagentos watch``."""

from __future__ import annotations

import json
import os
import signal
import subprocess

import numpy as np
import pytest
import yaml
from supervisor_util import CLI, ROOT, alive, make_workspace, runner_pid, state_of, stop, submit, wait_for, watch

from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

pytestmark = pytest.mark.sim

LONG_HOLD = {"duration_s": 3600.0}  # an hour of simulated time: minutes of wall time


def signal_cli(ws: Workspace, *args: str) -> str:
    result = subprocess.run([*CLI, "signal", str(ws.root), *args], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    return result.stdout.strip()


def checkpoint_time(ws: Workspace, target: str = "franka_tabletop") -> float:
    """Simulated time of the target's last checkpoint (0 if none yet)."""
    try:
        with np.load(ws.root / "targets" / target / "state.npz") as z:
            return float(z["time"])
    except (OSError, ValueError, KeyError):
        return 0.0


def running(ws: Workspace, sid: str):
    return lambda: state_of(ws, sid) == "running"


def test_pending_session_times_out_in_the_queue(tmp_path):
    ws = make_workspace(tmp_path / "ws", targets=2)
    submit(ws, "late", target="franka_0", limits={"queue_timeout_s": 0.5})
    sup = watch(ws, "--targets", "franka_1")  # nobody claims franka_0 sessions
    try:
        wait_for(lambda: state_of(ws, "late") == "timed_out", timeout=30, what="queue timeout")
    finally:
        assert stop(sup) == 0
    rec = ws.load_session("late")
    assert [t.dest for t in rec.transitions] == ["timed_out"] and rec.attempts == []
    assert rec.result.error.code == "timeout.queue"
    assert ws.find_session_path("late").parent.parent.name == "archive"


def test_execution_timeout_ends_the_session_with_evidence_and_a_halted_target(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "slow", skill="hold", parameters=LONG_HOLD, limits={"execution_timeout_s": 1.0})
    sup = watch(ws)
    try:
        wait_for(lambda: state_of(ws, "slow") == "timed_out", timeout=60, what="execution timeout")
    finally:
        assert stop(sup) == 0
    rec = ws.load_session("slow")
    assert [t.dest for t in rec.transitions] == ["claimed", "preflight_checking", "running", "timed_out"]
    attempt = rec.attempts[0]
    assert attempt.outcome == "timed_out" and attempt.error.code == "timeout.execution"
    assert rec.result.error.code == "timeout.execution"
    bundle = yaml.safe_load((ws.root / attempt.evidence / "bundle.yaml").read_text())
    assert bundle["outcome"]["status"] == "timed_out" and "terminal" in bundle["files"]


#: Longer than any step a working runner takes between two beats on a loaded 2-core machine
#: (building the target, the initial perception: over 1 s with the CPUs oversubscribed),
#: so that only the frozen runner goes silent for that long.
FROZEN_HEARTBEAT_TIMEOUT_S = 5.0


def test_stale_runner_heartbeat_kills_the_runner_and_halts_the_target_from_its_checkpoint(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "frozen", skill="hold", parameters=LONG_HOLD, limits={"heartbeat_timeout_s": FROZEN_HEARTBEAT_TIMEOUT_S})
    sup = watch(ws)
    try:
        wait_for(running(ws, "frozen"), timeout=60, what="running")
        frozen = runner_pid(ws, sup.pid)
        wait_for(lambda: checkpoint_time(ws) > 0.5, timeout=60, what="checkpoints while holding")
        os.kill(frozen, signal.SIGSTOP)  # a runner that stops answering altogether
        wait_for(lambda: state_of(ws, "frozen") == "timed_out", timeout=60, what="heartbeat timeout")
        wait_for(lambda: not alive(frozen), timeout=10, what="the frozen runner to be killed")
    finally:
        assert stop(sup) == 0
    rec = ws.load_session("frozen")
    assert rec.result.error.code == "heartbeat.runner" and rec.attempts[0].error.code == "heartbeat.runner"
    evidence = ws.root / rec.attempts[0].evidence
    events = yaml.safe_load((evidence / "events.yaml").read_text())
    assert any(e.get("recovered") and e["code"] == "heartbeat.runner" for e in events)
    terminal = yaml.safe_load((evidence / "terminal.yaml").read_text())
    state = np.load(ws.root / "targets" / "franka_tabletop" / "state.npz")
    # the snapshot is of the restored checkpoint, taken while it held, not of a reset world
    assert terminal["sim_time_s"] > 0 and terminal["sim_time_s"] == pytest.approx(float(state["time"]))
    # halted: the arm's position command is where the arm is
    assert np.allclose(state["ctrl"][:7], state["qpos"][:7], atol=1e-6)


def test_cancel_signal_stops_a_running_session_between_ticks(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "long", skill="hold", parameters=LONG_HOLD)
    sup = watch(ws)
    try:
        wait_for(running(ws, "long"), timeout=60, what="running")
        sig_id = signal_cli(ws, "cancel", "--session", "long", "--reason", "operator changed plan")
        wait_for(lambda: state_of(ws, "long") == "cancelled", timeout=30, what="cancelled")
    finally:
        assert stop(sup) == 0
    rec = ws.load_session("long")
    assert [t.dest for t in rec.transitions] == ["claimed", "preflight_checking", "running", "cancelling", "cancelled"]
    assert rec.attempts[0].outcome == "cancelled" and rec.attempts[0].error.code == "cancelled.operator"
    handled = ws.read("RUNTIME_SIGNAL").data.handled
    assert [(a.signal_id, a.result) for a in handled] == [(sig_id, "cancelled long")]


def test_runner_that_ignores_a_cancel_is_killed_and_the_target_put_in_a_safe_state(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "stuck", skill="hold", parameters=LONG_HOLD)
    sup = watch(ws, "--cancel-grace-s", "0.5")
    try:
        wait_for(running(ws, "stuck"), timeout=60, what="running")
        stuck = runner_pid(ws, sup.pid)
        os.kill(stuck, signal.SIGSTOP)  # it will never see the cancel
        signal_cli(ws, "cancel", "--session", "stuck")
        wait_for(lambda: state_of(ws, "stuck") == "cancelled", timeout=30, what="forced cancel")
        assert not alive(stuck)
        submit(ws, "next", skill="noop")  # a fresh runner serves the next session
        wait_for(lambda: state_of(ws, "next") == "awaiting_verification", timeout=60, what="next session")
    finally:
        assert stop(sup) == 0
    rec = ws.load_session("stuck")
    assert rec.result.error.code == "cancelled.operator"
    events = yaml.safe_load((ws.root / rec.attempts[0].evidence / "events.yaml").read_text())
    assert [e["code"] for e in events if e.get("recovered")] == ["cancelled.operator"]
    assert not (ws.root / "targets" / "franka_tabletop" / "inflight.yaml").exists()


def test_pause_holds_new_claims_and_resume_releases_them(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    sup = watch(ws)
    try:
        submit(ws, "warmup", skill="noop")
        wait_for(lambda: state_of(ws, "warmup") == "awaiting_verification", timeout=60, what="warm-up")
        signal_cli(ws, "pause", "--reason", "maintenance")
        wait_for(lambda: any(a.result == "paused" for a in ws.read("RUNTIME_SIGNAL").data.handled), timeout=10)
        submit(ws, "queued", skill="noop")
        with pytest.raises(AssertionError):
            wait_for(lambda: state_of(ws, "queued") != "pending", timeout=1.5, what="(no claim while paused)")
        signal_cli(ws, "resume")
        wait_for(lambda: state_of(ws, "queued") == "awaiting_verification", timeout=30, what="claim after resume")
    finally:
        assert stop(sup) == 0


def test_estop_halts_the_running_session_and_blocks_actuation_until_cleared(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "moving", skill="hold", parameters=LONG_HOLD)
    sup = watch(ws)
    try:
        wait_for(running(ws, "moving"), timeout=60, what="running")
        signal_cli(ws, "estop", "--reason", "person in the cell")
        wait_for(lambda: state_of(ws, "moving") == "cancelled", timeout=10, what="e-stop")
        submit(ws, "after", skill="noop")
        with pytest.raises(AssertionError):
            wait_for(lambda: state_of(ws, "after") != "pending", timeout=1.5, what="(no claim while e-stopped)")
        signal_cli(ws, "clear_estop")
        wait_for(lambda: state_of(ws, "after") == "awaiting_verification", timeout=30, what="claim after clear")
    finally:
        assert stop(sup) == 0
    rec = ws.load_session("moving")
    assert rec.result.error.code == "cancelled.estop" and rec.attempts[0].error.code == "cancelled.estop"
    results = [a.result for a in ws.read("RUNTIME_SIGNAL").data.handled]
    assert results == ["halted session moving", "e-stop cleared"]


def test_sigterm_cancels_the_inflight_session_cleanly_and_exits_zero(tmp_path):
    ws = make_workspace(tmp_path / "ws", targets=2)
    submit(ws, "inflight", skill="hold", target="franka_0", parameters=LONG_HOLD)
    sup = watch(ws, "--drain-s", "0.3", "--targets", "franka_0")
    wait_for(running(ws, "inflight"), timeout=60, what="running")
    submit(ws, "waiting", skill="noop", target="franka_0")
    assert stop(sup, sig=signal.SIGTERM) == 0
    rec = ws.load_session("inflight")
    assert rec.state == "cancelled" and rec.result.error.code == "cancelled.shutdown"
    assert state_of(ws, "waiting") == "pending"  # never claimed: the next supervisor gets it
    assert not list((ws.root / ".supervisors").glob("*.json"))


def test_two_plane_processes_run_a_submitted_graph_and_status_reports_it(tmp_path):
    graph = goal_graphs_dir() / "hold.yaml"
    out = subprocess.run([*CLI, "submit", str(graph), "--workspace", str(tmp_path / "ws")], capture_output=True,
                         text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    run_id = out.stdout.strip()
    ws = Workspace.open(tmp_path / "ws")
    assert ws.runs.active_ids() == [run_id]
    status = json.loads(subprocess.run([*CLI, "status", str(ws.root), "--json"], capture_output=True, text=True,
                                       timeout=60, cwd=ROOT).stdout)
    assert status["counts"] == {"pending": 1} and status["runs"][0]["nodes"] == {"hold_still": "running"}
    sup = watch(ws)
    agent = subprocess.Popen([*CLI, "agent", str(ws.root)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             cwd=ROOT)
    try:
        wait_for(lambda: ws.runs.active_ids() == [], timeout=120, what="the run to finish")
        status = json.loads(subprocess.run([*CLI, "status", str(ws.root), "--json"], capture_output=True, text=True,
                                           timeout=60, cwd=ROOT).stdout)
        assert [s["alive"] for s in status["supervisors"]] == [True]
    finally:
        assert stop(sup) == 0 and stop(agent) == 0
    run = ws.runs.load(run_id)
    assert run.state == "finished" and run.succeeded is True
    (rec,) = ws.list_sessions(run_id=run_id)
    assert rec.state == "succeeded" and rec.attempts[0].verdict.verdict == "success"
    assert status["counts"] == {} and [s["state"] for s in status["recent_sessions"]] == ["succeeded"]
