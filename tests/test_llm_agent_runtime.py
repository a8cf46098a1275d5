"""Agent-directed tool execution (runtime: agent) with the real offline model, under the SafetyGuard."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.protocol import Workspace
from phyagentos.runtime.agent_runtime import operation_menu

pytestmark = pytest.mark.sim

GOAL = "open the gripper fully, hold still for one second, then finish"


def write_graph(path):
    path.write_text(yaml.safe_dump({
        "version": 1, "name": "agent_gripper",
        "scene": {"objects": [{"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.5, -0.2]}]},
        "nodes": [{"id": "open_and_hold", "skill": "agent_directed", "target": "franka_tabletop", "runtime": "agent",
                   "params": {"goal": GOAL, "max_steps": 6},
                   "accept": {"still": {"max_joint_motion_rad": 0.05}, "unchanged": {"object": "cube"}}}]}))
    return path


def agent_steps(ws: Path, session_id: str) -> list[dict]:
    lines = (ws / "evidence" / session_id / "trace.jsonl").read_text().splitlines()
    return [r for r in map(json.loads, lines) if r["kind"] in ("agent_step", "handle_call")]


def test_an_agent_directed_session_finishes_with_every_command_through_the_handle(tmp_path):
    report = run_goal_graph(write_graph(tmp_path / "g.yaml"), tmp_path / "ws", seed=0)
    (summary,) = report.sessions
    rec = Workspace.open(tmp_path / "ws").load_session(summary.session_id)
    attempt = rec.attempts[0]
    assert rec.skill_runtime == "agent" and rec.adapter_plan["agent"]["operations"] == [
        "hold", "move_joints", "observe", "set_gripper"]
    assert attempt.outcome == "completed", attempt.error  # the model chose finish within its budget
    trace = agent_steps(tmp_path / "ws", rec.session_id)
    steps = [r for r in trace if r["kind"] == "agent_step"]
    assert steps[-1]["choice"] == {"operation": "finish"} and len(steps) >= 2  # acted before finishing
    for s in steps:  # every model call is recorded with the step
        assert s["call"]["provider"] == "llama.cpp" and s["call"]["prompt_tokens"] > 0
    # ... and in the session's context: prompt hash, model, parameters, tokens, latency, raw output, outcome
    calls = [c for c in rec.context.model_calls if c.role == "agent_runtime"]
    assert [c.prompt_sha256 for c in calls] == [s["call"]["prompt_sha256"] for s in steps]
    assert all(c.outcome == "accepted" and json.loads(c.output) == s["choice"] for c, s in zip(calls, steps))
    assert all(c.parameters["temperature"] == 0.0 and c.parameters["max_tokens"] == 40 and c.latency_s > 0
               for c in calls)
    assert calls[0].ref == f"evidence/{rec.session_id}/trace.jsonl"
    moved = [s for s in steps if s["choice"]["operation"] in ("move_joints", "set_gripper", "hold")
             and s.get("result", {}).get("moved", True)]
    handled = [r["operation"] for r in trace if r["kind"] == "handle_call" and r["ok"]]
    assert moved and all(s["choice"]["operation"] in handled for s in moved)
    # The verdict is the verifier's, from the evidence: 'still' holds iff the arm ended where it began.
    initial = yaml.safe_load((tmp_path / "ws" / "evidence" / rec.session_id / "initial.yaml").read_text())
    terminal = yaml.safe_load((tmp_path / "ws" / "evidence" / rec.session_id / "terminal.yaml").read_text())
    q0 = np.array(next(e for e in initial["entities"] if e["name"] == "panda")["attributes"]["joint_positions"])
    q1 = np.array(next(e for e in terminal["entities"] if e["name"] == "panda")["attributes"]["joint_positions"])
    still = float(np.max(np.abs(q1 - q0))) <= 0.05
    assert summary.verdict == ("success" if still else "failure")


def test_the_safety_guard_stops_an_agent_directed_motion_and_nothing_moves(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    safety = ws.root / "safety.yaml"
    safety.write_text(safety.read_text().replace("max_command_duration_s: 30", "max_command_duration_s: 0.05"))
    report = run_goal_graph(write_graph(tmp_path / "g.yaml"), ws.root, seed=0)
    rec = ws.load_session(report.sessions[0].session_id)
    attempt = rec.attempts[0]
    assert attempt.outcome == "failed" and attempt.error.code.startswith("safety."), attempt.error
    refused = [s for s in agent_steps(ws.root, rec.session_id) if s["kind"] == "agent_step" and not s["ok"]]
    assert refused[-1]["refused_by"] == "safety_guard"
    assert attempt.verdict.verdict == "failure" and attempt.verdict.diagnosis.cause == "safety_intervention"


def test_the_operation_menu_offers_only_granted_operations_and_never_a_repeat():
    menu = operation_menu(("observe", "set_gripper"), allow_finish=False, done=frozenset({("set_gripper", 0.0)}))
    ops = {v["properties"]["operation"]["enum"][0]: v for v in menu["anyOf"]}
    assert set(ops) == {"set_gripper", "observe"}
    assert ops["set_gripper"]["properties"]["opening_m"]["enum"] == [0.02, 0.04]
    assert "finish" in {v["properties"]["operation"]["enum"][0] for v in operation_menu(("observe",))["anyOf"]}


def test_the_runner_stays_alive_while_the_model_loads_and_thinks(tmp_path):
    """A heartbeat shorter than the model's load and think time: the runner beats while it
    waits on the model (SkillContext.alive from a helper thread), so the WatchdogSupervisor
    does not end a working session with ``heartbeat.runner``."""
    graph = yaml.safe_load(write_graph(tmp_path / "g.yaml").read_text())
    graph["nodes"][0]["limits"] = {"heartbeat_timeout_s": 1.5}
    (tmp_path / "g.yaml").write_text(yaml.safe_dump(graph))
    report = run_goal_graph(tmp_path / "g.yaml", tmp_path / "ws", seed=0)
    (summary,) = report.sessions
    rec = Workspace.open(tmp_path / "ws").load_session(summary.session_id)
    attempt = rec.attempts[0]
    assert attempt.outcome == "completed", attempt.error
    calls = [c for c in rec.context.model_calls if c.role == "agent_runtime"]
    assert calls and sum(c.latency_s for c in calls) > 1.5  # the model's time alone outlasts one heartbeat


def test_beating_stamps_while_the_body_runs_and_never_past_its_bound(monkeypatch):
    import time

    from phyagentos.runtime import agent_runtime

    monkeypatch.setattr(agent_runtime, "THINKING_BEAT_S", 0.02)
    stamps: list[float] = []
    with agent_runtime._beating(lambda: stamps.append(time.monotonic()), until=time.monotonic() + 10.0):
        time.sleep(0.2)
    ended = time.monotonic()
    n = len(stamps)
    assert n >= 3 and stamps[-1] <= ended
    time.sleep(0.1)
    assert len(stamps) == n  # the helper is gone with the body
    stamps.clear()
    bound = time.monotonic() + 0.06
    with agent_runtime._beating(lambda: stamps.append(time.monotonic()), until=bound):
        time.sleep(0.25)  # a model call that hangs past the session's time goes stale
    assert stamps and all(t < bound + 0.02 for t in stamps)
