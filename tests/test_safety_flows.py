"""Both flows pass the same SafetyGuard: behaviour-tree trajectories and agent-directed calls."""

from __future__ import annotations

import numpy as np
import py_trees
import pytest
import yaml

from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.errors import SafetyError, TargetError
from phyagentos.motion.retime import retime
from phyagentos.primitives.context import SkillContext
from phyagentos.primitives.execution import ExecuteTrajectory
from phyagentos.protocol import Workspace
from phyagentos.protocol.schemas import SafetyConfig
from phyagentos.resources import goal_graphs_dir
from phyagentos.runtime.safety_guard import EStopLatch, SafetyGuard
from phyagentos.runtime.target_handle import TargetSessionHandle
from phyagentos.targets import MuJoCoTarget, SceneSpec

pytestmark = pytest.mark.sim


@pytest.fixture
def target():
    t = MuJoCoTarget("flows", SceneSpec.default(), seed=0)
    yield t
    t.close()


def tick_leaf(leaf, ctx, trajectory):
    py_trees.blackboard.Blackboard.clear()
    writer = py_trees.blackboard.Client(name="test")
    writer.register_key(key="trajectory", access=py_trees.common.Access.WRITE)
    writer.trajectory = trajectory
    leaf.setup(context=ctx)
    leaf.tick_once()
    return leaf.status


def test_a_tree_trajectory_beyond_a_joint_limit_fails_the_leaf_before_anything_moves(target):
    ctx = SkillContext(target=target)
    ctx.guard = SafetyGuard.for_target(target, SafetyConfig(), events=ctx.events, estop=EStopLatch())
    q0 = target.arm_qpos()
    goal = q0.copy()
    goal[6] = 3.2  # joint 7 range ends at 2.8973 rad
    traj = retime(np.array([q0, goal]), dt=target.timestep)
    t0 = target.sim_time
    status = tick_leaf(ExecuteTrajectory("Execute"), ctx, traj)
    assert status == py_trees.common.Status.FAILURE
    assert ctx.failure["code"] == "safety.joint_limit"
    assert ctx.events[0]["code"] == "safety.joint_limit" and ctx.events[0]["flow"] == "builtin"
    assert target.sim_time == t0 and np.allclose(target.arm_qpos(), q0)  # not one step was streamed


def test_a_tree_trajectory_within_limits_is_streamed_unchanged(target):
    ctx = SkillContext(target=target)
    ctx.guard = SafetyGuard.for_target(target, SafetyConfig(), events=ctx.events, estop=EStopLatch())
    q0 = target.arm_qpos()
    traj = retime(np.array([q0, q0 + 0.05]), vel_limits=target.velocity_limits(), dt=target.timestep)
    status = tick_leaf(ExecuteTrajectory("Execute"), ctx, traj)
    assert status == py_trees.common.Status.RUNNING and ctx.events == []
    assert target.sim_time > 0


def test_the_builtin_pick_stops_at_a_tight_workspace_box_and_the_verifier_sees_a_safety_stop(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    safety = yaml.safe_load((ws.root / "safety.yaml").read_text())
    safety["workspace_box"] = {"min": [-0.2, -0.8, 0.25], "max": [1.0, 0.8, 1.2]}  # the pick must go lower
    (ws.root / "safety.yaml").write_text(yaml.safe_dump(safety))
    graph = tmp_path / "pick.yaml"
    data = yaml.safe_load((goal_graphs_dir() / "pick_and_place.yaml").read_text())
    data["nodes"] = [dict(data["nodes"][0], limits={"execution_timeout_s": 60})]
    graph.write_text(yaml.safe_dump(data))
    report = run_goal_graph(graph, ws.root, seed=0)
    [s] = report.sessions
    assert s.status == "failed" and "safety.workspace" in (s.reason or "")
    rec = Workspace.open(ws.root).load_session(s.session_id)
    events = yaml.safe_load((ws.root / rec.attempts[-1].evidence / "events.yaml").read_text())
    assert events[0]["code"] == "safety.workspace" and events[0]["flow"] == "builtin"
    assert rec.attempts[-1].verdict.verdict == "failure"  # a safety stop is not replanned


def handle_for(target, operations=("observe", "move_joints", "set_gripper", "snapshot")):
    beats = []
    guard = SafetyGuard.for_target(target, SafetyConfig(), events=[], estop=EStopLatch(), flow="agent")
    return TargetSessionHandle(target, operations, guard=guard, heartbeat=lambda: beats.append(1)), beats


def test_the_handle_exposes_only_the_manifest_and_records_refusals(target):
    handle, beats = handle_for(target)
    assert handle.operations == ("halt", "move_joints", "observe", "set_gripper", "snapshot")
    with pytest.raises(TargetError, match="not granted"):
        handle.call("step", ctrl=[0.0] * 7)
    with pytest.raises(TargetError, match="not granted"):
        handle.call("load_state", path="x")
    assert [e["code"] for e in handle.events] == ["handle.not_permitted", "handle.not_permitted"]
    state = handle.call("observe")
    assert state["target"] == "flows" and handle.state["sim_time_s"] == state["sim_time_s"] and beats == [1]


def test_the_handle_passes_on_the_robots_state_and_the_perceived_world_never_the_simulators(target):
    handle, _ = handle_for(target, operations=("observe", "query_state", "snapshot"))
    assert {"objects", "relations"} <= set(target.query_state())  # the simulation's own account
    for op in ("observe", "query_state"):
        assert not {"objects", "relations"} & set(handle.call(op))
    assert not {"objects", "relations"} & set(handle.state)
    seen = handle.call("snapshot")  # what the cameras and the perceiver make of the scene
    assert {"proprioception", "unseen"} <= set(seen)
    cube = next(e for e in seen["entities"] if e["name"] == "cube")
    assert cube["attributes"]["source"] == "perceived" and "confidence" in cube["attributes"]


def test_the_handle_validates_arguments_before_anything_moves(target):
    handle, _ = handle_for(target)
    t0 = target.sim_time
    for bad in ({"q": [0.0] * 6}, {"q": [float("nan")] * 7}, {"q": list(target.home_qpos), "speed_scale": 2.0},
                {"q": list(target.home_qpos), "bogus": 1}):
        with pytest.raises(TargetError):
            handle.call("move_joints", **bad)
    with pytest.raises(TargetError, match="opening_m"):
        handle.call("set_gripper", opening_m=0.09)
    assert target.sim_time == t0
    assert all(e["code"] == "handle.bad_arguments" for e in handle.events)


def test_a_handle_move_goes_through_the_guard(target):
    handle, beats = handle_for(target)
    q0 = target.arm_qpos()
    beyond = q0.copy()
    beyond[6] = 3.2  # joint 7 range ends at 2.8973 rad
    with pytest.raises(SafetyError) as exc:
        handle.call("move_joints", q=list(beyond))
    assert exc.value.code == "safety.joint_limit"
    assert handle.events[-1]["code"] == "safety.joint_limit" and handle.events[-1]["flow"] == "agent"
    assert np.allclose(target.arm_qpos(), q0, atol=1e-4)
    goal = q0 + np.array([0.1, 0, 0, 0, 0, 0, 0])
    result = handle.call("move_joints", q=list(goal), speed_scale=0.5)
    assert result["completed"] and np.allclose(target.arm_qpos(), goal, atol=0.01)
    assert handle.state["arm_qpos"] == pytest.approx(list(target.arm_qpos()))
    handle.call("halt")  # stopping is always allowed
    assert len(beats) == 2  # one per successful call; refusals do not renew the lease
