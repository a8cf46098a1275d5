"""A hand pre-shaped for a rim it cannot reach fully open, and a lift that rises what the arm
reaches (issue 28, libero_spatial task 4's bowl in the open top drawer).

The drawer's walls stand as high as the bowl's rim, within the 4 cm a fully open finger
reaches past the wall: every rim grasp collided there, fully open. ``compute_grasp`` then
tries the same rim points with the fingers 2 cm open each (the collision model's fingers set
that far, :meth:`~phyagentos.motion.collision.CollisionChecker.set_gripper_opening`) and the
pick's ``PreshapeHand`` opens the hand that far before it goes down. The bowl stands near the
edge of the Panda's workspace, where a 15 cm lift leaves the arm's reach: the lift ends as
high as it reaches when that is at least ``min_lift_m``. On the tabletop Franka model, with
its real fingers, IK and collision model.
"""

from __future__ import annotations

from types import SimpleNamespace

import mujoco
import numpy as np
import py_trees
import pytest
from test_rim_grasp import _run_compute_grasp  # the same ComputeGrasp harness on a Franka

from phyagentos.errors import IKError, PlanningError
from phyagentos.motion.collision import CollisionChecker
from phyagentos.motion.rim_grasp import DEFAULT_RIM_WALL_M, RIM_PRESHAPE_CLEARANCE_M
from phyagentos.primitives import SkillContext
from phyagentos.primitives.execution import REACH_STEP_M, CartesianMove, Gripper
from phyagentos.primitives.motion import session_checker
from phyagentos.targets import MuJoCoTarget
from phyagentos.targets.scene import SceneSpec

HALF = (0.0562, 0.0562, 0.0252)  # libero_spatial's akita bowl as perceived: 11.24 cm across, 5.04 cm tall


@pytest.fixture
def franka():
    t = MuJoCoTarget("preshape", SceneSpec.default(), seed=0)
    yield t
    t.close()


def _finger_gap(checker: CollisionChecker) -> float:
    """Distance (m) between the two finger bodies of the checked world."""
    m, d = checker.model, checker.data
    mujoco.mj_kinematics(m, d)
    fingers = [b for b in sorted(checker.gripper_bodies) if "finger" in m.body(b).name]
    assert len(fingers) == 2, [m.body(b).name for b in checker.gripper_bodies]
    return float(np.linalg.norm(d.xpos[fingers[0]] - d.xpos[fingers[1]]))


def test_the_collision_models_fingers_stand_as_far_open_as_asked(franka):
    checker = session_checker(SimpleNamespace(target=franka))
    franka.set_gripper(opening_m=0.04)
    checker.set_world_state(franka.data.qpos)
    wide = _finger_gap(checker)
    assert checker.set_gripper_opening(0.02)
    # each finger 2 cm nearer the middle: the pads 4 cm nearer each other
    assert wide - _finger_gap(checker) == pytest.approx(0.04, abs=1e-6)
    assert checker.set_gripper_opening(0.0)
    assert wide - _finger_gap(checker) == pytest.approx(0.08, abs=1e-6)
    # the world state gives the fingers back as the simulation has them
    checker.set_world_state(franka.data.qpos)
    assert _finger_gap(checker) == pytest.approx(wide, abs=1e-6)
    with pytest.raises(PlanningError, match="opening_m must be a finite number >= 0 m"):
        checker.set_gripper_opening(-0.01)


