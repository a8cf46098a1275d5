"""A goal-graph node on the policy flow, end to end: policy server process, supervisor, verifier."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir
from phyagentos.targets import MuJoCoTarget, SceneSpec

pytestmark = pytest.mark.sim


@pytest.fixture
def policy_server():
    """``phyagentos policy serve`` as a real process on a free loopback port."""
    proc = subprocess.Popen([sys.executable, "-m", "phyagentos.cli", "policy", "serve", "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("serving policy on ws://127.0.0.1:"), line
        yield line.split()[-1]
    finally:
        proc.kill()
        proc.wait(timeout=10)


def graph_with(tmp_path: Path, **params) -> Path:
    data = yaml.safe_load((goal_graphs_dir() / "policy_pick.yaml").read_text())
    data["nodes"][0]["params"].update(params)
    path = tmp_path / "policy_pick.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_a_policy_node_picks_the_cube_and_is_verified(tmp_path, policy_server):
    graph = graph_with(tmp_path, policy_endpoint=policy_server)
    report = run_goal_graph(graph, tmp_path / "ws", seed=0)
    assert report.succeeded, report.to_dict()
    [s] = report.sessions
    assert s.status == "succeeded" and s.verdict == "success"
    ws = Workspace.open(tmp_path / "ws")
    rec = ws.load_session(s.session_id)
    assert rec.skill_runtime == "policy"
    assert rec.adapter_plan["policy_adapter"] == "openpi"
    assert [b["bridge"] for b in rec.adapter_plan["action_bridges"]] == ["gripper_remap", "resample"]
    assert "stream_joint_positions" in rec.tool_manifest["operations"]
    bundle = tmp_path / "ws" / rec.attempts[-1].evidence
    assert yaml.safe_load((bundle / "events.yaml").read_text()) in (None, [])  # no safety intervention
    # physics, not the verifier: the cube is up in the gripper
    world = MuJoCoTarget("check", SceneSpec.from_dict(yaml.safe_load(graph.read_text())["scene"]))
    world.load_state(tmp_path / "ws" / "targets" / "franka_tabletop" / "state.npz")
    assert world.held_objects() == ("cube",) and world.object_pose("cube")[2, 3] > 0.1


def test_an_incompatible_policy_session_is_rejected_before_the_target_is_touched(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        closed = s.getsockname()[1]
    graph = graph_with(tmp_path, policy_endpoint=f"ws://127.0.0.1:{closed}", chunk_mode="sometimes")
    report = run_goal_graph(graph, tmp_path / "ws", seed=0)
    assert not report.succeeded
    [s] = report.sessions
    assert s.status == "rejected"
    rec = Workspace.open(tmp_path / "ws").load_session(s.session_id)
    assert {"preflight.policy_settings", "preflight.endpoint_unreachable"} <= {i.code for i in rec.rejection}
    assert all(i.field and i.expected and i.found and i.fix for i in rec.rejection)
    assert not (tmp_path / "ws" / "targets" / "franka_tabletop").exists()  # no target state was ever written
    assert not rec.attempts  # nothing ran
