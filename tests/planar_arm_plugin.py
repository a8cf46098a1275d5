"""A plugin target written as a user would (docs/targets.md, "Adding a robot"): a 2-DoF
planar arm, its MuJoCo model inline, on the shared MuJoCo arm base. Not a test module:
tests/test_target_plugin_example.py installs it through an entry point and runs a
session on it.

Frames and units: world frame z up; the arm moves in the horizontal plane (both hinge
axes along z), links 0.3 m and 0.25 m, joints in rad, position actuators (kp 60 N m/rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError
from phyagentos.targets.contract import ExecutionResult, TargetCapabilities
from phyagentos.targets.mujoco_arm import MuJoCoArmTarget

PLANAR_ARM_XML = """
<mujoco model="planar_arm">
  <compiler angle="radian"/>
  <option timestep="0.002"/>
  <worldbody>
    <light pos="0 0 2"/>
    <geom name="floor" type="plane" size="1 1 0.05" rgba="0.8 0.8 0.8 1"/>
    <camera name="overview" pos="0.3 -1.2 1.2" xyaxes="1 0 0 0 0.7 0.7"/>
    <body name="base" pos="0 0 0.1">
      <geom type="cylinder" size="0.05 0.05" rgba="0.2 0.2 0.2 1" contype="0" conaffinity="0"/>
      <body name="link1">
        <joint name="shoulder" type="hinge" axis="0 0 1" range="-2.5 2.5" damping="2"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" contype="0" conaffinity="0"/>
        <body name="link2" pos="0.3 0 0">
          <joint name="elbow" type="hinge" axis="0 0 1" range="-2.5 2.5" damping="2"/>
          <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.018" contype="0" conaffinity="0"/>
          <site name="tcp" pos="0.25 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="shoulder_act" joint="shoulder" kp="60" ctrlrange="-2.5 2.5"/>
    <position name="elbow_act" joint="elbow" kp="60" ctrlrange="-2.5 2.5"/>
  </actuator>
</mujoco>
"""

#: Home configuration, rad.
HOME_QPOS = (0.3, -0.6)


@dataclass(frozen=True)
class PlanarScene:
    """The planar arm's scene: nothing but the arm (no objects, regions or obstacles)."""

    objects: tuple = ()
    regions: tuple = ()
    obstacles: tuple = ()
    object_names: tuple[str, ...] = ()

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any] | None) -> "PlanarScene":
        if raw:
            raise TargetError(f"the planar arm's scene takes no keys, got {sorted(raw)}")
        return cls()

    def to_dict(self) -> dict[str, Any]:
        return {}


class PlanarArmTarget(MuJoCoArmTarget):
    """A 2-DoF planar arm without a gripper.

    Args:
        name: target name (TARGETS.md).
        scene: a :class:`PlanarScene` (default: the empty one).
        seed: seeds :attr:`rng`.
    """

    KIND = "simulation"
    TOOLS = ("observe", "move_joints", "hold", "snapshot")
    CAPABILITIES = TargetCapabilities(action_forms=("joint_trajectory",), sensors=("proprioception", "rgb"),
                                      simulated_ground_truth=True)
    ROBOT = "planar_arm"
    REPORT_CONTACTS = False

    @classmethod
    def scene_from_dict(cls, raw: Mapping[str, Any] | None, *, root: Any = None) -> PlanarScene:
        return PlanarScene.from_dict(raw)

    def __init__(self, name: str, scene: PlanarScene | None = None, *, seed: int | None = None):
        super().__init__(name, "simulation")
        self._scene = scene if scene is not None else PlanarScene()
        model = mujoco.MjModel.from_xml_string(PLANAR_ARM_XML)
        data = mujoco.MjData(model)
        self._init_arm(model, data, ("shoulder", "elbow"), tcp_site="tcp", seed=seed)
        self._home = np.array(HOME_QPOS)
        self.reset(seed=seed)

    # -- what the MuJoCo arm base asks of a subclass ------------------------------------
    @property
    def home_qpos(self) -> np.ndarray:
        return self._home.copy()

    def gripper_opening(self) -> float:
        """No gripper: always 0 m."""
        return 0.0

    def held_objects(self) -> tuple[str, ...]:
        return ()

    def velocity_limits(self) -> np.ndarray:
        """``(2,)`` rad/s for trajectory timing."""
        return np.array([1.5, 1.5])

    @property
    def datasheet_limits(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """``(velocity (2,) rad/s, acceleration (2,) rad/s^2)`` for the safety guard (the
        default is the Franka's seven joints)."""
        return (2.0, 2.0), (8.0, 8.0)

    def ground_truth(self) -> dict[str, Any]:
        """The simulator's truth: the joint angles, rad, and the tcp position, m."""
        return {"stamp_s": self.sim_time, "arm_qpos": [float(q) for q in self.arm_qpos()],
                "tcp_position": [float(x) for x in self.tcp_pose()[:3, 3]], "objects": {}, "held": []}

    # -- the Target contract ----------------------------------------------------------
    def reset(self, *, seed: int | None = None) -> dict:
        """Arm at :data:`HOME_QPOS`, at rest, clock at 0. Returns :meth:`observe`."""
        self._check_open()
        m, d = self._model, self._data
        mujoco.mj_resetData(m, d)
        d.qpos[self._qadr] = self._home
        d.ctrl[self._arm_act] = self._home
        mujoco.mj_forward(m, d)
        self._rng = np.random.default_rng(seed)
        self.runtime_notes = {}
        return self.observe()

    def step(self, ctrl: Sequence[float] | None = None) -> None:
        """One physics step; ``ctrl`` (2,) joint position targets, rad (``None``: keep)."""
        self._check_open()
        if ctrl is not None:
            c = np.asarray(ctrl, dtype=float).reshape(-1)
            if c.shape != (2,) or not np.all(np.isfinite(c)):
                raise TargetError(f"ctrl must be 2 finite joint angles, got {ctrl!r}")
            self._data.ctrl[self._arm_act] = np.clip(c, self._ctrl_lo, self._ctrl_hi)
        mujoco.mj_step(self._model, self._data)

    def execute_trajectory(self, traj, *, tracking_tol_rad: float = 0.05) -> ExecutionResult:
        """Stream ``traj`` (``t`` (M,) s, ``q``/``qd`` (M, 2)) to the position actuators, then settle."""
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        self._check_start(Q[0], tracking_tol_rad)
        ts = self._model.opt.timestep
        duration = float(t[-1])
        n = int(math.ceil(duration / ts - 1e-9)) if duration > 0 else 0
        times = np.minimum((np.arange(n) + 1) * ts, duration)
        t0 = self._data.time
        completed, max_err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, True, set())
        if completed:
            steps += self.settle(Q[-1])
        return ExecutionResult(completed=completed, max_tracking_error_rad=max_err,
                               sim_time_s=float(self._data.time - t0), steps=steps, reason=reason)
