"""MuJoCo simulation of the Franka Panda tabletop (:mod:`phyagentos.targets.scene`).

Control model: the arm has MuJoCo position actuators (``kp`` 870 / 120) and passive joint
damping (``b`` 100 / 10), with gravity compensation on the robot bodies (as the real
Panda's controller does). A position actuator tracking a moving reference lags by
``(b / kp) * q_dot`` in steady state, so :meth:`MuJoCoTarget.execute_trajectory` streams

    ctrl = q_ref + (b / kp) * qd_ref

with ``b`` and ``kp`` read from the model. The two finger actuators always get the same
command (the finger joints are also coupled by an equality constraint).

Units: metres, radians, seconds; poses are (4, 4) world transforms.
"""

from __future__ import annotations

import logging
import math
from typing import Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError

from ..base import ExecutionResult
from ..contract import TargetCapabilities
from ..mujoco_arm import GripperResult, MuJoCoArmTarget, PlansOnTheTabletop
from ..scene import (
    ARM_JOINT_NAMES,
    DEFAULT_SCENE,
    FINGER_ACTUATOR_NAMES,
    FINGER_BODY_NAMES,
    FINGER_JOINT_NAMES,
    FT_SITE,
    GRIPPER_MAX_OPENING_M,
    HOME_QPOS,
    TCP_SITE,
    SceneSpec,
    build_scene,
)

__all__ = ["MuJoCoTarget", "GripperResult", "ExecutionResult", "MAX_GRIP_FORCE_N"]

log = logging.getLogger(__name__)

_TOOLS = ("observe", "move_joints", "set_gripper", "hold", "snapshot")
#: Largest grip force a close may command, N per finger (the finger actuators' force
#: limit in the shipped model; Franka Hand datasheet: 70 N continuous).
MAX_GRIP_FORCE_N = 70.0


