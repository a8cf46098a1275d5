"""MuJoCoTarget: execution, gripper, snapshot, persistence and full pick-and-place."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from phyagentos.errors import TargetError
from phyagentos.motion import (
    DEFAULT_ACCELERATION_LIMITS,
    CollisionChecker,
    plan_path,
    retime,
    solve_ik,
    top_down_rotation,
)
from phyagentos.targets import (
    DEFAULT_SCENE,
    BaseRolloutTarget,
    ExecutionResult,
    MuJoCoTarget,
    ObjectSpec,
    SceneSpec,
)

pytestmark = pytest.mark.sim

_BENCH = Path(__file__).resolve().parents[1] / "bench" / "bare_pick_and_place.py"


def _load_bench():
    spec = importlib.util.spec_from_file_location("bare_pick_and_place", _BENCH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # registered first, as importlib's recipe does (its dataclasses need it)
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


@pytest.fixture(scope="module")
def bench():
    return _load_bench()


@pytest.fixture()
def target():
    with MuJoCoTarget("sim", DEFAULT_SCENE, seed=0) as t:
        yield t


def _pose(p, yaw=0.0):
    T = np.eye(4)
    T[:3, :3] = top_down_rotation(yaw)
    T[:3, 3] = p
    return T


def _wall_trajectory(t: MuJoCoTarget, seed: int = 0):
    """Home -> pregrasp above the goal, over the wall, retimed for the sim actuators."""
    checker = CollisionChecker(t.model, margin_m=0.01)
    checker.set_world_state(t.data.qpos)
    q_goal = solve_ik(t.model, q_seed=t.home_qpos, target=_pose((0.5, 0.25, 0.12))).q
    path = plan_path(checker, t.arm_qpos(), q_goal, seed=seed)
    return retime(path, vel_limits=t.velocity_limits(), acc_limits=DEFAULT_ACCELERATION_LIMITS, dt=t.timestep), q_goal


# ----------------------------------------------------------------------------- basics


def test_target_is_a_simulation_rollout_target_with_the_listed_tools(target):
    assert isinstance(target, BaseRolloutTarget)
    assert target.kind == "simulation" and target.name == "sim"
    assert target.tools() == ("observe", "move_joints", "set_gripper", "hold", "snapshot")
    obs = target.observe()
    assert obs["arm_qpos"].shape == (7,) and obs["tcp_pose"].shape == (4, 4)
    np.testing.assert_allclose(obs["arm_qpos"], target.home_qpos, atol=1e-3)
    assert target.gripper_opening() == pytest.approx(0.04, abs=1e-3)
    assert target.sim_time == 0.0


def test_unknown_object_and_tool_names_list_the_valid_ones(target):
    with pytest.raises(TargetError, match="objects: 'cube'"):
        target.object_pose("sphere")
    with pytest.raises(TargetError, match="valid tools: 'hold', 'move_joints', 'observe', 'set_gripper', 'snapshot'"):
        target.invoke_tool("teleport")
    with pytest.raises(TargetError, match="bad arguments for tool 'hold'"):
        target.invoke_tool("hold", seconds=1.0)


def test_tools_run_through_invoke_tool(target):
    r = target.invoke_tool("hold", duration_s=0.1)
    assert r["steps"] == 50 and target.sim_time == pytest.approx(0.1)
    q = target.home_qpos + np.array([0.2, 0, 0, 0, 0, 0, 0.3])
    res = target.invoke_tool("move_joints", q=q.tolist())
    assert res["completed"] and res["max_tracking_error_rad"] < 0.05
    np.testing.assert_allclose(target.arm_qpos(), q, atol=0.006)
    g = target.invoke_tool("set_gripper", opening_m=0.02)
    assert g["opening_m"] == pytest.approx(0.02, abs=2e-3) and not g["stalled"]
    assert set(g) == {"opening_m", "stalled"}  # the hand's encoders only: nothing held is named
    assert target.invoke_tool("observe")["target"] == "sim"
    assert "relations" in target.invoke_tool("snapshot")


def test_reset_seeds_the_generator_and_restores_the_start(target):
    target.step_for(0.2, arm_ctrl=target.home_qpos + 0.1)
    target.reset(seed=5)
    a = target.rng.random()
    np.testing.assert_allclose(target.arm_qpos(), target.home_qpos, atol=1e-3)
    assert target.sim_time == 0.0
    target.reset(seed=5)
    assert target.rng.random() == a


def test_closed_target_refuses_work():
    t = MuJoCoTarget("sim", DEFAULT_SCENE)
    with t:
        pass
    assert t.closed
    with pytest.raises(TargetError, match="closed"):
        t.step()


def test_render_returns_an_image_of_the_scene_headless(target):
    # set-up installs OSMesa; phyagentos selects it when there is no display
    img = target.render(width=64, height=48)
    assert img.shape == (48, 64, 3) and img.dtype == np.uint8
    assert img.std() > 5.0  # not a blank frame: table, robot and cube are drawn


def test_an_image_larger_than_the_framebuffer_is_refused_with_its_size_not_blamed_on_opengl(target):
    vis = target.model.vis.global_
    with pytest.raises(TargetError, match=rf"exceeds the model's offscreen framebuffer \({vis.offwidth}x{vis.offheight}"):
        target.render(width=int(vis.offwidth) + 1, height=48)
    assert target.render(width=64, height=48).shape == (48, 64, 3)  # the target still renders


# ----------------------------------------------------------------------------- execution


def test_execute_trajectory_tracks_within_tolerance_thanks_to_feedforward():
    with MuJoCoTarget("sim", DEFAULT_SCENE) as t:
        traj, q_goal = _wall_trajectory(t)
        res = t.execute_trajectory(traj, tracking_tol_rad=0.05)
        assert isinstance(res, ExecutionResult)
        assert res.completed and res.contacts == ()
        assert res.max_tracking_error_rad < 0.02
        assert res.sim_time_s >= traj.duration and res.steps >= len(traj) - 1
        np.testing.assert_allclose(t.arm_qpos(), q_goal, atol=0.006)
        with_ff = res.max_tracking_error_rad
    with MuJoCoTarget("sim", DEFAULT_SCENE) as t:
        traj, _ = _wall_trajectory(t)
        res = t.execute_trajectory(traj, tracking_tol_rad=1.0, feedforward=False)
        without_ff = res.max_tracking_error_rad
    # the position actuators lag by (b/kp) * qd without feed-forward (~0.06 rad here)
    assert without_ff > 3.0 * with_ff
    assert without_ff > 0.04


def test_tracking_a_trajectory_slice_by_slice_matches_one_shot_execution():
    with MuJoCoTarget("sim", DEFAULT_SCENE) as a:
        traj, q_goal = _wall_trajectory(a)
        a.execute_trajectory(traj, settle_s=0.0)
        q_one_shot = a.arm_qpos()
    with MuJoCoTarget("sim", DEFAULT_SCENE) as b:
        traj, _ = _wall_trajectory(b)
        t, errs = 0.0, []
        while t < traj.duration - 1e-9:
            t_end = min(t + 0.05, traj.duration)
            r = b.track(traj, t_start=t, t_end=t_end, tracking_tol_rad=0.05)
            assert r.completed and r.contacts == ()
            errs.append(r.max_tracking_error_rad)
            t = t_end
        assert max(errs) < 0.02
        np.testing.assert_allclose(b.arm_qpos(), q_one_shot, atol=1e-3)
        assert b.settle(traj.q[-1]) < 250
        np.testing.assert_allclose(b.arm_qpos(), q_goal, atol=0.006)
        b.halt()
        q = b.arm_qpos()
        b.hold(duration_s=0.2)
        np.testing.assert_allclose(b.arm_qpos(), q, atol=2e-3)


def test_execute_trajectory_stops_early_when_tracking_error_exceeds_tolerance():
    with MuJoCoTarget("sim", DEFAULT_SCENE) as t:
        traj, _ = _wall_trajectory(t)
        res = t.execute_trajectory(traj, tracking_tol_rad=0.01, feedforward=False)
        assert not res.completed and "tracking error" in res.reason
        assert res.steps < len(traj)


def test_execute_trajectory_refuses_a_trajectory_that_starts_elsewhere(target):
    traj = retime(np.array([target.home_qpos + 0.3, target.home_qpos + 0.4]))
    with pytest.raises(TargetError, match="starts"):
        target.execute_trajectory(traj)


# ----------------------------------------------------------------------------- persistence


def test_save_and_load_state_restore_the_simulation_exactly(tmp_path):
    path = tmp_path / "targets" / "sim" / "state.npz"
    with MuJoCoTarget("sim", DEFAULT_SCENE) as a:
        a.step_for(0.3, arm_ctrl=a.home_qpos + 0.05)
        a.save_state(path)
        saved_time = a.sim_time
        ctrl = a.data.ctrl.copy()
        for _ in range(200):
            a.step()
        qpos_a, qvel_a = a.data.qpos.copy(), a.data.qvel.copy()
    # a fresh target (as in a later session) continues bit for bit
    with MuJoCoTarget("sim", DEFAULT_SCENE) as b:
        b.load_state(path)
        assert b.sim_time == saved_time
        np.testing.assert_array_equal(b.data.ctrl, ctrl)
        for _ in range(200):
            b.step()
        np.testing.assert_array_equal(b.data.qpos, qpos_a)
        np.testing.assert_array_equal(b.data.qvel, qvel_a)
    other = SceneSpec(objects=(ObjectSpec("cube", position=(0.4, -0.3)),))
    with MuJoCoTarget("other", other) as c:
        with pytest.raises(TargetError, match="different scene"):
            c.load_state(path)
        with pytest.raises(TargetError, match="does not exist"):
            c.load_state(tmp_path / "missing.npz")


def _identity(path):
    st = path.stat()
    return st.st_ino, st.st_mtime_ns, st.st_size


def test_saving_an_unchanged_world_again_leaves_its_state_file_alone(tmp_path):
    path = tmp_path / "state.npz"
    with MuJoCoTarget("sim", DEFAULT_SCENE) as a:
        a.step_for(0.1, arm_ctrl=a.home_qpos + 0.05)
        a.save_state(path)
        first = _identity(path)
        a.save_state(path)  # the checkpoint before a session's first tick, right after the last one
        assert _identity(path) == first
        a.step()
        a.save_state(path)  # the world moved: written again
        assert _identity(path) != first
        moved = _identity(path)
        a.load_state(path)  # a file it wrote itself and a world unchanged since
        a.save_state(path)
        assert _identity(path) == moved


def test_a_state_file_replaced_by_another_writer_is_read_and_rewritten(tmp_path):
    path = tmp_path / "state.npz"
    with MuJoCoTarget("sim", DEFAULT_SCENE) as a, MuJoCoTarget("sim", DEFAULT_SCENE) as b:
        a.save_state(path)
        b.step_for(0.2, arm_ctrl=b.home_qpos + 0.1)
        b.save_state(path)  # e.g. a recovering runner's checkpoint
        a.load_state(path)
        assert a.world_digest() == b.world_digest() and a.sim_time == b.sim_time
        np.testing.assert_array_equal(a.data.qpos, b.data.qpos)
        replaced = _identity(path)
        a.step()
        a.save_state(path)
        assert _identity(path) != replaced


def test_other_bytes_under_the_same_inode_mtime_and_size_are_still_read(tmp_path):
    # What a key of file metadata would miss: inode numbers are reused and mtimes are
    # coarse; the target compares the file's bytes.
    path, other = tmp_path / "state.npz", tmp_path / "other.npz"
    with MuJoCoTarget("sim", DEFAULT_SCENE) as a, MuJoCoTarget("sim", DEFAULT_SCENE) as b:
        a.save_state(path)
        b.step_for(0.2, arm_ctrl=b.home_qpos + 0.1)
        b.save_state(other)
        assert other.stat().st_size == path.stat().st_size  # npz files of one model and scene
        before = path.stat()
        with open(path, "r+b") as fh:  # same inode, then the old mtime back
            fh.write(other.read_bytes())
        os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
        assert _identity(path) == (before.st_ino, before.st_mtime_ns, before.st_size)
        a.load_state(path)
        assert a.world_digest() == b.world_digest() and a.sim_time == b.sim_time


def test_loading_the_state_a_target_already_holds_ends_where_a_restore_does(tmp_path):
    path = tmp_path / "state.npz"
    with MuJoCoTarget("sim", DEFAULT_SCENE) as a, MuJoCoTarget("sim", DEFAULT_SCENE) as b:
        for _ in range(37):  # after mj_step the derived quantities lag the integrated state
            a.step(a.home_qpos + 0.05)
        a.save_state(path)
        a.load_state(path)  # not read: the live world is the file's
        b.load_state(path)  # read and restored
        for name in ("qpos", "qvel", "act", "ctrl", "xpos", "xquat", "site_xpos", "sensordata", "qacc"):
            np.testing.assert_array_equal(getattr(a.data, name), getattr(b.data, name), err_msg=name)
        assert a.world_digest() == b.world_digest()
        for _ in range(50):
            a.step()
            b.step()
        np.testing.assert_array_equal(a.data.qpos, b.data.qpos)


# ----------------------------------------------------------------------------- pick and place


PICK_CASES = [
    (0, (0.5, -0.2), 0.0),
    (1, (0.45, -0.27), 0.35),
    (2, (0.58, -0.18), -0.6),
    (3, (0.38, -0.22), 1.1),
    (4, (0.62, -0.3), 0.0),
]


@pytest.mark.parametrize("seed,xy,yaw", PICK_CASES)
def test_pick_and_place_puts_the_cube_inside_the_goal_region(bench, seed, xy, yaw):
    scene = SceneSpec(
        objects=(ObjectSpec("cube", position=xy, yaw=yaw),),
        regions=DEFAULT_SCENE.regions,
        obstacles=DEFAULT_SCENE.obstacles,
    )
    result = bench.run_bare_pick_and_place(seed=seed, scene=scene)
    p = np.array(result["cube_final_position"])
    region = DEFAULT_SCENE.region("goal")
    assert region.contains_xy(p[:2], margin_m=0.02)
    assert p[2] == pytest.approx(0.02, abs=2e-3)
    assert result["unexpected_contacts"] == []
    assert result["max_tracking_error_rad"] < 0.05


def test_bare_script_reads_its_speeds_from_the_shipped_trees(bench):
    import inspect  # noqa: PLC0415

    from phyagentos.primitives.execution import CartesianMove  # noqa: PLC0415

    default = inspect.signature(CartesianMove.__init__).parameters["velocity_scale"].default
    assert bench.CARTESIAN_DEFAULT_VELOCITY_SCALE == default
    m = bench.SkillMotions.from_trees()
    pick = yaml.safe_load((bench.TREES / "pick.yaml").read_text())["params"]
    place = yaml.safe_load((bench.TREES / "place.yaml").read_text())["params"]
    assert (m.approach_velocity_scale, m.lift_velocity_scale, m.lift_m) == (
        pick["approach_velocity_scale"]["default"], pick["lift_velocity_scale"]["default"], pick["lift_m"]["default"])
    assert (m.lower_velocity_scale, m.place_approach_height_m) == (
        place["lower_velocity_scale"]["default"], place["approach_height_m"]["default"])
    assert m.retreat_velocity_scale == default and m.retreat_offset_m == pytest.approx(0.10)


def test_snapshot_reports_holding_while_grasped_and_inside_after_placing(bench):
    seen: dict[str, dict] = {}

    def observer(stage, t):
        seen[stage] = t.snapshot()

    bench.run_bare_pick_and_place(seed=0, observer=observer)
    holding = {"subject": "gripper", "relation": "holding", "object": "cube"}
    inside = {"subject": "cube", "relation": "inside", "object": "goal"}
    assert holding in seen["grasped"]["relations"]
    assert holding in seen["transferred"]["relations"]
    assert {"subject": "cube", "relation": "on", "object": "table"} not in seen["transferred"]["relations"]
    assert holding not in seen["retreated"]["relations"]
    assert inside in seen["retreated"]["relations"]
    assert {"subject": "cube", "relation": "on", "object": "table"} in seen["retreated"]["relations"]
    cube = next(e for e in seen["retreated"]["entities"] if e["name"] == "cube")
    assert cube["kind"] == "object" and len(cube["position"]) == 3 and len(cube["quat_wxyz"]) == 4
    assert cube["size"] == [0.02, 0.02, 0.02]  # half extents, MuJoCo's box convention
    assert yaml.safe_load(yaml.safe_dump(seen["retreated"])) == seen["retreated"]
    kinds = {e["kind"] for e in seen["retreated"]["entities"]}
    assert {"robot", "gripper", "object", "region", "obstacle"} <= kinds


def test_set_gripper_stalls_on_the_cube_and_names_nothing(target):
    q = solve_ik(target.model, q_seed=target.home_qpos, target=_pose((0.5, -0.2, 0.12))).q
    target.invoke_tool("move_joints", q=q)
    q2 = solve_ik(target.model, q_seed=q, target=_pose((0.5, -0.2, 0.02))).q
    target.invoke_tool("move_joints", q=q2)
    g = target.set_gripper(opening_m=0.0)
    assert g.stalled and g.to_dict() == {"opening_m": g.opening_m, "stalled": True}
    assert g.opening_m == pytest.approx(0.021, abs=2e-3)
    assert target.held_objects() == ("cube",)
    with pytest.raises(TargetError, match="opening_m"):
        target.set_gripper(opening_m=0.05)


def test_a_motion_into_the_cube_reports_the_robots_parts_that_met_it_never_the_cube(target):
    """The unexpected contacts of an execution name where on the robot they are (its own link
    names), not what it met: a real arm's collision sensing cannot name the thing it hit."""
    q = solve_ik(target.model, q_seed=target.home_qpos, target=_pose((0.5, -0.2, 0.12))).q
    target.invoke_tool("move_joints", q=q)
    target.set_gripper(opening_m=0.0)  # closed: the fingertips come down on the cube's top
    q2 = solve_ik(target.model, q_seed=q, target=_pose((0.5, -0.2, 0.0))).q
    traj = retime(np.array([q, q2]), vel_limits=np.full(7, 0.5), acc_limits=np.array(DEFAULT_ACCELERATION_LIMITS),
                  dt=target.timestep)
    res = target.execute_trajectory(traj, tracking_tol_rad=1.0)
    robot = {target.model.body(b).name for b in range(target.model.nbody)} - {"world", "cube"}
    assert res.contacts and set(res.contacts) <= robot
    assert all(isinstance(c, str) and "cube" not in c for c in res.contacts)
    assert res.to_dict()["contacts"] == list(res.contacts)
