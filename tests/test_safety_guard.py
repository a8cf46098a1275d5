"""SafetyGuard: every check, its violation code and outcome, clamps only where authorised."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from phyagentos.protocol.schemas import SAFETY_VIOLATIONS, SafetyConfig
from phyagentos.runtime.safety_guard import ChainFK, EStopLatch, SafetyGuard
from phyagentos.targets import MuJoCoTarget, SceneSpec
from phyagentos.targets.scene import ARM_JOINT_NAMES

DT = 0.002


@pytest.fixture(scope="module")
def target():
    t = MuJoCoTarget("guard", SceneSpec())
    yield t
    t.close()


def guard_for(target, **config) -> SafetyGuard:
    return SafetyGuard.for_target(target, SafetyConfig(**config), events=[], estop=EStopLatch())


def smooth(q0, delta, n=50, gripper=None):
    """(n, 7|8) rest-to-rest move by ``delta`` rad (smoothstep), admissible by construction."""
    s = np.linspace(0, 1, n + 1)[1:]
    q = np.asarray(q0) + np.outer(3 * s**2 - 2 * s**3, delta)
    return q if gripper is None else np.hstack([q, np.full((n, 1), gripper)])


def test_an_admissible_chunk_passes_untouched_and_records_nothing(target):
    guard = guard_for(target)
    chunk = smooth(target.home_qpos, np.full(7, 0.01), gripper=0.04)
    decision = guard.check(chunk, dt=DT)
    assert decision.outcome == "pass" and decision.admitted and decision.actions is chunk
    assert guard.events == []


@pytest.mark.parametrize("fault, code, outcome", [
    ("dtype", "safety.dtype", "reject"),
    ("shape", "safety.shape", "reject"),
    ("nan", "safety.nan", "reject"),
    ("inf", "safety.nan", "reject"),
    ("joint_limit", "safety.joint_limit", "halt"),
    ("gripper", "safety.joint_limit", "halt"),
    ("velocity", "safety.velocity", "halt"),
    ("acceleration", "safety.acceleration", "halt"),
    ("workspace", "safety.workspace", "halt"),
    ("duration", "safety.duration", "reject"),
    ("rate", "safety.rate", "reject"),
])
def test_each_violation_is_refused_with_its_code_and_outcome_in_the_events(target, fault, code, outcome):
    guard = guard_for(target, workspace_box={"min": [-0.2, -0.8, 0.30], "max": [1.0, 0.8, 1.2]})
    q0 = target.home_qpos
    chunk, dt = smooth(q0, np.full(7, 0.01), gripper=0.04), DT
    if fault == "dtype":
        chunk = chunk.astype(np.int64)
    elif fault == "shape":
        chunk = chunk[:, :6]
    elif fault == "nan":
        chunk[10, 2] = np.nan
    elif fault == "inf":
        chunk[3, 7] = np.inf
    elif fault == "joint_limit":
        chunk = smooth(q0, np.array([0, 0, 0, 2.3, 0, 0, 0]), n=2000)  # joint 4 beyond -0.4 rad
    elif fault == "gripper":
        chunk[:, 7] = 0.06
    elif fault == "velocity":
        chunk = smooth(q0, np.array([0.3, 0, 0, 0, 0, 0, 0]), n=50)  # ~4.5 rad/s peak
    elif fault == "acceleration":
        chunk = smooth(q0, np.array([0.1, 0, 0, 0, 0, 0, 0]), n=100)  # 1.5 rad/s but 30 rad/s^2
    elif fault == "workspace":
        chunk = smooth(q0, np.array([0, 0.4, 0, 0, 0, 0, 0]), n=1500)  # tcp dips below z = 0.30
    elif fault == "duration":
        chunk, dt = smooth(q0, np.full(7, 0.01), n=200), 0.2  # 40 s
    elif fault == "rate":
        dt = 0.0002  # 5 kHz
    decision = guard.check(chunk, dt=dt)
    assert not decision.admitted and decision.actions is None
    assert decision.outcome == outcome
    assert decision.code == code
    assert code in {e["code"] for e in guard.events}
    event = next(e for e in guard.events if e["code"] == code)
    assert event["layer"] == "safety_guard" and event["outcome"] == outcome and event["message"]


def test_clamping_happens_only_for_codes_safety_yaml_authorises(target):
    chunk = smooth(target.home_qpos, np.array([0, 0, 0, 0, 0, 0, 3.0]), n=2000)  # wrist past 2.8973 rad
    refused = guard_for(target).check(chunk, dt=DT)
    assert refused.outcome == "halt" and refused.code == "safety.joint_limit"

    guard = guard_for(target, clamp_allowed=["safety.joint_limit"])
    clamped = guard.check(chunk, dt=DT)
    assert clamped.outcome == "clamp" and clamped.admitted
    assert clamped.actions[:, 6].max() <= guard.limits.q_max[6] + 1e-12
    assert np.allclose(clamped.actions[:, :6], chunk[:, :6])
    assert [e["outcome"] for e in guard.events] == ["clamp"]


def test_a_clamped_velocity_is_rate_limited_and_then_admissible(target):
    guard = guard_for(target, clamp_allowed=["safety.velocity", "safety.acceleration"])
    chunk = smooth(target.home_qpos, np.array([0.3, 0, 0, 0, 0, 0, 0]), n=50)
    decision = guard.check(chunk, dt=DT)
    assert decision.outcome == "clamp"
    v = np.diff(np.vstack([target.home_qpos, decision.actions]), axis=0) / DT
    assert np.all(np.abs(v) <= guard.limits.v_max + 1e-9)
    # the clamped command passes a fresh check: the clamp produced an admissible command
    guard.sync(target.home_qpos)
    assert guard.check(decision.actions, dt=DT).outcome == "pass"


def test_unclampable_codes_and_an_estop_that_does_not_halt_are_invalid_config():
    with pytest.raises(ValidationError, match="cannot be clamped"):
        SafetyConfig(clamp_allowed=["safety.workspace"])
    with pytest.raises(ValidationError, match="must be 'halt'"):
        SafetyConfig(violation_outcomes={"safety.estop": "reject"})
    with pytest.raises(ValidationError, match="unknown violation code"):
        SafetyConfig(violation_outcomes={"safety.speed": "halt"})
    assert set(SafetyConfig().violation_outcomes) == set(SAFETY_VIOLATIONS)


def test_limits_are_read_only_once_loaded(target):
    config = SafetyConfig(max_joint_velocity_scale=0.5)
    with pytest.raises(ValidationError):
        config.max_joint_velocity_scale = 1.0  # frozen: no writer can widen a limit
    guard = SafetyGuard.for_target(target, config, events=[], estop=EStopLatch())
    for arr in (guard.limits.q_min, guard.limits.q_max, guard.limits.v_max, guard.limits.a_max, guard.limits.box_min):
        assert not arr.flags.writeable
    assert np.allclose(guard.limits.v_max, 0.5 * np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61]))


def test_an_engaged_estop_halts_every_command_until_cleared(target):
    guard = guard_for(target)
    chunk = smooth(target.home_qpos, np.full(7, 0.01))
    guard.estop.engage("operator pressed the button")
    decision = guard.check(chunk, dt=DT)
    assert decision.outcome == "halt" and decision.code == "safety.estop"
    assert guard.events[-1]["code"] == "safety.estop"
    guard.estop.clear()
    assert guard.check(chunk, dt=DT).outcome == "pass"


def test_the_target_local_estop_hook_stops_streaming_within_one_physics_step(target):
    guard = guard_for(target)  # arms target.estop with the guard's latch
    target.reset(seed=0)
    from phyagentos.motion.retime import retime

    traj = retime(np.array([target.home_qpos, target.home_qpos + 0.3]), dt=target.timestep)
    t0 = target.sim_time
    result = target.track(traj, t_start=0.0, t_end=0.05)
    assert result.completed and result.steps == 25
    guard.estop.engage("test")
    result = target.track(traj, t_start=0.05, t_end=0.5)
    assert not result.completed and result.steps == 0 and "e-stop" in result.reason
    assert target.sim_time == pytest.approx(t0 + 0.05)
    # halted: the arm is commanded to where it is, not to the trajectory
    assert np.allclose(target.data.ctrl[:7], target.arm_qpos(), atol=1e-12)
    guard.estop.clear()
    target.estop = None


def test_vectorised_forward_kinematics_matches_mujoco(target):
    fk = ChainFK(target.model, ARM_JOINT_NAMES, "tcp")
    rng = np.random.default_rng(7)
    lo, hi = target.model.jnt_range[:7, 0], target.model.jnt_range[:7, 1]
    Q = rng.uniform(lo, hi, size=(64, 7))
    fast = fk.positions(Q)  # numpy path
    small = np.vstack([fk.positions(Q[i:i + 1]) for i in range(len(Q))])  # mj_kinematics path
    assert np.allclose(fast, small, atol=1e-12)
    target.reset(seed=0)
    assert np.allclose(fk.positions(target.arm_qpos()[None, :])[0], target.tcp_pose()[:3, 3], atol=1e-9)


def test_guards_of_one_model_share_its_chain_and_another_model_gets_its_own(target):
    config = SafetyConfig()
    first, second = SafetyGuard.for_target(target, config), SafetyGuard.for_target(target, config)
    assert first.limits.fk is second.limits.fk is ChainFK.of(target.model, ARM_JOINT_NAMES, "tcp")
    other = MuJoCoTarget("other", SceneSpec.default(), seed=0)
    try:
        chain = SafetyGuard.for_target(other, config).limits.fk
        assert chain is not first.limits.fk
        Q = np.random.default_rng(3).uniform(-0.5, 0.5, size=(2, 7))  # the scratch-data path
        assert np.allclose(chain.positions(Q), ChainFK(other.model, ARM_JOINT_NAMES, "tcp").positions(Q), atol=1e-12)
        assert np.allclose(first.limits.fk.positions(Q), chain.positions(Q), atol=1e-12)
    finally:
        other.close()


def test_single_actions_take_the_same_checks(target):
    guard = guard_for(target)
    q0 = target.home_qpos
    one = np.hstack([q0 + 1e-4, [0.04]])[None, :]
    assert guard.check(one, dt=0.01).outcome == "pass"
    guard.sync(q0)
    jump = one.copy()
    jump[0, 0] += 0.1  # 10 rad/s over one 10 ms period
    assert guard.check(jump, dt=0.01).code == "safety.velocity"
    nan = one.copy()
    nan[0, 4] = np.nan
    assert guard.check(nan, dt=0.01).code == "safety.nan"
    beyond = np.hstack([q0, [0.05]])[None, :]
    assert guard.check(beyond, dt=0.01).code == "safety.joint_limit"


def test_forgetting_a_model_drops_its_chains_and_with_them_the_model():
    import gc
    import weakref

    other = MuJoCoTarget("other", SceneSpec.default(), seed=0)
    ChainFK.of(other.model, ARM_JOINT_NAMES, "tcp")
    ref = weakref.ref(other.model)
    assert ChainFK.forget(other.model) == 1 and ChainFK.forget(other.model) == 0
    other.close()
    del other
    gc.collect()
    assert ref() is None
