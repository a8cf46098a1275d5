"""IK, collision checking, planning, retiming, Cartesian paths and grasps on the real scene."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from phyagentos.errors import IKError, PlanningError, TimingError
from phyagentos.motion import (
    DEFAULT_ACCELERATION_LIMITS,
    FRANKA_VELOCITY_LIMITS,
    PLANNERS,
    CollisionChecker,
    Trajectory,
    actuator_velocity_limits,
    cartesian_path,
    forward_kinematics,
    place_pose,
    plan_path,
    qp_solver_name,
    retime,
    solve_ik,
    top_down_grasp,
    top_down_grasp_candidates,
    top_down_rotation,
)
from phyagentos.targets import DEFAULT_SCENE, HOME_QPOS, build_scene

pytestmark = pytest.mark.sim

HOME = np.array(HOME_QPOS)


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return build_scene(DEFAULT_SCENE)


@pytest.fixture(scope="module")
def world_qpos(model) -> np.ndarray:
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, model.key("home").id)
    return d.qpos.copy()


@pytest.fixture()
def checker(model, world_qpos) -> CollisionChecker:
    c = CollisionChecker(model, margin_m=0.01)
    c.set_world_state(world_qpos)
    return c


def pose(p, yaw=0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = top_down_rotation(yaw)
    T[:3, 3] = p
    return T


@pytest.fixture(scope="module")
def wall_problem(model) -> tuple[np.ndarray, np.ndarray]:
    """Pregrasp above the cube and the same pose above the goal, the wall between."""
    q_a = solve_ik(model, q_seed=HOME, target=pose((0.5, -0.2, 0.12))).q
    q_b = solve_ik(model, q_seed=q_a, target=pose((0.5, 0.25, 0.12))).q
    return np.array(q_a), np.array(q_b)


# ----------------------------------------------------------------------------- IK


def test_qp_backend_is_daqp():
    assert qp_solver_name() == "daqp"


@pytest.mark.parametrize(
    "p,yaw", [((0.5, -0.2, 0.12), 0.0), ((0.45, 0.25, 0.05), 0.7), ((0.35, -0.3, 0.3), -1.2), ((0.6, 0.1, 0.2), 0.0)]
)
def test_ik_reaches_a_reachable_pose_within_a_millimetre(model, p, yaw):
    T = pose(p, yaw)
    sol = solve_ik(model, q_seed=HOME, target=T)
    assert sol.position_error_m <= 1e-3 and sol.orientation_error_rad <= 1e-2
    T_fk = forward_kinematics(model, sol.q)
    assert np.linalg.norm(T_fk[:3, 3] - T[:3, 3]) <= 1e-3
    lo, hi = model.jnt_range[:7, 0], model.jnt_range[:7, 1]
    assert np.all(sol.q >= lo - 1e-9) and np.all(sol.q <= hi + 1e-9)
    assert sol.q.shape == (7,) and sol.iterations < 50


def test_ik_raises_for_an_unreachable_pose_and_reports_residuals(model):
    with pytest.raises(IKError, match=r"position error \d+\.\d mm"):
        solve_ik(model, q_seed=HOME, target=pose((2.0, 0.0, 0.3)))


def test_ik_rejects_malformed_inputs(model):
    with pytest.raises(IKError):
        solve_ik(model, q_seed=np.zeros(6), target=pose((0.5, 0, 0.2)))
    with pytest.raises(IKError, match="unknown IK frame"):
        solve_ik(model, q_seed=HOME, target=pose((0.5, 0, 0.2)), frame="nope")


def test_ik_keeps_the_fingers_fixed(model, world_qpos):
    q_full = world_qpos.copy()
    q_full[7:9] = 0.013
    sol = solve_ik(model, q_seed=HOME, target=pose((0.5, -0.1, 0.2)), qpos_full=q_full)
    T_fk = forward_kinematics(model, sol.q, qpos_full=q_full)
    assert np.linalg.norm(T_fk[:3, 3] - [0.5, -0.1, 0.2]) <= 1e-3


def test_ik_keeps_the_models_of_few_contexts_alive(model):
    # A runner builds new targets run after run; the IK contexts it caches hold their
    # models (about 24 MiB each), so the cache, not the targets, would decide their lifetime.
    import gc
    import weakref


    gone = []
    for _ in range(12):
        m = build_scene(DEFAULT_SCENE)
        solve_ik(m, q_seed=HOME, target=pose((0.5, -0.2, 0.12)))
        gone.append(weakref.ref(m))
        del m
    gc.collect()
    assert sum(r() is not None for r in gone) <= 4


def test_forgetting_a_model_drops_its_ik_contexts_and_with_them_the_model():
    import gc
    import weakref

    from phyagentos.motion.ik import forget_model

    m = build_scene(DEFAULT_SCENE)
    solve_ik(m, q_seed=HOME, target=pose((0.5, -0.2, 0.12)))
    ref = weakref.ref(m)
    assert forget_model(m) == 1 and forget_model(m) == 0
    del m
    gc.collect()
    assert ref() is None


def test_the_ik_context_of_a_model_in_use_is_kept_while_others_come_and_go(model):
    from phyagentos.motion import ik

    solve_ik(model, q_seed=HOME, target=pose((0.5, -0.2, 0.12)))
    mine = next(c for c in ik._CACHE.values() if c.model is model)
    for _ in range(2 * ik._CACHE_MAX):
        solve_ik(build_scene(DEFAULT_SCENE), q_seed=HOME, target=pose((0.5, -0.2, 0.12)))
        solve_ik(model, q_seed=HOME, target=pose((0.45, 0.25, 0.05)))  # used between the others
    assert any(c is mine for c in ik._CACHE.values())


# ----------------------------------------------------------------------------- collision


def test_collision_checker_accepts_home(checker):
    assert checker.is_valid(HOME)
    assert checker.colliding_pairs(HOME) == ()


def test_collision_checker_flags_a_configuration_intersecting_the_wall(model, checker):
    q = solve_ik(model, q_seed=HOME, target=pose((0.5, 0.03, 0.12))).q  # gripper inside the wall
    assert not checker.is_valid(q)
    assert any("obstacle:wall" in pair for pair in checker.colliding_pairs(q))


def test_collision_checker_flags_a_configuration_intersecting_the_table(model):
    c = CollisionChecker(model, margin_m=0.0)
    q = HOME.copy()
    q[1] = 1.2  # lean far forward: the hand goes through the table
    assert not c.is_valid(q)
    assert any("table" in pair for pair in c.colliding_pairs(q))


def test_collision_checker_honours_joint_limits(checker):
    q = HOME.copy()
    q[3] = 0.3  # joint 4 upper limit is -0.4
    assert not checker.is_valid(q)
    assert ("joint_limit", "robot:panda0_joint4") in checker.colliding_pairs(q)


def test_attached_object_moves_with_the_gripper_and_may_touch_the_fingers(model, world_qpos):
    c = CollisionChecker(model, margin_m=0.0)
    q_world = world_qpos.copy()
    q_world[7:9] = 0.015  # finger pads closer together than the 4 cm cube is wide
    c.set_world_state(q_world)
    q_mid = solve_ik(model, q_seed=HOME, target=pose((0.5, -0.2, 0.15))).q
    assert c.is_valid(q_mid)
    # cube held between the pads: it overlaps the fingers, which is allowed
    c.attach("cube", np.eye(4))
    assert c.attached == "cube"
    assert c.is_valid(q_mid)
    # tcp above the wall: the gripper clears it, a cube hanging 5 cm lower does not
    q_over = solve_ik(model, q_seed=q_mid, target=pose((0.5, 0.03, 0.34))).q
    hanging = np.eye(4)
    hanging[2, 3] = 0.05  # along the tcp z axis, i.e. below the tcp
    c.attach("cube", hanging)
    assert not c.is_valid(q_over)
    assert ("cube", "obstacle:wall") in c.colliding_pairs(q_over)
    c.detach()
    assert c.attached is None
    assert c.is_valid(q_over)
    with pytest.raises(PlanningError, match="objects: 'cube'"):
        c.attach("sphere", np.eye(4))


def test_checkers_at_two_margins_sharing_one_model_copy_answer_as_checkers_with_their_own(model, world_qpos):
    # a copy is the whole model (a LIBERO world: ~250 MB of it, textures included): the
    # checkers at 0 and at the planning margin share one and still answer exactly alike
    own = {m: CollisionChecker(model, margin_m=m) for m in (0.01, 0.0)}
    first = CollisionChecker(model, margin_m=0.01)
    shared = {0.01: first, 0.0: CollisionChecker(model, margin_m=0.0, share_model_of=first)}
    assert shared[0.0].model is first.model and own[0.0].model is not first.model
    q_world = world_qpos.copy()
    q_world[7:9] = 0.015
    rng = np.random.default_rng(0)
    configs = [HOME, solve_ik(model, q_seed=HOME, target=pose((0.5, 0.03, 0.12))).q,
               solve_ik(model, q_seed=HOME, target=pose((0.5, 0.03, 0.34))).q]
    configs += [HOME + rng.normal(0.0, 0.4, 7) for _ in range(40)]
    hanging = np.eye(4)
    hanging[2, 3] = 0.05
    for attach in (None, hanging, None):
        for checkers in (own, shared):
            for c in checkers.values():
                c.set_world_state(q_world)
                c.detach() if attach is None else c.attach("cube", attach)
        for q in configs:
            for m in (0.01, 0.0, 0.0, 0.01):  # alternate between the sharing checkers
                assert shared[m].is_valid(q) == own[m].is_valid(q)
                assert shared[m].colliding_pairs(q) == own[m].colliding_pairs(q)
    assert len({own[m].is_valid(q) for m in own for q in configs}) == 2  # both answers occur
    with pytest.raises(PlanningError, match="another model"):
        CollisionChecker(build_scene(DEFAULT_SCENE), share_model_of=first)


def test_the_session_checkers_of_a_target_share_one_model_copy():
    from types import SimpleNamespace

    from phyagentos.primitives.motion import PLANNING_MARGIN_M, session_checker
    from phyagentos.targets import MuJoCoTarget

    with MuJoCoTarget("franka", seed=0) as t:
        ctx = SimpleNamespace(target=t)
        zero, planning = session_checker(ctx), session_checker(ctx, margin_m=PLANNING_MARGIN_M)
        assert zero.margin_m == 0.0 and planning.margin_m == PLANNING_MARGIN_M
        assert planning.model is zero.model and zero.model is not t.model
        assert session_checker(ctx) is zero


# ----------------------------------------------------------------------------- planning


def test_planner_finds_a_path_over_the_wall_whose_dense_states_are_all_valid(checker, wall_problem):
    q_a, q_b = wall_problem
    assert not checker.check_path(np.array([q_a, q_b]))  # straight line goes through the wall
    path = plan_path(checker, q_a, q_b, seed=0)
    assert path.shape[1] == 7 and len(path) >= 3
    np.testing.assert_allclose(path[0], q_a)
    np.testing.assert_allclose(path[-1], q_b)
    for a, b in zip(path[:-1], path[1:]):
        n = int(math.ceil(np.max(np.abs(b - a)) / 0.005))
        for k in range(n + 1):
            assert checker.is_valid(a + (b - a) * k / n)


def test_planner_is_reproducible_with_a_seed(checker, wall_problem):
    q_a, q_b = wall_problem
    np.testing.assert_array_equal(plan_path(checker, q_a, q_b, seed=7), plan_path(checker, q_a, q_b, seed=7))


def test_planner_rejects_unknown_planner_names_with_the_valid_list(checker, wall_problem):
    with pytest.raises(PlanningError) as exc:
        plan_path(checker, *wall_problem, planner="AStar")
    for name in PLANNERS:
        assert repr(name) in str(exc.value)


def test_planner_names_the_colliding_pair_of_an_invalid_goal(model, checker):
    q_bad = solve_ik(model, q_seed=HOME, target=pose((0.5, 0.03, 0.12))).q
    with pytest.raises(PlanningError, match="goal configuration is invalid: .*obstacle:wall"):
        plan_path(checker, HOME, q_bad)


@pytest.mark.parametrize("planner", ["PRM", "KPIECE1", "BITstar"])
def test_other_planners_solve_an_easy_problem(checker, model, planner):
    q = solve_ik(model, q_seed=HOME, target=pose((0.4, -0.25, 0.2))).q
    path = plan_path(checker, HOME, q, planner=planner, seed=1, timeout_s=5.0)
    assert checker.check_path(path, resolution_rad=0.01)


# ----------------------------------------------------------------------------- retiming


@pytest.mark.parametrize("seed", [0, 3])
def test_retime_respects_limits_and_the_timed_trajectory_stays_collision_free(
    checker, wall_problem, model, world_qpos, seed
):
    path = plan_path(checker, *wall_problem, seed=seed)
    vel = actuator_velocity_limits(model)
    acc = np.array(DEFAULT_ACCELERATION_LIMITS)
    contact = CollisionChecker(model, margin_m=0.0)  # the plan used a 1 cm margin
    contact.set_world_state(world_qpos)
    traj = retime(path, vel_limits=vel, acc_limits=acc, dt=0.002, checker=contact)
    assert isinstance(traj, Trajectory)
    assert np.all(np.abs(traj.qd) <= vel * (1 + 1e-6))
    assert np.all(np.abs(traj.qdd) <= acc * (1 + 1e-6))
    assert np.all(np.diff(traj.t) > 0) and np.all(np.diff(traj.t) <= 0.002 + 1e-12)
    np.testing.assert_allclose(traj.q[0], path[0])
    np.testing.assert_allclose(traj.q[-1], path[-1])
    np.testing.assert_allclose(traj.qd[[0, -1]], 0.0)
    assert traj.duration == pytest.approx(traj.t[-1])
    # velocities are consistent with positions
    np.testing.assert_allclose(np.gradient(traj.q, traj.t, axis=0)[5:-5], traj.qd[5:-5], atol=0.02)
    # every sample is collision free
    assert all(contact.is_valid(q) for q in traj.q)


def test_retime_defaults_are_the_franka_datasheet_velocities():
    traj = retime(np.array([HOME, HOME + 2.0 * np.array([1, 0, 0, 0, 0, 0, 0])]))
    assert np.max(np.abs(traj.qd[:, 0])) == pytest.approx(FRANKA_VELOCITY_LIMITS[0], rel=0.01)


def test_retime_of_a_single_point_is_a_trajectory_at_rest():
    traj = retime(HOME[None, :])
    assert len(traj) == 1 and traj.duration == 0.0


def test_retime_rejects_bad_limits():
    with pytest.raises(TimingError):
        retime(np.array([HOME, HOME + 0.1]), vel_limits=np.zeros(7))
    with pytest.raises(TimingError):
        retime(np.zeros((3, 7)), acc_limits=np.ones(6))


def test_trajectory_is_frozen():
    traj = retime(np.array([HOME, HOME + 0.1]))
    with pytest.raises(ValueError):
        traj.q[0, 0] = 1.0
    with pytest.raises(Exception):
        traj.t = np.zeros(1)  # type: ignore[misc]


# ----------------------------------------------------------------------------- Cartesian


def test_cartesian_path_moves_the_tcp_along_a_straight_line(model):
    q0 = solve_ik(model, q_seed=HOME, target=pose((0.5, -0.2, 0.12))).q
    goal = pose((0.5, -0.2, 0.02))
    path = cartesian_path(model, q_start=q0, T_goal=goal, step_m=0.01)
    assert len(path) == 11
    start = forward_kinematics(model, q0)[:3, 3]
    for q in path:
        p = forward_kinematics(model, q)[:3, 3]
        # distance from the segment start -> goal
        d = p - start
        u = (goal[:3, 3] - start) / np.linalg.norm(goal[:3, 3] - start)
        assert np.linalg.norm(d - (d @ u) * u) < 1.5e-3
    assert np.linalg.norm(forward_kinematics(model, path[-1])[:3, 3] - goal[:3, 3]) <= 1e-3
    assert np.max(np.abs(np.diff(path, axis=0))) < 0.1


def test_cartesian_path_raises_when_the_line_leaves_the_workspace(model):
    with pytest.raises(IKError, match="waypoint"):
        cartesian_path(model, q_start=HOME, T_goal=pose((1.5, 0.0, 0.3)))


# ----------------------------------------------------------------------------- grasps


def test_top_down_grasp_closes_across_the_shorter_side_with_the_nearest_yaw():
    T_obj = np.eye(4)
    T_obj[:3, 3] = [0.5, -0.2, 0.02]
    yaw = 0.3
    T_obj[:3, :3] = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    plan = top_down_grasp(T_obj, (0.03, 0.015, 0.02), approach_height_m=0.1, current_yaw_rad=0.0)
    G = plan.grasp
    np.testing.assert_allclose(G[:3, 2], [0, 0, -1], atol=1e-9)  # tcp z down
    closing = G[:3, 1]
    short_axis = T_obj[:3, 1]  # half extent 0.015 along the box y axis
    assert abs(abs(closing @ short_axis) - 1) < 1e-9
    assert abs(plan.yaw_rad) <= math.pi / 2 + 1e-9
    assert plan.width_m == pytest.approx(0.03)
    np.testing.assert_allclose(plan.pregrasp[:3, 3], G[:3, 3] + [0, 0, 0.1])
    # a cube has four candidate yaws, sorted by distance to the current yaw
    cands = top_down_grasp_candidates(np.eye(4), (0.02, 0.02, 0.02), current_yaw_rad=0.2)
    assert len(cands) == 4 and cands[0].yaw_rad == pytest.approx(0.0)


def test_top_down_grasp_keeps_the_fingertips_off_the_table():
    T_obj = np.eye(4)
    T_obj[2, 3] = 0.01  # a flat box, 2 cm tall
    G = top_down_grasp(T_obj, (0.02, 0.02, 0.01)).grasp
    assert G[2, 3] >= 0.015 + 0.004 - 1e-12


def test_a_flat_box_is_held_by_the_pads_of_a_hand_whose_fingers_reach_less_far_below_the_tcp():
    # robosuite's Panda (LiberoTarget.finger_geometry_m): the fingers end 9.5 mm below the tcp and
    # the pads span 4 mm below to 11 mm above it; a cream cheese box 1.8 cm tall on the table
    T_obj = np.eye(4)
    T_obj[2, 3] = 0.009
    panda = (0.0095, 0.004, 0.035)
    z_franka = top_down_grasp_candidates(T_obj, (0.043, 0.0215, 0.009))[0].grasp[2, 3]
    z_panda = top_down_grasp_candidates(T_obj, (0.043, 0.0215, 0.009), fingers_m=panda)[0].grasp[2, 3]
    assert z_franka == pytest.approx(0.015 + 0.004)
    assert z_panda == pytest.approx(0.0095 + 0.004)  # the fingertips 4 mm over the table
    def pads_on(z):  # how much of the Panda's pads (4 mm below to 11 mm above the tcp) lies along the box's side, m
        return min(0.018, z + 0.011) - max(0.0, z - panda[1])
    assert pads_on(z_franka) < 0.003 < 0.008 < pads_on(z_panda)
    # a box 6 cm tall is held at its centre by either hand; one 10 cm tall no deeper than the finger base
    T_obj[2, 3] = 0.03
    assert top_down_grasp_candidates(T_obj, (0.03, 0.03, 0.03), fingers_m=panda)[0].grasp[2, 3] == pytest.approx(0.03)
    assert top_down_grasp_candidates(T_obj, (0.03, 0.03, 0.03))[0].grasp[2, 3] == pytest.approx(0.03)
    T_obj[2, 3] = 0.05
    assert top_down_grasp_candidates(T_obj, (0.03, 0.03, 0.05), fingers_m=panda)[0].grasp[2, 3] == pytest.approx(0.065)


def test_place_pose_puts_the_held_object_over_the_region_just_above_the_table():
    T_tcp_obj = np.eye(4)
    T_tcp_obj[2, 3] = 0.002  # object 2 mm further along the tcp z (below the tcp)
    T = place_pose((0.5, 0.25), (0.02, 0.02, 0.02), T_tcp_object=T_tcp_obj, clearance_m=0.003)
    obj = T @ T_tcp_obj
    np.testing.assert_allclose(obj[:3, 3], [0.5, 0.25, 0.023], atol=1e-9)
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1])
