"""``so101_real``: the SO-101 on its Feetech bus, with the MuJoCo SO-101 as its twin.

:class:`SO101RealTarget` *is* an :class:`~phyagentos.targets.so101.SO101Target` (the
twin: the same model, IK, reach, collision checking, preflight, timing and rendering)
whose motion happens on the bus:

- every streamed period goes through :class:`~.arm.SO101Arm` (sync read, the bus
  SafetyGuard, sync write of the goals), and the twin *mirrors* the measured arm: its arm
  actuators are driven to the measured joint angles and its physics advanced by one
  period, so the objects in the twin respond to what the real arm did (the twin's
  object poses are a belief, not a measurement: on hardware, perception on the real
  cameras is what the verifier must see);
- the jaw is mirrored with its *commanded* angle (a closed jaw squeezes in the twin as
  it does on the bus) and its measured ``Present_Load`` is the grip effort
  (:meth:`_gripper_effort_n`);
- reset and restore never move the arm: the twin's arm is set to the measured pose.

With ``dry_run`` the bus is only read: the twin plans, checks and executes in
simulation (the view shows it), and no torque or goal reaches the servos.

Construction (before anything moves): the calibration file is loaded (missing: a
:class:`~.calibration.CalibrationError`), the port opened and the six ids pinged
(:class:`~.driver.BusError` ``bus.port`` / ``bus.id_mismatch`` / ``bus.model``), the
calibration written and the first reading checked; only then is torque enabled, holding
the present pose.

TARGETS.md (the ``so101_real`` entry ``phyagentos run --port`` writes)::

    driver: so101_real
    endpoint: /dev/ttyACM0            # the serial port
    constraints:
      calibration: ~/.cache/huggingface/lerobot/calibration/robots/so101_follower/so101.json
      dry_run: false
      control_period_s: 0.02
      bus_limits: {stop_policy: hold, max_step_rad: 0.25, ...}   # guard.BusLimits
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path
from typing import Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError

from ..base import ExecutionResult
from ..mujoco_target import GripperResult
from ..scene import SceneSpec
from ..so101 import SO101_DEFAULT_SCENE, SO101Target
from .arm import SO101Arm
from .calibration import Calibration, default_calibration_path
from .guard import BusLimits
from .protocol import MOTOR_NAMES

__all__ = ["SO101RealTarget", "REAL_VELOCITY_LIMIT_RAD_S"]

log = logging.getLogger(__name__)

#: Joint speed the real target times its trajectories for, rad/s (a third of the
#: STS3215's no-load 4.7 rad/s: a first session on a real arm is slow on purpose).
REAL_VELOCITY_LIMIT_RAD_S = 1.5
#: Tracking tolerance on the bus (measured vs the goal one period earlier), rad.
REAL_TRACKING_TOL_RAD = 0.15
_JAW_STALL_RAD_S = 0.05


class SO101RealTarget(SO101Target):
    """The real SO-101 (module docstring).

    Args:
        name: target name (TARGETS.md).
        scene: the twin's scene (what the world is believed to hold).
        seed: the twin's seed.
        port: serial device of the arm's bus (``/dev/ttyACM0``; a bus twin's ``/dev/pts/N``);
            None: the twin alone, no bus (what graph preflight builds for its reach checks;
            :meth:`from_target_spec` requires the port).
        calibration: LeRobot calibration JSON (default :func:`default_calibration_path`).
        limits: bus guard limits (:class:`~.guard.BusLimits`).
        dry_run: read the bus only; motion happens in the twin.
        control_period_s: period of the bus loop, s.

    Raises:
        TargetError: :class:`~.calibration.CalibrationError`; :class:`~.driver.BusError`.
    """

    def __init__(self, name: str, scene: SceneSpec = SO101_DEFAULT_SCENE, *, seed: int | None = None,
                 port: str | None = None, calibration: str | os.PathLike | Calibration | None = None,
                 limits: BusLimits | None = None, dry_run: bool = False, control_period_s: float = 0.02):
        self._estop_latch = None
        self.arm: SO101Arm | None = None
        self._real_cams: dict = {}
        cal = None
        if port:  # the calibration first: a missing file is an error before the bus is touched
            cal = calibration if isinstance(calibration, Calibration) else Calibration.load(
                Path(calibration).expanduser() if calibration else default_calibration_path())
        super().__init__(name, scene, seed=seed)
        self._kind = "real_robot"
        self.dry_run = bool(dry_run) or not port
        if not port:  # the twin alone: graph preflight's reach checks build the target this way
            return
        arm = SO101Arm(str(port), calibration=cal, limits=limits, control_period_s=control_period_s,
                       estop=self._estop_latch, dry_run=dry_run)
        try:
            arm.connect()
        except Exception:
            arm.close()
            raise
        self.arm = arm
        self._bind_ranges(cal)
        self._jaw_goal = float(arm.goal_q[5])  # the jaw keeps squeezing what it held
        self._mirror_pose(arm.last_q)
        log.info("so101_real on %s: connected%s", port, " (dry run: read only)" if dry_run else "")

    @classmethod
    def from_target_spec(cls, spec, scene: SceneSpec, *, seed: int | None = None) -> "SO101RealTarget":
        """Build from a TARGETS.md entry (``endpoint`` = port; ``constraints`` as in the
        module docstring)."""
        if not spec.endpoint:
            raise TargetError(f"target {spec.name!r} (so101_real) needs the arm's serial port as its endpoint: "
                              f"`phyagentos run ... --target {spec.name} --port /dev/ttyACM0` (or a bus twin's port "
                              f"from `phyagentos bus-twin so101`)")
        c = dict(spec.constraints or {})
        return cls(spec.name, scene, seed=seed, port=spec.endpoint, calibration=c.get("calibration"),
                   limits=BusLimits.from_dict(c.get("bus_limits")), dry_run=bool(c.get("dry_run", False)),
                   control_period_s=float(c.get("control_period_s", 0.02)))

    # -- e-stop hook: the runtime's SafetyGuard sets ``target.estop`` -------------------------
    @property
    def estop(self):
        return self._estop_latch

    @estop.setter
    def estop(self, latch) -> None:
        self._estop_latch = latch
        if getattr(self, "arm", None) is not None:
            self.arm.estop = latch

    def _bind_ranges(self, cal: Calibration, eps_rad: float = 0.005) -> None:
        """Narrow the twin's arm joint and actuator ranges to the calibrated ranges (less
        ``eps_rad``), so IK, planning and the runtime SafetyGuard stay where the bus guard
        admits goals."""
        m = self._model
        R = cal.safe_ranges_rad()
        for k, n in enumerate(self.arm_joint_names):
            j, a = m.joint(n).id, m.actuator(n).id
            lo = max(float(m.jnt_range[j, 0]), float(R[k, 0]) + eps_rad)
            hi = min(float(m.jnt_range[j, 1]), float(R[k, 1]) - eps_rad)
            if lo >= hi:
                raise TargetError(f"calibrated range of {n} ({R[k, 0]:+.3f}..{R[k, 1]:+.3f} rad) does not overlap the "
                                  f"twin's joint range; re-run calibration")
            m.jnt_range[j] = (lo, hi)
            m.actuator_ctrlrange[a] = (lo, hi)
            self._ctrl_lo[a], self._ctrl_hi[a] = lo, hi

    # -- twin mirror -------------------------------------------------------------------------
    def _mirror_pose(self, q6: np.ndarray) -> None:
        """Set the twin's arm and jaw to ``q6`` (no dynamics: reset / restore)."""
        d = self._data
        d.qpos[self._qadr] = q6[:5]
        d.qvel[self._dadr] = 0.0
        d.qpos[self._jaw_qadr] = q6[5]
        d.ctrl[self._arm_act] = np.clip(q6[:5], self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act])
        d.ctrl[self._jaw_act] = getattr(self, "_jaw_goal", q6[5])
        mujoco.mj_forward(self._model, d)

    def _mirror_step(self, _k: int, q6: np.ndarray) -> None:
        """One period of the twin following the measured arm (and the commanded jaw)."""
        m, d = self._model, self._data
        d.ctrl[self._arm_act] = np.clip(q6[:5], self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act])
        d.ctrl[self._jaw_act] = self._jaw_goal
        for _ in range(max(1, int(round(self.arm.dt / m.opt.timestep)))):
            mujoco.mj_step(m, d)
        if self._on_step is not None:
            self._on_step()

    def _goals(self, Q5: np.ndarray) -> np.ndarray:
        return np.column_stack([Q5, np.full(len(Q5), self._jaw_goal)])

    # -- the contract's motion, on the bus ------------------------------------------------------
    @property
    def kind(self) -> str:
        return "real_robot"

    def velocity_limits(self) -> np.ndarray:
        """(5,) rad/s trajectories are timed for: min(twin's, :data:`REAL_VELOCITY_LIMIT_RAD_S`)."""
        return np.minimum(super().velocity_limits(), REAL_VELOCITY_LIMIT_RAD_S)

    def track(self, traj, *, t_start: float, t_end: float, tracking_tol_rad: float = 0.05,
              feedforward: bool = True) -> ExecutionResult:
        """Stream the slice ``(t_start, t_end]`` of ``traj`` on the bus, one goal per control
        period (dry run: in the twin). Tolerance: max(``tracking_tol_rad``, 0.15 rad)."""
        if self.dry_run:
            return super().track(traj, t_start=t_start, t_end=t_end, tracking_tol_rad=tracking_tol_rad,
                                 feedforward=feedforward)
        self._check_open()
        t, Q, _ = self._traj_arrays(traj)
        dt = self.arm.dt
        times = np.arange(t_start + dt, t_end + 1e-9, dt)
        if len(times) == 0 or times[-1] < t_end - 1e-9:
            times = np.append(times, t_end)
        times = times[times > t_start]
        Qr = np.column_stack([np.interp(times, t, Q[:, j]) for j in range(self.n_arm)])
        t0 = self.sim_time
        res = self.arm.follow(self._goals(Qr), tracking_tol_rad=max(tracking_tol_rad, REAL_TRACKING_TOL_RAD),
                              on_period=self._mirror_step)
        reason = "" if res.completed else f"{res.code}: {res.reason}"
        return ExecutionResult(res.completed, res.max_tracking_error_rad, self.sim_time - t0, res.periods,
                               reason=reason, code="" if res.completed else res.code)

    def execute_trajectory(self, traj, *, tracking_tol_rad: float = 0.05, feedforward: bool = True) -> ExecutionResult:
        """Stream the whole trajectory, then settle at its end (bus; dry run: twin)."""
        if self.dry_run:
            return super().execute_trajectory(traj, tracking_tol_rad=tracking_tol_rad, feedforward=feedforward)
        t, Q, _ = self._traj_arrays(traj)
        res = self.track(traj, t_start=0.0, t_end=float(t[-1]), tracking_tol_rad=tracking_tol_rad)
        if res.completed:
            self.settle(Q[-1])
        return res

    def settle(self, q: Sequence[float] | None = None, *, settle_s: float = 0.5, tol_rad: float = 0.03,
               _contacts: set | None = None) -> int:
        """Hold goal ``q`` (5,) (default: the last goal) until the arm is within ``tol_rad``
        or ``settle_s`` s; returns the twin steps taken (periods x steps per period)."""
        if self.dry_run:
            return super().settle(q, settle_s=settle_s, tol_rad=max(tol_rad, 0.005), _contacts=_contacts)
        self._check_open()
        goal5 = self.arm.guard._last_goal[:5] if q is None else np.asarray(q, dtype=float).reshape(5)
        res = self.arm.settle(np.append(goal5, self._jaw_goal), timeout_s=settle_s, tol_rad=tol_rad,
                              on_period=self._mirror_step)
        return res.periods * max(1, int(round(self.arm.dt / self._model.opt.timestep)))

    def hold(self, q: Sequence[float] | None = None, *, duration_s: float) -> int:
        """Hold the arm at ``q`` (default: its last goal) for ``duration_s`` s (bus periods)."""
        if self.dry_run:
            return super().hold(q, duration_s=duration_s)
        self._check_open()
        if duration_s < 0 or not math.isfinite(duration_s):
            raise TargetError(f"seconds must be a finite number >= 0, got {duration_s}")
        goal5 = self.arm.guard._last_goal[:5] if q is None else np.asarray(q, dtype=float).reshape(5)
        n = max(1, int(round(duration_s / self.arm.dt)))
        res = self.arm.follow(np.tile(np.append(goal5, self._jaw_goal), (n, 1)), tracking_tol_rad=math.inf,
                              on_period=self._mirror_step)
        if not res.completed:
            raise TargetError(f"hold stopped: {res.code}: {res.reason}", code=res.code or None)
        return res.periods * max(1, int(round(self.arm.dt / self._model.opt.timestep)))

    def step(self, ctrl: Sequence[float] | None = None) -> None:
        """One bus period with goal ``ctrl`` (5,) or (6,) rad (None: the last goal)."""
        if self.dry_run:
            return super().step(ctrl)
        self._check_open()
        if ctrl is None:
            g = self.arm.guard._last_goal
        else:
            c = np.asarray(ctrl, dtype=float).reshape(-1)
            if c.shape not in ((5,), (6,)) or not np.all(np.isfinite(c)):
                raise TargetError(f"ctrl must be 5 or 6 finite numbers, got shape {c.shape}")
            if c.shape == (6,):
                self._jaw_goal = float(c[5])
            g = np.append(c[:5], self._jaw_goal)
        res = self.arm.follow(g.reshape(1, 6), tracking_tol_rad=math.inf, on_period=self._mirror_step)
        if not res.completed:
            raise TargetError(f"step stopped: {res.code}: {res.reason}", code=res.code or None)

    def set_gripper(self, *, opening_m: float, settle_s: float = 0.5, force_n: float | None = None) -> GripperResult:
        """Drive the jaw to the opening (as the twin does) on the bus and wait until it stops
        (velocity below 0.05 rad/s, 0.1 .. ``settle_s`` s). Raises TargetError for an
        opening outside [0, 0.04] m or a bus stop."""
        if self.dry_run:
            return super().set_gripper(opening_m=opening_m, settle_s=settle_s)
        self._check_open()
        o = float(opening_m)
        if not (0.0 <= o <= 0.04 + 1e-9) or not math.isfinite(o):
            raise TargetError(f"opening_m must be in [0, 0.04] m, got {opening_m}")
        self._jaw_goal = float(self._jaw_map.angles[0] if o <= 0.0 else self._jaw_map.angle_for(2.0 * o))
        arm5 = self.arm.guard._last_goal[:5]
        dt = self.arm.dt
        n_max, n_min = max(1, int(round(settle_s / dt))), max(1, int(round(0.1 / dt)))
        g = np.append(arm5, self._jaw_goal)
        prev = None
        for k in range(n_max):
            res = self.arm.follow(g.reshape(1, 6), tracking_tol_rad=math.inf, on_period=self._mirror_step)
            if not res.completed:
                raise TargetError(f"gripper stopped: {res.code}: {res.reason}", code=res.code or None)
            jaw = float(self.arm.last_q[5])
            if prev is not None and k + 1 >= n_min and abs(jaw - prev) / dt < _JAW_STALL_RAD_S:
                break
            prev = jaw
        opening = self.gripper_opening()
        return GripperResult(opening_m=opening, stalled=abs(opening - o) > 0.002)

    def _gripper_effort_n(self) -> float:
        """Grip force, N: the jaw servo's measured ``Present_Load`` (0.1 % of 3.35 N m) over the
        pad lever (the twin's when dry-running)."""
        if self.dry_run or self.arm is None or self.arm.last_state is None:
            return super()._gripper_effort_n()
        super()._gripper_effort_n()  # measures the lever once
        torque = abs(float(self.arm.last_state.load[5])) / 1000.0 * float(self._model.actuator_forcerange[self._jaw_act, 1])
        return torque / self._jaw_lever_m

    def halt(self) -> None:
        """Stop where the arm is: arm goals := the measured positions, the jaw keeps its goal
        (a held object stays held); one sync write, not latched."""
        if self.dry_run or self.closed or self.arm is None:
            return super().halt()
        try:
            q, _ = self.arm.read()
            if self.arm.stopped is None:
                self.arm.guard.sync(q)
                self.arm.send(np.append(q[:5], self._jaw_goal))  # the jaw keeps its grip
            self._mirror_pose(q)
        except Exception as exc:  # noqa: BLE001 - a halt must not raise; the guard recorded the stop
            log.warning("so101_real halt: %s", exc)

    def reset(self, *, seed: int | None = None, settle_s: float = 0.3) -> dict:
        """The twin's objects to their scene poses; its arm to the *measured* pose (the real
        arm is never moved by a reset). Returns :meth:`observe`."""
        super().reset(seed=seed, settle_s=settle_s)
        self._sync_from_bus()
        return self.observe()

    def load_state(self, path) -> None:
        """Restore the twin's world (objects) from ``path``; the arm from the bus (a dry run
        keeps the twin's simulated arm: it is the one that moved)."""
        super().load_state(path)
        if not self.dry_run:
            self._sync_from_bus()

    def _sync_from_bus(self) -> None:
        if self.arm is None:
            return
        q, _ = self.arm.read()
        self._mirror_pose(q)
        self.arm.guard.sync(np.append(q[:5], self._jaw_goal))

    # -- cameras: physical ones through OpenCV, the rest rendered by the twin ---------------------
    def configure_sensors(self, sensors) -> None:
        """Install ``sensors.yaml``'s sensors: cameras with a ``real`` block are opened with
        OpenCV (:class:`~.camera.OpenCVCamera`); the others are the twin's model cameras.

        Raises:
            TargetError: a real camera that does not open, or a model camera the twin lacks.
        """
        from .camera import OpenCVCamera  # noqa: PLC0415 - OpenCV only for real cameras

        real = [s for s in sensors if getattr(s, "real", None) is not None]
        super().configure_sensors([s for s in sensors if getattr(s, "real", None) is None])
        for cam in self._real_cams.values():
            cam.close()
        self._real_cams = {s.name: OpenCVCamera(s) for s in real}
        self._sensor_specs.update({s.name: s for s in real})

    def capture(self, sensor: str):
        """A frame of camera ``sensor``: a physical camera's (RGB, declared intrinsics and
        pose, no depth) or the twin's rendering."""
        cam = self._real_cams.get(sensor)
        if cam is not None:
            self._frame_count += 1
            return cam.capture(stamp_s=self.sim_time)
        return super().capture(sensor)

    def bus_events(self) -> list[dict]:
        """The bus guard's interventions so far (codes, outcomes, messages): evidence."""
        return list(self.arm.guard.events) if self.arm is not None else []

    def query_state(self) -> dict:
        out = super().query_state()
        if self.arm is not None:
            out["bus"] = {"port": self.arm.bus.port, "dry_run": self.dry_run, "stopped": self.arm.stopped,
                          "events": [{k: v for k, v in e.items() if k != "t"} for e in self.arm.guard.events][-20:],
                          "joint_names": list(MOTOR_NAMES),
                          "measured_q": [round(float(v), 4) for v in self.arm.last_q] if self.arm.last_q is not None
                          else None}
        return out

    def close(self) -> None:
        if self.arm is not None and not self.closed:
            self.arm.close()
        for cam in self._real_cams.values():
            cam.close()
        self._real_cams = {}
        super().close()

    def __repr__(self) -> str:
        port = self.arm.bus.port if self.arm is not None else None
        return f"SO101RealTarget(name={self.name!r}, port={port!r}, dry_run={getattr(self, 'dry_run', None)})"
