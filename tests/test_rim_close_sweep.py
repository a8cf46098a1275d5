"""A rim grasp whose fingers would meet something else on their way in is not taken (issue 28,
libero_spatial task 4: the bowl in the open top drawer, a rim point beside the drawer's wall).

Fully open, the outer finger of such a rim point stands beyond the drawer's wall, clear of it,
so the pre-grasp and the grasp pass the collision check; the close then stops the finger on
the wall while the inner one pushes the bowl: the hand squeezed the drawer and the bowl
together (fingers 8.3 and 13.5 mm open, on a 3 mm wall) and the bowl slipped out in the lift.
``reach_blocked(close_to_m=)`` checks the close too, at openings 5 mm apart, and
``ComputeGrasp`` asks it for every rim point. On the tabletop Franka model with a thin
static wall standing 2 cm outside a perceived bowl's rim; the finger openings LIBERO's Panda
reports are checked against its model.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_rim_grasp import _entity, _run_compute_grasp

from phyagentos.motion.grasp import hand_yaw
from phyagentos.motion.rim_grasp import DEFAULT_RIM_WALL_M, rim_grasp_candidates
from phyagentos.primitives.perception import CLOSE_SWEEP_STEP_M, _unusable
from phyagentos.targets import MuJoCoTarget
from phyagentos.targets.scene import DEFAULT_SCENE, ObstacleSpec, SceneSpec

HALF = (0.0562, 0.0562, 0.0252)  # libero_spatial's akita bowl as perceived: 11.24 cm across, 5.04 cm tall
BOWL_XY = (0.45, -0.25)
#: the wall's inner face stands this far outside the bowl's rim (m), 5 mm thick, 4 cm tall
GAP_M = 0.02


@pytest.fixture
def franka_beside_a_wall():
    wall = ObstacleSpec("drawer_side", center=(BOWL_XY[0] + HALF[0] + GAP_M + 0.0025, BOWL_XY[1], 0.02),
                        half_extents=(0.0025, 0.08, 0.02))
    scene = SceneSpec(objects=DEFAULT_SCENE.objects, regions=DEFAULT_SCENE.regions,
                      obstacles=(*DEFAULT_SCENE.obstacles, wall))
    t = MuJoCoTarget("sweep", scene, seed=0)
    t.set_gripper(opening_m=0.04)
    yield t
    t.close()


def _rim_points(target):
    T = np.eye(4)
    T[:3, 3] = (BOWL_XY[0], BOWL_XY[1], HALF[2])
    return rim_grasp_candidates(T, np.asarray(HALF), wall_m=DEFAULT_RIM_WALL_M, approach_height_m=0.10,
                                current_yaw_rad=hand_yaw(target.tcp_pose()), max_width_m=0.08)


def _toward_wall(plan) -> float:
    """How far (m) the plan's tcp stands from the bowl's centre towards the wall (+x)."""
    return float(plan.grasp[0, 3] - BOWL_XY[0])


def test_a_rim_point_whose_outer_finger_closes_onto_a_wall_is_blocked_at_the_close(franka_beside_a_wall):
    target = franka_beside_a_wall
    ctx = SimpleNamespace(target=target)
    plans = _rim_points(target)
    facing = max(plans, key=_toward_wall)
    # the open hand is clear of the wall there: the reach alone passes
    assert _unusable(ctx, "bowl_1", facing) is None
    blocked = _unusable(ctx, "bowl_1", facing, close_to_m=DEFAULT_RIM_WALL_M / 2)
    assert blocked is not None and blocked.stage == "close" and blocked.collides
    assert "drawer_side" in blocked
    # the rim point on the far side closes on the wall of the bowl alone
    away = min(plans, key=_toward_wall)
    assert _unusable(ctx, "bowl_1", away, close_to_m=DEFAULT_RIM_WALL_M / 2) is None


def test_a_close_from_where_the_fingers_are_is_not_swept_when_they_are_shut(franka_beside_a_wall):
    target = franka_beside_a_wall
    ctx = SimpleNamespace(target=target)
    facing = max(_rim_points(target), key=_toward_wall)
    target.set_gripper(opening_m=0.0)
    # the hand already shut: nothing left to sweep; the pre-grasp and grasp checks as before
    assert _unusable(ctx, "bowl_1", facing, close_to_m=DEFAULT_RIM_WALL_M / 2) is None
    assert CLOSE_SWEEP_STEP_M < 0.008  # thinner than a finger pad: no wall passes between two checks


def test_compute_grasp_takes_a_rim_point_whose_close_is_clear(franka_beside_a_wall):
    target = franka_beside_a_wall
    ctx = SimpleNamespace(target=target)
    plans = _rim_points(target)
    # rim points the open hand reaches clear, whose close meets the wall
    blocked = [p for p in plans if _unusable(ctx, "bowl_1", p) is None
               and _unusable(ctx, "bowl_1", p, close_to_m=DEFAULT_RIM_WALL_M / 2) is not None]
    assert blocked
    for k in range(len(plans)):
        board, [rec] = _run_compute_grasp(target, _entity("bowl_1", "akita_black_bowl", "cylinder", HALF, xy=BOWL_XY),
                                          candidate=k)
        G = board["grasp_pose"]
        assert rec["grasp_kind"] == "rim"
        assert not any(np.allclose(G, p.grasp, atol=1e-6) for p in blocked), f"candidate {k} took a blocked rim point"


@pytest.mark.sim
def test_libero_reports_each_finger_on_its_side_of_the_tcp():
    from phyagentos.targets.libero.target import FINGER_JOINT_NAMES, LiberoScene, LiberoTarget

    with LiberoTarget("fingers", LiberoScene(suite="libero_spatial", task=4, init=0), seed=0) as t:
        m, d = t.model, t.data
        for opening in (0.03, 0.012):
            t.set_gripper(opening_m=opening)
            p = t.proprioception()
            T = p.tcp_pose
            along_y = [float(T[:3, 1] @ (d.xpos[m.joint(n).bodyid[0]] - T[:3, 3])) for n in FINGER_JOINT_NAMES]
            plus, minus = p.finger_offsets_m
            # the first finger stands on the tcp's +y side, the second on its -y side, each as far out as reported
            assert along_y[0] > 0 > along_y[1]
            assert plus == pytest.approx(along_y[0], abs=1e-4) and minus == pytest.approx(-along_y[1], abs=1e-4)
            assert 0.5 * (plus + minus) == pytest.approx(p.gripper_opening_m, abs=1e-9)
