"""A move for one kind of grasp only: the pick's ``LiftOff`` rises a container taken by its rim
slowly first, and does nothing after any other grasp (issue 28).

Held at one point of its rim, a bowl hangs off-centre and swings about the fingers' closing
axis when the hand is jerked up; in LIBERO's open top drawer its far rim, 1.3 cm under the
cabinet's top, hit it and the bowl left the pinch. ``CartesianMove(grasp_kind="rim")`` moves
only when the planned grasp is a rim grasp. On the tabletop Franka model.
"""

from __future__ import annotations

import py_trees
import pytest
from test_preshape_and_reach import _lift  # a CartesianMove ticked to its end on a Franka

from phyagentos.primitives.execution import CartesianMove
from phyagentos.primitives.grasp_sense import plan_grasp
from phyagentos.targets import MuJoCoTarget
from phyagentos.targets.scene import SceneSpec


@pytest.fixture
def franka():
    t = MuJoCoTarget("liftoff", SceneSpec.default(), seed=0)
    yield t
    t.close()


@pytest.mark.parametrize("planned", [None, "across"])
def test_a_rim_only_move_after_another_grasp_does_nothing(franka, planned):
    if planned is not None:
        plan_grasp(franka, object="cube", width_m=0.04, kind=planned)
    z0, t0 = float(franka.tcp_pose()[2, 3]), franka.sim_time
    ctx, status = _lift(franka, offset=[0.0, 0.0, 0.02], grasp_kind="rim")
    assert status == py_trees.common.Status.SUCCESS
    assert ctx.trace.records == [] and franka.sim_time == t0
    assert float(franka.tcp_pose()[2, 3]) == pytest.approx(z0, abs=1e-6)


def test_a_rim_only_move_after_a_rim_grasp_moves(franka):
    plan_grasp(franka, object="bowl_1", width_m=0.003, kind="rim")
    z0 = float(franka.tcp_pose()[2, 3])
    ctx, status = _lift(franka, offset=[0.0, 0.0, 0.02], grasp_kind="rim")
    assert status == py_trees.common.Status.SUCCESS, ctx.failure
    assert [r["kind"] for r in ctx.trace.records][:1] == ["execute_start"]
    assert float(franka.tcp_pose()[2, 3]) - z0 == pytest.approx(0.02, abs=2e-3)


def test_grasp_kind_is_a_name():
    with pytest.raises(ValueError, match="grasp_kind must be a grasp kind's name"):
        CartesianMove("LiftOff", offset=[0.0, 0.0, 0.02], grasp_kind=3)