class MuJoCoTarget(PlansOnTheTabletop, MuJoCoArmTarget):
    """A simulated Franka Panda on a table, built from a :class:`SceneSpec`.

    What is particular to the Franka: its model (:func:`~phyagentos.targets.scene.build_scene`),
    the two coupled finger actuators and grip-force command, its ``(7,)``/``(8,)``/``(nu,)``
    control forms and its velocity limits. Everything else (sensors, rendering,
    checkpoints, contacts, ground truth) comes from :class:`MuJoCoArmTarget`.

    Args:
        name: target name.
        scene: what is on the table (default :data:`DEFAULT_SCENE`).
        seed: seeds :attr:`rng` and the camera noise; physics itself is deterministic.

    Raises:
        TargetError: the scene does not build.
    """

    ROBOT = "panda"
    CAPABILITIES = TargetCapabilities(action_forms=("joint_trajectory", "gripper_command"),
                                      sensors=("proprioception", "rgb", "wrist_force", "contacts", "perception"),
                                      simulated_ground_truth=True)
    SENSORS_KEY = "franka_tabletop"
    FT_SITE = FT_SITE

    def __init__(self, name: str, scene: SceneSpec = DEFAULT_SCENE, *, seed: int | None = None):
        super().__init__(name, "simulation")
        if not isinstance(scene, SceneSpec):
            raise TargetError(f"scene must be a SceneSpec, got {type(scene).__name__}")
        scene = self._prepare_scene(scene)
        model = build_scene(scene)
        self._init_arm(model, mujoco.MjData(model), ARM_JOINT_NAMES, tcp_site=TCP_SITE, seed=seed)
        m = self._model
        self._finger_act = np.array([m.actuator(n).id for n in FINGER_ACTUATOR_NAMES])
        self._finger_qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in FINGER_JOINT_NAMES])
        self._finger_dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in FINGER_JOINT_NAMES])
        self._damping = m.dof_damping[self._dadr].copy()
        self._home = np.array(HOME_QPOS, dtype=float)
        self._home_key = m.key("home").id
        robot_root = int(m.body_rootid[m.body("panda0_link1").id])
        self._init_tabletop(scene, robot_root=robot_root,
                            finger_sides={m.body(FINGER_BODY_NAMES[0]).id: 1, m.body(FINGER_BODY_NAMES[1]).id: 2})
        # Grip force: a position actuator squeezes with kp * (target - opening), so a
        # target below 0 (closed) is how a force is commanded; the finger joint range
        # still stops the fingers at 0.
        self._finger_kp = float(m.actuator_gainprm[self._finger_act[0], 0])
        m.actuator_ctrlrange[self._finger_act, 0] = -MAX_GRIP_FORCE_N / self._finger_kp
        self._ctrl_lo = m.actuator_ctrlrange[:, 0].copy()
        # Perturbations (phyagentos.targets.perturbations) change friction and mass;
        # nominal values are restored before the next session's are installed.
        self._nominal = (m.geom_friction.copy(), m.geom_priority.copy(), m.body_mass.copy(), m.body_inertia.copy())
        self._perturbations = None
        self._nominal_settled = False  # nominal values restored and their constants computed
        self.reset(seed=seed)

    @property
    def home_qpos(self) -> np.ndarray:
        """``(7,)`` rad ready configuration: tcp ~0.37 m above the table, pointing down."""
        return self._home.copy()

    def gripper_opening(self) -> float:
        """Current opening per finger in metres (0 closed .. 0.04 open)."""
        return float(np.mean(self._data.qpos[self._finger_qadr]))

    def _gripper_effort_n(self) -> float:
        """Squeeze of the finger actuators, N per finger (their actuator force; MuJoCo's
        ``actuator_force`` is negative when pushing the fingers closed)."""
        return float(max(0.0, -np.mean(self._data.actuator_force[self._finger_act])))

    def velocity_limits(self, torque_fraction: float = 0.6) -> np.ndarray:
        """``(7,)`` rad/s the simulated actuators sustain with feed-forward (see
        :func:`phyagentos.motion.retime.actuator_velocity_limits`)."""
        from phyagentos.motion.retime import actuator_velocity_limits  # noqa: PLC0415

        return actuator_velocity_limits(self._model, ARM_JOINT_NAMES, torque_fraction=torque_fraction)

    # -- lifecycle --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, settle_s: float = 0.3) -> dict:
        """Arm at :attr:`home_qpos`, gripper open, objects at their spec poses; physics
        settles for ``settle_s`` simulated seconds, then the clock restarts at 0.
        ``seed`` re-seeds :attr:`rng` and the camera noise. Returns :meth:`observe`."""
        self._reset_keyframe(self._home_key, settle_s, seed)
        return self.observe()

    # -- low-level control ------------------------------------------------------------
    def step(self, ctrl: Sequence[float] | None = None) -> None:
        """One physics step (``model.opt.timestep`` s).

        ``ctrl``: ``None`` (keep the current command), ``(7,)`` arm position targets (rad),
        ``(8,)`` arm targets plus gripper opening per finger (m), or ``(nu,)`` raw
        actuator commands. Values are clipped to the actuator control ranges.
        """
        self._check_open()
        if ctrl is not None:
            self._set_ctrl(np.asarray(ctrl, dtype=float).reshape(-1))
        mujoco.mj_step(self._model, self._data)

    def _set_ctrl(self, c: np.ndarray) -> None:
        d = self._data
        nu = self._model.nu
        if c.shape == (7,):
            d.ctrl[self._arm_act] = c
        elif c.shape == (8,):
            d.ctrl[self._arm_act] = c[:7]
            d.ctrl[self._finger_act] = c[7]
        elif c.shape == (nu,):
            d.ctrl[:] = c
            d.ctrl[self._finger_act] = c[self._finger_act].mean()
        else:
            raise TargetError(f"ctrl must have shape (7,), (8,) or ({nu},), got {c.shape}")
        if not np.all(np.isfinite(d.ctrl)):
            raise TargetError("ctrl must be finite")
        np.clip(d.ctrl, self._ctrl_lo, self._ctrl_hi, out=d.ctrl)

    def step_for(self, seconds: float, *, arm_ctrl: Sequence[float] | None = None) -> int:
        """Step the physics for ``seconds`` (rounded to whole steps) holding the current
        command, or ``arm_ctrl`` (7,) rad if given. Returns the number of steps."""
        self._check_open()
        if seconds < 0 or not math.isfinite(seconds):
            raise TargetError(f"seconds must be a finite number >= 0, got {seconds}")
        if arm_ctrl is not None:
            self._set_ctrl(np.asarray(arm_ctrl, dtype=float).reshape(-1)[:7])
        m, d = self._model, self._data
        n = int(round(seconds / m.opt.timestep))
        for _ in range(n):
            mujoco.mj_step(m, d)
        return n

    def track(
        self,
        traj,
        *,
        t_start: float,
        t_end: float,
        tracking_tol_rad: float = 0.05,
        feedforward: bool = True,
    ) -> ExecutionResult:
        """Stream only the slice ``(t_start, t_end]`` (s on the trajectory's clock) of
        ``traj``, one physics step per ``timestep``; for executors that advance a
        trajectory a control period per tick. Call :meth:`settle` after the last slice.
        The start check of :meth:`execute_trajectory` applies when ``t_start <= 0``.
        Returns the :class:`ExecutionResult` of this slice."""
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        if t_start <= 0.0:
            self._check_start(Q[0], tracking_tol_rad)
        times = self._slice_times(t, t_start, t_end)
        return self._stream_result(t, Q, QD, times, tracking_tol_rad, feedforward)

    # -- gripper ----------------------------------------------------------------------
    def set_gripper(self, *, opening_m: float, settle_s: float = 0.5, force_n: float | None = None) -> GripperResult:
        """Command both fingers to ``opening_m`` per finger (0 .. 0.04 m) and simulate
        until they stop (at least 0.1 s, at most ``settle_s``). The arm holds its
        current command.

        ``force_n`` (N per finger, 0 .. :data:`MAX_GRIP_FORCE_N`) squeezes whatever
        stops the fingers short of ``opening_m`` with that force: the position target
        goes ``force_n / kp`` past ``opening_m`` (finger ``kp`` read from the model).
        Without it the squeeze is ``kp * (width - opening_m)``, about 10 N on a 4 cm box.
        The command persists until the next call.

        Raises TargetError for an opening or force outside its range."""
        self._check_open()
        o = float(opening_m)
        if not (-1e-9 <= o <= GRIPPER_MAX_OPENING_M + 1e-9) or not math.isfinite(o):
            raise TargetError(f"opening_m must be in [0, {GRIPPER_MAX_OPENING_M}] m, got {opening_m}")
        if force_n is not None and not (0.0 <= float(force_n) <= MAX_GRIP_FORCE_N):
            raise TargetError(f"force_n must be in [0, {MAX_GRIP_FORCE_N}] N per finger, got {force_n}")
        m, d = self._model, self._data
        command = min(max(o, 0.0), GRIPPER_MAX_OPENING_M)
        if force_n is not None:
            command -= float(force_n) / self._finger_kp
        d.ctrl[self._finger_act] = command
        ts = m.opt.timestep
        n_max = max(1, int(round(settle_s / ts)))
        n_min = min(n_max, int(round(0.1 / ts)))
        still = 0
        for k in range(n_max):
            mujoco.mj_step(m, d)
            v = float(np.max(np.abs(d.qvel[self._finger_dadr])))
            still = still + 1 if v < 2e-3 else 0
            if k + 1 >= n_min and still >= int(round(0.05 / ts)):
                break
        opening = self.gripper_opening()
        return GripperResult(opening_m=opening, stalled=abs(opening - o) > 0.002)

    # -- perception and perturbations (phyagentos.targets.perturbations) ---------------
    @property
    def perturbations(self):
        """The session's :class:`~phyagentos.targets.perturbations.ActivePerturbations`, or ``None``."""
        return self._perturbations

    def set_perturbations(self, active) -> None:
        """Restore nominal friction and mass, then install ``active`` (``None``: none).

        Called by the target pool for every session, since a target outlives its sessions.
        A session without perturbations after one without them changes nothing: the
        restore and the constants (``mj_setConst`` on a scratch ``MjData``, about 0.5 ms)
        are then skipped.
        """
        if not active and self._nominal_settled:
            self._perturbations = None
            return
        m = self._model
        friction, priority, mass, inertia = self._nominal
        m.geom_friction[:] = friction
        m.geom_priority[:] = priority
        m.body_mass[:] = mass
        m.body_inertia[:] = inertia
        self._perturbations = active if active else None
        if self._perturbations is not None:
            self._perturbations.apply_model(m, object_geoms=self._obj_geom, object_bodies=self._obj_body)
        # Constraint regularisation depends on body masses (invweight0); recompute on a
        # scratch MjData so the live state is untouched.
        mujoco.mj_setConst(m, mujoco.MjData(m))
        self._nominal_settled = self._perturbations is None

    def perceive(self, samples: int = 1) -> dict:
        """What the robot's perception reports: a :meth:`snapshot` whose object positions
        carry the session's perception noise, averaged over ``samples`` frames (>= 1).

        Without perturbations it equals :meth:`snapshot`. A ``displaced`` perturbation
        fires after the first perception that sees its object on the table.
        Raises TargetError for ``samples`` < 1.
        """
        if not isinstance(samples, int) or isinstance(samples, bool) or samples < 1:
            raise TargetError(f"perceive: samples must be an integer >= 1, got {samples!r}")
        snap = self.snapshot()
        if self._perturbations is not None:
            snap = self._perturbations.perceive(snap, samples=samples, target=self)
        return snap

    def footprint_clear(self, name: str, xy, *, clearance_m: float = 0.0) -> bool:
        """True if object ``name`` centred at ``xy`` (world, m) would stay on the table and
        ``clearance_m`` away from obstacles and the other objects (axis-aligned footprints)."""
        he = np.asarray(self._scene.object(name).half_extents)
        x, y = float(xy[0]), float(xy[1])
        if not (0.2 <= x <= 0.9 and -0.6 <= y <= 0.6):
            return False
        others = [(ob.center[:2], ob.half_extents[:2]) for ob in self._scene.obstacles]
        others += [(self.object_pose(o.name)[:2, 3], o.half_extents[:2]) for o in self._scene.objects if o.name != name]
        for c, h in others:
            if abs(x - c[0]) < he[0] + h[0] + clearance_m and abs(y - c[1]) < he[1] + h[1] + clearance_m:
                return False
        return True

    def move_object(self, name: str, xy) -> None:
        """Put object ``name`` at ``xy`` (world, m) keeping its height and orientation, at rest."""
        q = self._obj_qadr[self.scene.object(name).name]
        v = self._obj_dadr[name]
        self._data.qpos[q:q + 2] = [float(xy[0]), float(xy[1])]
        self._data.qvel[v:v + 6] = 0.0
        mujoco.mj_forward(self._model, self._data)

    def _tool_set_gripper(self, opening_m: float, settle_s: float = 0.5, force_n: float | None = None) -> dict:
        return self.set_gripper(opening_m=opening_m, settle_s=settle_s, force_n=force_n).to_dict()