def _bowl(xy=(0.45, -0.25)):
    return {"name": "bowl_1", "kind": "object", "position": [xy[0], xy[1], HALF[2]], "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "size": list(HALF), "attributes": {"shape": "cylinder", "class": "akita_black_bowl", "confidence": 0.9}}


def test_a_rim_the_open_fingers_cannot_reach_is_taken_with_the_hand_preshaped(franka, monkeypatch):
    """Fully open, every rim point's fingers meet the drawer's walls (a stand-in for them: the
    fully open check refuses every grasp); pre-shaped, the real check of the model passes."""
    import phyagentos.primitives.perception as perception

    real = perception._unusable
    asked = []

    def unusable(ctx, obj, plan, *, opening_m=None, close_to_m=None):
        asked.append(opening_m)
        if opening_m is None:
            return perception.Blocked("grasp collides: gripper0_rightfinger-wooden_cabinet_1_cabinet_top",
                                      stage="grasp", collides=True)
        return real(ctx, obj, plan, opening_m=opening_m, close_to_m=close_to_m)

    monkeypatch.setattr(perception, "_unusable", unusable)
    board, [rec] = _run_compute_grasp(franka, _bowl())
    preshape = DEFAULT_RIM_WALL_M / 2 + RIM_PRESHAPE_CLEARANCE_M
    assert rec["grasp_kind"] == "rim" and rec["preshape_m"] == pytest.approx(preshape)
    assert preshape == pytest.approx(0.02)  # half the Franka Hand's stroke on a 3 mm wall
    # every rim point was tried fully open (the skill's height and the lower ones) before one pre-shaped
    assert asked.count(None) == rec["rim_points_refused"] and rec["rim_points_refused"] >= 16
    assert franka.runtime_notes["planned_grasp"]["preshape_m"] == pytest.approx(preshape)

    # the pick's PreshapeHand opens the hand that far; the close is the same as ever
    ctx = SkillContext(target=franka)
    leaf = Gripper("PreshapeHand", command="preshape", object="bowl_1")
    leaf.setup(context=ctx)
    py_trees.blackboard.Blackboard.clear()
    leaf.tick_once()
    assert leaf.status == py_trees.common.Status.SUCCESS
    assert franka.gripper_opening() == pytest.approx(preshape, abs=2e-3)
    [shaped] = [r for r in ctx.trace.records if r["kind"] == "gripper"]
    assert shaped["command"] == "preshape" and shaped["object"] == "bowl_1"


def test_a_rim_reachable_fully_open_keeps_the_hand_fully_open(franka):
    _, [rec] = _run_compute_grasp(franka, _bowl())
    assert "preshape_m" not in rec and franka.runtime_notes["planned_grasp"]["preshape_m"] is None
    franka.set_gripper(opening_m=0.04)
    ctx = SkillContext(target=franka)
    leaf = Gripper("PreshapeHand", command="preshape", object="bowl_1")
    leaf.setup(context=ctx)
    leaf.tick_once()
    # nothing to do: the hand stays fully open, no time passes, nothing is traced
    assert franka.gripper_opening() == pytest.approx(0.04, abs=2e-3) and ctx.trace.records == []


def _lift(target, **params) -> tuple[SkillContext, py_trees.common.Status]:
    ctx = SkillContext(target=target)
    leaf = CartesianMove("Lift", velocity_scale=1.0, **params)
    leaf.setup(context=ctx)
    for _ in range(2000):
        leaf.tick_once()
        if leaf.status != py_trees.common.Status.RUNNING:
            break
    return ctx, leaf.status


def test_a_lift_past_the_arms_reach_rises_as_high_as_it_reaches(franka):
    z0 = float(franka.tcp_pose()[2, 3])
    # 1.5 m up from the ready pose is far out of the Panda's reach
    ctx, status = _lift(franka, offset=[0.0, 0.0, 1.5], at_least_m=0.05)
    assert status == py_trees.common.Status.SUCCESS, ctx.failure
    [limited] = [r for r in ctx.trace.records if r["kind"] == "reach_limited"]
    rose = float(franka.tcp_pose()[2, 3]) - z0
    assert limited["asked_m"] == 1.5 and 0.05 <= limited["moved_m"] < 1.5
    assert rose == pytest.approx(limited["moved_m"], abs=3e-3)
    # a centimetre more is out of reach: it stopped at the edge, not short of it
    T = franka.tcp_pose()
    T[2, 3] += REACH_STEP_M
    from phyagentos.motion.cartesian import cartesian_path
    from phyagentos.primitives.motion import ik_options

    with pytest.raises(IKError):
        cartesian_path(franka.model, q_start=franka.arm_qpos(), T_goal=T, **ik_options(franka))


def test_without_at_least_a_lift_out_of_reach_fails_before_moving(franka):
    q0 = franka.arm_qpos().copy()
    ctx, status = _lift(franka, offset=[0.0, 0.0, 1.5])
    assert status == py_trees.common.Status.FAILURE
    assert ctx.failure["code"] == "ik.unreachable"
    assert np.allclose(franka.arm_qpos(), q0, atol=1e-3)
    # nor when the arm reaches less than asked at least
    ctx, status = _lift(franka, offset=[0.0, 0.0, 1.5], at_least_m=1.2)
    assert status == py_trees.common.Status.FAILURE and ctx.failure["code"] == "ik.unreachable"


def test_at_least_is_checked_before_anything_moves():
    with pytest.raises(ValueError, match="at_least_m applies to an 'offset' move only"):
        CartesianMove("Lift", to="grasp_pose", at_least_m=0.05)
    with pytest.raises(ValueError, match="at_least_m must be a number of m >= 0 or null"):
        CartesianMove("Lift", offset=[0.0, 0.0, 0.15], at_least_m=-0.01)
    # more than the offset asks: all of it
    assert CartesianMove("Lift", offset=[0.0, 0.0, 0.15], at_least_m=0.5).at_least_m == pytest.approx(0.15)


def test_a_close_on_the_object_tells_the_perceiver_where_the_hand_closed(franka, monkeypatch):
    """A hold seen only after the lift needs where the hand closed (the object's pose in the
    hand): the close, judged on the object by the hand's own sensing, notes its tcp pose to the
    session's perceiver and keeps the perceiver's state for the next session; a close on
    nothing notes nothing."""
    import dataclasses

    notes = []

    class Perceiver:
        def note_grasp_close(self, proprio):
            notes.append(proprio)

        def export_state(self):
            return {"closed_at": {"tcp_pose": notes[-1].tcp_pose.tolist(), "stamp_s": notes[-1].stamp_s}}

    real = franka.proprioception
    squeezing = {"on": False}

    def proprioception():
        p = real()
        return dataclasses.replace(p, gripper_opening_m=0.02, gripper_effort_n=20.0) if squeezing["on"] else p

    def set_gripper(*, opening_m, **kw):
        squeezing["on"] = opening_m == 0.0
        return SimpleNamespace(opening_m=0.02 if squeezing["on"] else opening_m, stalled=squeezing["on"])

    monkeypatch.setattr(franka, "proprioception", proprioception)
    monkeypatch.setattr(franka, "set_gripper", set_gripper)
    franka.runtime_notes["planned_grasp"] = {"object": "cube_1", "width_m": 0.04}
    ctx = SkillContext(target=franka, perceiver=Perceiver())
    for leaf in (Gripper("CloseOnNothing", command="close"), Gripper("CloseOnObject", command="close", object="cube_1")):
        leaf.setup(context=ctx)
        leaf.tick_once()
        assert leaf.status == py_trees.common.Status.SUCCESS
    [noted] = notes  # only the close on the object
    np.testing.assert_allclose(noted.tcp_pose, franka.tcp_pose())
    assert franka.runtime_notes["perception"]["closed_at"]["stamp_s"] == noted.stamp_s
