"""A second embodiment: the unchanged pick-and-place graph runs on the 5-joint SO-101."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir
from phyagentos.targets import SceneSpec
from phyagentos.targets.so101 import ARM_JOINT_NAMES, SO101Target

pytestmark = pytest.mark.sim


def test_so101_target_builds_the_tabletop_scene_with_a_tool_frame_like_the_frankas():
    graph = yaml.safe_load((goal_graphs_dir() / "pick_and_place_compact.yaml").read_text())
    with SO101Target("so101", SceneSpec.from_dict(graph["scene"])) as arm:
        assert arm.arm_joint_names == ARM_JOINT_NAMES and arm.arm_qpos().shape == (5,)
        # home: tool pointing straight down (tcp z = world -z)
        assert arm.tcp_pose()[2, 2] == pytest.approx(-1.0, abs=0.01)
        opened = arm.set_gripper(opening_m=0.04)
        closed = arm.set_gripper(opening_m=0.0)
        assert opened.opening_m > 0.03 and closed.opening_m < 0.002 and not closed.stalled


def test_the_same_pick_and_place_graph_runs_on_the_so101_by_changing_only_the_target(tmp_path):
    graph = goal_graphs_dir() / "pick_and_place_compact.yaml"
    report = run_goal_graph(graph, tmp_path / "ws", seed=0, target="so101_tabletop")
    assert report.succeeded, report.to_dict()
    assert {s.target for s in report.sessions} == {"so101_tabletop"}
    ws = Workspace.open(tmp_path / "ws")
    place = ws.load_session(report.sessions[-1].session_id)
    assert place.adapter_plan["target_adapter"] == "mujoco_so101"
    # physics, not the verifier: the cube rests inside the goal footprint in the saved world
    scene = SceneSpec.from_dict(yaml.safe_load(graph.read_text())["scene"])
    with SO101Target("check", scene) as world:
        world.load_state(next((tmp_path / "ws" / "targets").rglob("state.npz")))
        cube = world.object_pose("cube")[:3, 3]
        goal = scene.region("goal")
        assert np.all(np.abs(cube[:2] - np.array(goal.center)) <= np.array(goal.half_extents))
        assert cube[2] == pytest.approx(0.015, abs=0.005) and world.held_objects() == ()


def test_five_joints_cannot_point_straight_down_at_the_pregrasp_and_the_declared_tolerance_adapts_the_ik():
    from phyagentos.errors import IKError
    from phyagentos.motion.grasp import top_down_grasp
    from phyagentos.motion.ik import solve_ik
    from phyagentos.primitives.motion import ik_options

    graph = yaml.safe_load((goal_graphs_dir() / "pick_and_place_compact.yaml").read_text())
    with SO101Target("so101", SceneSpec.from_dict(graph["scene"])) as arm:
        plan = top_down_grasp(arm.object_pose("cube"), (0.015, 0.015, 0.015), approach_height_m=0.10)
        with pytest.raises(IKError):
            solve_ik(arm.model, q_seed=arm.arm_qpos(), target=plan.pregrasp, arm_joint_names=ARM_JOINT_NAMES)
        opts = ik_options(arm)  # what the primitives pass: the target's declared capability
        assert opts["position_priority"] and opts["orientation_tol_rad"] == arm.ik_orientation_tol_rad
        sol = solve_ik(arm.model, q_seed=arm.arm_qpos(), target=plan.pregrasp, **opts)
        assert sol.position_error_m <= 1e-3 and 0.01 < sol.orientation_error_rad <= arm.ik_orientation_tol_rad
