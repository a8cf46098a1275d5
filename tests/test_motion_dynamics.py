"""Timing a path within the actuators' torques: ArmDynamics (MuJoCo inverse dynamics, a
medium's drag included) and retime's torque constraint."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from phyagentos.errors import MotionError
from phyagentos.motion import ArmDynamics, retime

#: Two hinges about z carrying a light body with a large inertia, as robosuite's Panda's finger
#: tips are (0.01 kg, 0.01 kg m^2): MuJoCo's inertia-box fluid model makes it a box metres
#: wide, whose drag in a dense medium loads both joints when either turns it.
ARM = """
<mujoco>
  <option density="{density}" viscosity="2e-5" gravity="0 0 -9.81"/>
  <worldbody>
    <body name="link1">
      <joint name="j1" type="hinge" axis="0 0 1" damping="0.01"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>
      <body name="link2" pos="0.3 0 0">
        <joint name="j2" type="hinge" axis="0 0 1" damping="0.01"/>
        <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02" mass="0.5"/>
        <body name="tip" pos="0.2 0 0">
          <inertial pos="0 0 0" mass="0.01" diaginertia="0.01 0.01 0.01"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position joint="j1" kp="500" forcelimited="true" forcerange="-5 5"/>
    <position joint="j2" kp="300" forcelimited="true" forcerange="-0.2 0.2"/>
  </actuator>
</mujoco>
"""

PATH = np.array([[0.0, 0.0], [1.2, -1.5]])
VEL, ACC = np.array([1.5, 1.5]), np.array([6.0, 6.0])
#: N m: the two actuators' force limits (the second, the wrist's, below what the drag asks at VEL)
LIMITS = (5.0, 0.2)


def _model(density: float) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(ARM.format(density=density))


def test_the_torques_are_mujocos_inverse_dynamics_of_the_arm_with_the_mediums_drag():
    m = _model(1.2)
    dyn = ArmDynamics(m, ("j1", "j2"), torque_limits=LIMITS)
    d = mujoco.MjData(m)
    q, qd, qdd = np.array([0.3, -0.7]), np.array([1.1, -0.8]), np.array([2.0, -3.0])
    d.qpos[:], d.qvel[:], d.qacc[:] = q, qd, qdd
    mujoco.mj_inverse(m, d)
    np.testing.assert_allclose(dyn.inverse(q, qd, qdd), d.qfrc_inverse, atol=1e-9)
    # the drag is most of it: without the medium the same motion asks far less of the wrist
    still = ArmDynamics(_model(0.0), ("j1", "j2"), torque_limits=LIMITS).inverse(q, qd, qdd)
    assert abs(dyn.inverse(q, qd, qdd)[1]) > 2.0 * abs(still[1])


def test_a_path_timed_within_the_torques_stays_within_them_where_speed_limits_alone_do_not():
    dyn = ArmDynamics(_model(1.2), ("j1", "j2"), torque_limits=LIMITS)
    plain = retime(PATH, vel_limits=VEL, acc_limits=ACC)
    timed = retime(PATH, vel_limits=VEL, acc_limits=ACC, dynamics=dyn)
    tau_plain = np.array([dyn.inverse(*s) for s in zip(plain.q, plain.qd, plain.qdd)])
    tau = np.array([dyn.inverse(*s) for s in zip(timed.q, timed.qd, timed.qdd)])
    assert np.abs(tau_plain[:, 1]).max() > LIMITS[1]
    assert np.all(np.abs(tau) <= 1.05 * dyn.torque_limits), np.abs(tau).max(axis=0)
    assert timed.duration > plain.duration
    np.testing.assert_allclose(timed.q[[0, -1]], PATH, atol=1e-9)


def test_where_the_torques_stay_low_the_timing_is_the_speed_limits_own():
    dyn = ArmDynamics(_model(0.0), ("j1", "j2"), torque_limits=LIMITS)
    plain = retime(PATH, vel_limits=VEL, acc_limits=ACC)
    timed = retime(PATH, vel_limits=VEL, acc_limits=ACC, dynamics=dyn)
    assert timed.duration == pytest.approx(plain.duration, rel=0.01)


@pytest.mark.parametrize("joints,limits,expect", [
    (("j1", "nope"), (1.0, 1.0), "'nope' is not a hinge joint"),
    (("j1", "j2"), (1.0,), "torque_limits must be 2 finite numbers > 0"),
    (("j1", "j2"), (1.0, 0.0), "torque_limits must be 2 finite numbers > 0"),
])
def test_an_unknown_joint_or_bad_torque_limits_are_refused_by_name(joints, limits, expect):
    with pytest.raises(MotionError, match=expect):
        ArmDynamics(_model(1.2), joints, torque_limits=limits)
