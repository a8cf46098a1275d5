"""Whether the arm reaches a hand pose does not hang on one IK seed: the solver is local, and
from a wrist wound far from the goal it stops short of poses the arm reaches (LIBERO-10 task 9,
init 9: the push that shuts the microwave, 4-15 cm short from where the place left the joints,
reached from the ready configuration with either hand)."""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.errors import IKError
from phyagentos.motion.ik import solve_ik
from phyagentos.primitives import SkillContext
from phyagentos.primitives.motion import nearer_reachable_hand
from phyagentos.targets import MuJoCoTarget
from phyagentos.targets.scene import SceneSpec

#: Found by a search over random joints around the ready configuration: from here IK to
#: POINT with the hand pointing down fails for both hands; from the ready configuration
#: it converges for both.
WOUND = np.array([1.199, 0.362, 0.794, -2.777, -0.834, -0.392, -0.163])
POINT = np.array([0.454, -0.183, 0.295])
CLOSING = np.array([1.0, 0.0, 0.0])
DOWN = np.array([0.0, 0.0, -1.0])


@pytest.fixture
def franka():
    t = MuJoCoTarget("reach", SceneSpec.default(), seed=0)
    yield t
    t.close()


def _hand(closing):
    return np.column_stack([np.cross(closing, DOWN), closing, DOWN])


def test_a_hand_unreached_from_a_wound_wrist_is_reached_from_the_ready_configuration(franka, monkeypatch):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = _hand(CLOSING), POINT
    names = tuple(franka.arm_joint_names)
    with pytest.raises(IKError):  # the premise: from the wound joints the solver stops short
        solve_ik(franka.model, q_seed=WOUND, target=T, arm_joint_names=names, frame=franka.tcp_site)
    monkeypatch.setattr(franka, "arm_qpos", lambda: WOUND.copy())
    best = nearer_reachable_hand(SkillContext(target=franka), CLOSING, DOWN, [POINT])
    assert best is not None
    turn, R = best
    assert np.allclose(np.abs(R[:, 1]), np.abs(CLOSING)) and np.allclose(R[:, 2], DOWN) and 0.0 <= turn <= np.pi


def test_from_the_current_joints_the_answer_is_the_current_seeds_alone(franka):
    """Where the current joints reach a hand, the ready configuration is never consulted: the
    choice is the one the current seed makes (nearer the current wrist)."""
    here = franka.tcp_pose()[:3, 3] + [0.0, 0.05, -0.05]
    best = nearer_reachable_hand(SkillContext(target=franka), CLOSING, DOWN, [here])
    assert best is not None
    names = tuple(franka.arm_joint_names)
    for sign in (1.0, -1.0):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = _hand(sign * CLOSING), here
        solve_ik(franka.model, q_seed=franka.arm_qpos(), target=T, arm_joint_names=names, frame=franka.tcp_site)
    # both hands converge from here: the nearer one is chosen, as before the fallback
    wrist = franka.tcp_pose()[:3, :3]
    turns = [float(np.arccos(np.clip((np.trace(wrist.T @ _hand(s * CLOSING)) - 1.0) / 2.0, -1.0, 1.0)))
             for s in (1.0, -1.0)]
    assert best[0] == pytest.approx(min(turns))
