"""The SO-101's own links at a start configuration: the planner's validity check must not
refuse ordinary poses of the arm because of its own adjacent links.

Tracker issue 35: a step failed ``planning_failed`` with "start configuration is invalid:
moving_jaw_so101_v1 <-> wrist". The jaw and the wrist sit on either side of the wrist-roll
joint (grandparent and grandchild, which MuJoCo does not filter); they never touch, but
the jaw's hull passes 8-9 mm from the wrist's, inside the planner's 1 cm margin.
"""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.motion.collision import CollisionChecker
from phyagentos.motion.planner import plan_path
from phyagentos.primitives.motion import PLANNING_MARGIN_M
from phyagentos.targets.so101.target import (
    ALLOWED_COLLISION_PAIRS,
    ARM_JOINT_NAMES,
    GRIPPER_JOINT,
    HOME_QPOS,
    SO101_DEFAULT_SCENE,
    SO101Target,
)

JAW = "moving_jaw_so101_v1"


@pytest.fixture(scope="module")
def so101():
    t = SO101Target("so101", SO101_DEFAULT_SCENE, seed=0)
    yield t
    t.close()


def _checker(t: SO101Target, margin_m: float, *, allowed=None) -> CollisionChecker:
    return CollisionChecker(t.model, arm_joint_names=ARM_JOINT_NAMES, margin_m=margin_m, tcp_site="tcp",
                            allowed_pairs=t.allowed_collision_pairs if allowed is None else allowed,
                            gripper_bodies=t.gripper_body_names)


def _with_jaw(t: SO101Target, angle: float) -> np.ndarray:
    m = t.model
    q = np.array(t.data.qpos, dtype=float)
    q[m.jnt_qposadr[m.joint(GRIPPER_JOINT).id]] = angle
    return q


def _jaw_range(t: SO101Target) -> tuple[float, float]:
    lo, hi = t.model.jnt_range[t.model.joint(GRIPPER_JOINT).id]
    return float(lo), float(hi)


def test_the_target_declares_the_jaw_and_the_wrist_adjacent(so101):
    assert ("wrist", JAW) in so101.allowed_collision_pairs
    assert so101.allowed_collision_pairs == ALLOWED_COLLISION_PAIRS


def test_home_with_the_jaw_closed_open_or_at_the_grasp_angle_is_a_valid_start(so101):
    checker = _checker(so101, PLANNING_MARGIN_M)
    lo, hi = _jaw_range(so101)
    home = np.array(HOME_QPOS)
    for angle in (lo, 0.0, 0.46, hi):  # closed, zero, pads parallel, fully open
        checker.set_world_state(_with_jaw(so101, angle))
        assert checker.is_valid(home), (angle, checker.colliding_pairs(home))
    # and a plan starts from there (the rolled wrist of a grasp as its goal)
    goal = home.copy()
    goal[4] = 1.0
    checker.set_world_state(_with_jaw(so101, hi))
    path = plan_path(checker, home, goal, timeout_s=2.0, seed=0)
    assert np.allclose(path[0], home) and np.allclose(path[-1], goal)


@pytest.mark.parametrize("roll", [0.3, 1.0, 1.8])
def test_a_rolled_wrist_is_a_valid_start_whatever_the_jaw(so101, roll):
    """The rolls where the margin flagged the jaw against the wrist (issue 35)."""
    checker = _checker(so101, PLANNING_MARGIN_M)
    q = np.array(HOME_QPOS)
    q[4] = roll
    lo, hi = _jaw_range(so101)
    for angle in np.linspace(lo, hi, 5):
        checker.set_world_state(_with_jaw(so101, float(angle)))
        assert checker.is_valid(q), (roll, angle, checker.colliding_pairs(q))


def test_the_jaw_never_touches_the_wrist_so_excluding_the_pair_hides_no_contact(so101):
    """Why the exclusion is safe: at margin 0, over the wrist-roll x jaw range, the pair
    is never in contact; only the planning margin flagged it (the cause of issue 35)."""
    exact = _checker(so101, 0.0, allowed=())
    margin = _checker(so101, PLANNING_MARGIN_M, allowed=())
    rlo, rhi = so101.model.jnt_range[so101.model.joint("wrist_roll").id]
    lo, hi = _jaw_range(so101)
    flagged = 0
    for roll in np.linspace(rlo, rhi, 13):
        q = np.array(HOME_QPOS)
        q[4] = roll
        for angle in np.linspace(lo, hi, 7):
            world = _with_jaw(so101, float(angle))
            exact.set_world_state(world)
            assert ("moving_jaw_so101_v1", "wrist") not in exact.colliding_pairs(q), (roll, angle)
            margin.set_world_state(world)
            flagged += ("moving_jaw_so101_v1", "wrist") in margin.colliding_pairs(q)
    assert flagged > 0  # without the declared pair, the margin alone refuses these starts


def test_the_so101_declares_the_width_its_fixed_jaw_allows_and_grasp_planning_refuses_wider():
    from phyagentos.errors import IKError
    from phyagentos.motion.grasp import top_down_grasp_candidates
    from phyagentos.targets.so101.target import MAX_GRASP_WIDTH_M

    assert SO101Target.max_grasp_width_m == MAX_GRASP_WIDTH_M == 0.05
    T = np.eye(4)
    T[:3, 3] = (0.45, -0.1, 0.02)
    assert top_down_grasp_candidates(T, (0.02, 0.02, 0.02), max_width_m=MAX_GRASP_WIDTH_M)  # 4 cm: taken
    with pytest.raises(IKError, match="6.0 cm wide.*takes 4.6 cm at most"):
        top_down_grasp_candidates(T, (0.03, 0.03, 0.03), max_width_m=MAX_GRASP_WIDTH_M)
    assert top_down_grasp_candidates(T, (0.035, 0.035, 0.035))  # the Franka's default 8 cm is unchanged


def test_the_so101_perception_mask_keeps_the_top_of_a_4_to_7_cm_cube(so101):
    """The Franka Hand's gripper box cut the top off cubes taller than 3 cm at the SO-101's home."""
    cfg = so101.perception_config()
    assert cfg.robot_mask.gripper_half_y_m == 0.065 and tuple(cfg.robot_mask.gripper_z_m) == (-0.11, 0.04)
    (p0, p1, r), = so101.hand_capsules()
    assert r == 0.025 and np.linalg.norm(np.subtract(p1, p0)) > 0.08
