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

import io
import json
import logging
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.protocol.atomic import atomic_write_bytes

from .state_file import read_state_npz
from .base import BaseRolloutTarget, ExecutionResult
from .scene import (
    ARM_JOINT_NAMES,
    DEFAULT_SCENE,
    FINGER_ACTUATOR_NAMES,
    FINGER_BODY_NAMES,
    FINGER_JOINT_NAMES,
    GRIPPER_MAX_OPENING_M,
    HOME_QPOS,
    TABLE_GEOM,
    FLOOR_GEOM,
    TCP_SITE,
    SceneSpec,
    build_scene,
    object_joint_name,
)

__all__ = ["MuJoCoTarget", "GripperResult", "ExecutionResult", "MAX_GRIP_FORCE_N"]

log = logging.getLogger(__name__)

_TOOLS = ("observe", "move_joints", "set_gripper", "hold", "snapshot")
#: Largest grip force a close may command, N per finger (the finger actuators' force
#: limit in the shipped model; Franka Hand datasheet: 70 N continuous).
MAX_GRIP_FORCE_N = 70.0
_STATE_FORMAT = 1

# geom kinds for contact classification
_K_NONE, _K_ENV, _K_ROBOT, _K_FINGER, _K_OBJECT = 0, 1, 2, 3, 4


@dataclass(frozen=True)
class GripperResult:
    """Outcome of :meth:`MuJoCoTarget.set_gripper`.

    Attributes:
        opening_m: measured opening per finger after settling, metres (0 .. 0.04).
        stalled: the fingers stopped more than 2 mm short of the commanded opening
            (something is between them).
        grasped: name of the object touching both finger pads, else ``None``.
    """

    opening_m: float
    stalled: bool
    grasped: str | None

    def to_dict(self) -> dict[str, Any]:
        return {"opening_m": self.opening_m, "stalled": self.stalled, "grasped": self.grasped}


def _pose(xpos, xmat) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = xpos
    T[:3, :3] = np.asarray(xmat).reshape(3, 3)
    return T


class MuJoCoTarget(BaseRolloutTarget):
    """A simulated Franka Panda on a table, built from a :class:`SceneSpec`.

    Args:
        name: target name.
        scene: what is on the table (default :data:`DEFAULT_SCENE`).
        seed: seeds :attr:`rng` (a numpy Generator for perturbations); physics itself is
            deterministic.

    Raises:
        TargetError: the scene does not build.

    Class attributes (read by preflight without constructing a target):
        KIND: target kind as declared in TARGETS.md.
        TOOLS: operations a session may be granted.
        ACTION_FORMS: action representations the target executes natively.
    """

    KIND = "simulation"
    TOOLS = _TOOLS
    ACTION_FORMS = ("joint_trajectory", "gripper_command")

    def __init__(self, name: str, scene: SceneSpec = DEFAULT_SCENE, *, seed: int | None = None):
        super().__init__(name, "simulation")
        if not isinstance(scene, SceneSpec):
            raise TargetError(f"scene must be a SceneSpec, got {type(scene).__name__}")
        self._scene = scene
        self._model = build_scene(scene)
        self._data = mujoco.MjData(self._model)
        m = self._model
        self._jids = np.array([m.joint(n).id for n in ARM_JOINT_NAMES])
        self._qadr = m.jnt_qposadr[self._jids].copy()
        self._dadr = m.jnt_dofadr[self._jids].copy()
        acts = []
        for j in self._jids:
            found = [a for a in range(m.nu) if m.actuator_trnid[a, 0] == j]
            if not found:
                raise TargetError(f"no actuator drives joint {m.joint(int(j)).name!r}")
            acts.append(found[0])
        self._arm_act = np.array(acts)
        self._finger_act = np.array([m.actuator(n).id for n in FINGER_ACTUATOR_NAMES])
        self._finger_qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in FINGER_JOINT_NAMES])
        self._finger_dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in FINGER_JOINT_NAMES])
        self._kp = m.actuator_gainprm[self._arm_act, 0].copy()
        self._damping = m.dof_damping[self._dadr].copy()
        self._ff_gain = self._damping / self._kp
        self._ctrl_lo = m.actuator_ctrlrange[:, 0].copy()
        self._ctrl_hi = m.actuator_ctrlrange[:, 1].copy()
        self._tcp = m.site(TCP_SITE).id
        self._home = np.array(HOME_QPOS, dtype=float)
        self._home_key = m.key("home").id
        # objects
        self._obj_names = scene.object_names
        self._obj_body = {o.name: m.body(o.name).id for o in scene.objects}
        self._obj_qadr = {o.name: int(m.jnt_qposadr[m.joint(object_joint_name(o.name)).id]) for o in scene.objects}
        self._obj_dadr = {o.name: int(m.jnt_dofadr[m.joint(object_joint_name(o.name)).id]) for o in scene.objects}
        # geom classification
        robot_root = int(m.body_rootid[m.body("panda0_link1").id])
        finger_bodies = {m.body(n).id for n in FINGER_BODY_NAMES}
        body_obj = {b: name for name, b in self._obj_body.items()}
        kind = np.zeros(m.ngeom, dtype=np.int8)
        gobj = np.full(m.ngeom, -1, dtype=np.int32)
        for g in range(m.ngeom):
            if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0:
                continue
            b = int(m.geom_bodyid[g])
            if b in finger_bodies:
                kind[g] = _K_FINGER
            elif b != 0 and m.body_rootid[b] == robot_root:
                kind[g] = _K_ROBOT
            elif int(m.body_rootid[b]) in body_obj:
                kind[g] = _K_OBJECT
                gobj[g] = self._obj_names.index(body_obj[int(m.body_rootid[b])])
            else:
                kind[g] = _K_ENV
        self._gkind = kind
        self._gobj = gobj
        self._left_geoms = frozenset(g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body(FINGER_BODY_NAMES[0]).id and kind[g])
        self._right_geoms = frozenset(g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body(FINGER_BODY_NAMES[1]).id and kind[g])
        self._support_geoms = frozenset((m.geom(TABLE_GEOM).id, m.geom(FLOOR_GEOM).id))
        self._U_cache: dict[frozenset, np.ndarray] = {}  # held objects -> unexpected-contact matrix
        self._renderer = None
        self._rng = np.random.default_rng(seed)
        #: Target-local e-stop hook: any object with ``is_set()`` (the SafetyGuard's latch);
        #: trajectory streaming checks it every physics step and halts the arm when set.
        self.estop = None
        # Grip force: a position actuator squeezes with kp * (target - opening), so a
        # target below 0 (closed) is how a force is commanded; the finger joint range
        # still stops the fingers at 0.
        self._finger_kp = float(m.actuator_gainprm[self._finger_act[0], 0])
        m.actuator_ctrlrange[self._finger_act, 0] = -MAX_GRIP_FORCE_N / self._finger_kp
        self._ctrl_lo = m.actuator_ctrlrange[:, 0].copy()
        # Perturbations (phyagentos.targets.perturbations) change friction and mass;
        # nominal values are restored before the next session's are installed.
        self._obj_geom = {o.name: m.geom(o.name).id for o in scene.objects}
        self._nominal = (m.geom_friction.copy(), m.geom_priority.copy(), m.body_mass.copy(), m.body_inertia.copy())
        self._perturbations = None
        self.reset(seed=seed)

    # -- basic accessors --------------------------------------------------------------
    @property
    def model(self) -> mujoco.MjModel:
        """The compiled MuJoCo model (treat as read-only)."""
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The live MuJoCo data."""
        return self._data

    @property
    def scene(self) -> SceneSpec:
        return self._scene

    @property
    def rng(self) -> np.random.Generator:
        """numpy Generator seeded by ``reset(seed=...)`` for perturbations."""
        return self._rng

    @property
    def arm_joint_names(self) -> tuple[str, ...]:
        return ARM_JOINT_NAMES

    @property
    def home_qpos(self) -> np.ndarray:
        """``(7,)`` rad ready configuration: tcp ~0.37 m above the table, pointing down."""
        return self._home.copy()

    @property
    def sim_time(self) -> float:
        """Simulated time in seconds since the last reset (or loaded state)."""
        return float(self._data.time)

    @property
    def timestep(self) -> float:
        return float(self._model.opt.timestep)

    @property
    def feedforward_gain(self) -> np.ndarray:
        """``(7,)`` s: joint damping / actuator kp, read from the model."""
        return self._ff_gain.copy()

    def arm_qpos(self) -> np.ndarray:
        """``(7,)`` current arm joint angles, rad."""
        return self._data.qpos[self._qadr].copy()

    def arm_qvel(self) -> np.ndarray:
        """``(7,)`` current arm joint velocities, rad/s."""
        return self._data.qvel[self._dadr].copy()

    def gripper_opening(self) -> float:
        """Current opening per finger in metres (0 closed .. 0.04 open)."""
        return float(np.mean(self._data.qpos[self._finger_qadr]))

    def tcp_pose(self) -> np.ndarray:
        """``(4, 4)`` world pose of the ``tcp`` site."""
        d = self._data
        return _pose(d.site_xpos[self._tcp], d.site_xmat[self._tcp])

    def object_pose(self, name: str) -> np.ndarray:
        """``(4, 4)`` world pose of object ``name``; TargetError listing objects if unknown."""
        b = self._obj_body.get(name)
        if b is None:
            raise TargetError(f"unknown object {name!r}; objects: {format_choices(self._obj_names)}")
        d = self._data
        return _pose(d.xpos[b], d.xmat[b])

    def velocity_limits(self, torque_fraction: float = 0.6) -> np.ndarray:
        """``(7,)`` rad/s the simulated actuators sustain with feed-forward (see
        :func:`phyagentos.motion.retime.actuator_velocity_limits`)."""
        from phyagentos.motion.retime import actuator_velocity_limits  # noqa: PLC0415

        return actuator_velocity_limits(self._model, ARM_JOINT_NAMES, torque_fraction=torque_fraction)

    # -- lifecycle --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, settle_s: float = 0.3) -> dict:
        """Arm at :attr:`home_qpos`, gripper open, objects at their spec poses; physics
        settles for ``settle_s`` simulated seconds, then the clock restarts at 0.
        ``seed`` re-seeds :attr:`rng` only. Returns :meth:`observe`."""
        self._check_open()
        self._rng = np.random.default_rng(seed)
        m, d = self._model, self._data
        mujoco.mj_resetDataKeyframe(m, d, self._home_key)
        mujoco.mj_forward(m, d)
        for _ in range(int(round(settle_s / m.opt.timestep))):
            mujoco.mj_step(m, d)
        d.time = 0.0
        mujoco.mj_forward(m, d)
        return self.observe()

    def close(self) -> None:
        if self._renderer is not None:
            try:
                self._renderer.close()
            except Exception:  # pragma: no cover
                pass
            self._renderer = None
        super().close()

    def _check_open(self) -> None:
        if self.closed:
            raise TargetError(f"target {self.name!r} is closed")

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

    # -- contacts ---------------------------------------------------------------------
    def _finger_contacts(self) -> tuple[set[int], set[int]]:
        """Objects (indices) touching the left and right finger geoms."""
        d = self._data
        left: set[int] = set()
        right: set[int] = set()
        n = d.ncon
        if n == 0:
            return left, right
        geoms = d.contact.geom
        dist = d.contact.dist
        for i in range(n):
            if dist[i] > 1e-4:
                continue
            g0, g1 = int(geoms[i, 0]), int(geoms[i, 1])
            for a, b in ((g0, g1), (g1, g0)):
                o = int(self._gobj[b])
                if o < 0:
                    continue
                if a in self._left_geoms:
                    left.add(o)
                elif a in self._right_geoms:
                    right.add(o)
        return left, right

    def held_objects(self) -> tuple[str, ...]:
        """Objects in contact with both finger pads."""
        left, right = self._finger_contacts()
        return tuple(self._obj_names[i] for i in sorted(left & right))

    def _unexpected_matrix(self, held: set[int]) -> np.ndarray:
        """(ngeom, ngeom) bool: True where a contact between the two geoms is unexpected."""
        k = self._gkind
        o = self._gobj
        robotish = (k == _K_ROBOT) | (k == _K_FINGER)
        collides = k != _K_NONE
        U = np.zeros((len(k), len(k)), dtype=bool)
        U |= robotish[:, None] & collides[None, :]
        U |= U.T
        held_mask = np.array([oi in held for oi in o]) & (k == _K_OBJECT)
        fingers = k == _K_FINGER
        U[np.ix_(fingers, held_mask)] = False
        U[np.ix_(held_mask, fingers)] = False
        obstacles = (k == _K_ENV) & ~np.isin(np.arange(len(k)), list(self._support_geoms))
        U[np.ix_(held_mask, obstacles)] = True
        U[np.ix_(obstacles, held_mask)] = True
        return U

    def _geom_label(self, g: int) -> str:
        m = self._model
        k = self._gkind[g]
        if k in (_K_ROBOT, _K_FINGER):
            return m.body(int(m.geom_bodyid[g])).name
        if k == _K_OBJECT:
            return self._obj_names[int(self._gobj[g])]
        return m.geom(g).name or m.body(int(m.geom_bodyid[g])).name

    # -- trajectory execution -----------------------------------------------------------
    @staticmethod
    def _traj_arrays(traj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(traj.t, dtype=float).reshape(-1)
        Q = np.asarray(traj.q, dtype=float)
        QD = np.asarray(getattr(traj, "qd", np.zeros_like(Q)), dtype=float)
        if len(t) < 1 or Q.shape != (len(t), 7) or QD.shape != Q.shape:
            raise TargetError(f"trajectory must have t (M,), q and qd (M, 7); got {t.shape}, {Q.shape}, {QD.shape}")
        if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(QD)) and np.all(np.isfinite(t))):
            raise TargetError("trajectory contains non-finite values")
        return t - t[0], Q, QD

    def _check_start(self, Q0: np.ndarray, tracking_tol_rad: float) -> None:
        start_err = float(np.max(np.abs(Q0 - self.arm_qpos())))
        allowed = max(tracking_tol_rad, 0.02)
        if start_err > allowed:
            raise TargetError(
                f"trajectory starts {start_err:.3f} rad from the current arm configuration (allowed {allowed:.3f} rad)"
            )

    def _unexpected_for_current_grasp(self) -> np.ndarray:
        left, right = self._finger_contacts()
        key = frozenset(left & right)
        U = self._U_cache.get(key)
        if U is None:
            U = self._U_cache[key] = self._unexpected_matrix(set(key))
        return U

    def _collect_contacts(self, U: np.ndarray, bad_pairs: set) -> None:
        d = self._data
        if d.ncon:
            g = d.contact.geom
            hit = U[g[:, 0], g[:, 1]] & (d.contact.dist < 0.0)
            if hit.any():
                for i in np.nonzero(hit)[0]:
                    bad_pairs.add((int(g[i, 0]), int(g[i, 1])))

    def _contact_names(self, bad_pairs: set) -> tuple[tuple[str, str], ...]:
        out = tuple(sorted({tuple(sorted((self._geom_label(a), self._geom_label(b)))) for a, b in bad_pairs}))
        if out:
            log.info("unexpected contacts during execution: %s", out)
        return out  # type: ignore[return-value]

    def _stream(self, t, Q, QD, times, tracking_tol_rad, feedforward, bad_pairs) -> tuple[bool, float, int, str]:
        """Step once per entry of ``times`` (s, trajectory clock) with the interpolated
        reference; returns (completed, max error, steps, reason)."""
        m, d = self._model, self._data
        n = len(times)
        if n == 0:
            return True, 0.0, 0, ""
        Qr = np.column_stack([np.interp(times, t, Q[:, j]) for j in range(7)])
        QDr = np.column_stack([np.interp(times, t, QD[:, j]) for j in range(7)])
        ff = self._ff_gain if feedforward else np.zeros(7)
        lo, hi = self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act]
        C = np.clip(Qr + ff * QDr, lo, hi)
        U = self._unexpected_for_current_grasp()
        arm_act, qadr = self._arm_act, self._qadr
        ctrl, qpos = d.ctrl, d.qpos
        max_err = 0.0
        estop = self.estop
        for k in range(n):
            if estop is not None and estop.is_set():
                ctrl[arm_act] = np.clip(qpos[qadr], lo, hi)  # halt: stay where we are
                return False, max_err, k, f"e-stop at t={times[k]:.3f} s"
            ctrl[arm_act] = C[k]
            mujoco.mj_step(m, d)
            err = float(np.max(np.abs(qpos[qadr] - Qr[k])))
            if err > max_err:
                max_err = err
            self._collect_contacts(U, bad_pairs)
            if err > tracking_tol_rad:
                ctrl[arm_act] = np.clip(qpos[qadr], lo, hi)  # stop where we are
                reason = (
                    f"tracking error {err:.4f} rad exceeded {tracking_tol_rad:.4f} rad at "
                    f"t={times[k]:.3f} s of {float(t[-1]):.3f} s"
                )
                return False, max_err, k + 1, reason
        return True, max_err, n, ""

    def execute_trajectory(
        self,
        traj,
        *,
        tracking_tol_rad: float = 0.05,
        feedforward: bool = True,
        settle_s: float = 0.5,
        settle_tol_rad: float = 0.005,
    ) -> ExecutionResult:
        """Stream a timed joint trajectory to the arm's position actuators, then settle.

        Each physics step gets ``ctrl = q_ref + (b / kp) * qd_ref`` (linear
        interpolation of the trajectory at the step's end time; ``b`` joint damping and
        ``kp`` actuator gain read from the model).

        Args:
            traj: object with ``t`` (M,) s, ``q`` (M, 7) rad and ``qd`` (M, 7) rad/s
                (e.g. :class:`phyagentos.motion.retime.Trajectory`); ``q[0]`` must be
                within ``max(tracking_tol_rad, 0.02)`` rad of the current arm configuration.
            tracking_tol_rad: stop early (``completed=False``, arm held where it is) when
                any joint is farther than this from the reference.
            feedforward: add the damping velocity feed-forward; ``False`` streams bare
                positions (for comparison).
            settle_s: after the last sample, hold the final configuration until the arm is
                within ``settle_tol_rad`` and nearly still, at most this long.
            settle_tol_rad: settling tolerance, rad.

        Returns:
            :class:`ExecutionResult`; ``contacts`` lists unexpected contact pairs (robot
            against anything except a held object in the fingers, or a held object
            against an obstacle).

        Raises:
            TargetError: malformed trajectory or a start far from the current state.
        """
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        self._check_start(Q[0], tracking_tol_rad)
        ts = self._model.opt.timestep
        duration = float(t[-1])
        n = int(math.ceil(duration / ts - 1e-9)) if duration > 0 else 0
        times = np.minimum((np.arange(n) + 1) * ts, duration)
        t0 = self._data.time
        bad: set = set()
        completed, max_err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, feedforward, bad)
        if completed:
            steps += self.settle(Q[-1], settle_s=settle_s, tol_rad=settle_tol_rad, _contacts=bad)
        return ExecutionResult(
            completed=completed,
            max_tracking_error_rad=max_err,
            sim_time_s=float(self._data.time - t0),
            steps=steps,
            contacts=self._contact_names(bad),
            reason=reason,
        )

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
        duration = float(t[-1])
        t_end = min(float(t_end), duration)
        ts = self._model.opt.timestep
        n = max(0, int(round((t_end - max(t_start, 0.0)) / ts)))
        times = np.minimum(max(t_start, 0.0) + (np.arange(n) + 1) * ts, duration)
        if n and t_end >= duration - 1e-12:
            times[-1] = duration
        t0 = self._data.time
        bad: set = set()
        completed, max_err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, feedforward, bad)
        return ExecutionResult(
            completed=completed,
            max_tracking_error_rad=max_err,
            sim_time_s=float(self._data.time - t0),
            steps=steps,
            contacts=self._contact_names(bad),
            reason=reason,
        )

    def settle(
        self,
        q: Sequence[float] | None = None,
        *,
        settle_s: float = 0.5,
        tol_rad: float = 0.005,
        _contacts: set | None = None,
    ) -> int:
        """Command the arm to ``q`` (7,) rad (default: the current command) and step
        until it is within ``tol_rad`` and slower than 0.02 rad/s, at most ``settle_s``
        simulated seconds. Returns the number of steps."""
        self._check_open()
        m, d = self._model, self._data
        lo, hi = self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act]
        if q is not None:
            q_end = np.asarray(q, dtype=float).reshape(-1)
            if q_end.shape != (7,):
                raise TargetError(f"settle: q must have shape (7,), got {q_end.shape}")
            d.ctrl[self._arm_act] = np.clip(q_end, lo, hi)
        else:
            q_end = d.ctrl[self._arm_act].copy()
        U = self._unexpected_for_current_grasp() if _contacts is not None else None
        qadr, dadr = self._qadr, self._dadr
        steps = 0
        for _ in range(int(round(settle_s / m.opt.timestep))):
            mujoco.mj_step(m, d)
            steps += 1
            if U is not None:
                self._collect_contacts(U, _contacts)  # type: ignore[arg-type]
            if float(np.max(np.abs(d.qpos[qadr] - q_end))) < tol_rad and float(np.max(np.abs(d.qvel[dadr]))) < 0.02:
                break
        return steps

    def hold(self, q: Sequence[float] | None = None, *, duration_s: float) -> int:
        """Hold the arm at ``q`` (7,) rad (default: where it is now) for ``duration_s``
        simulated seconds. Returns the number of steps."""
        self._check_open()
        target_q = self.arm_qpos() if q is None else np.asarray(q, dtype=float).reshape(-1)
        if target_q.shape != (7,) or not np.all(np.isfinite(target_q)):
            raise TargetError(f"hold: q must be 7 finite joint angles, got {q!r}")
        return self.step_for(duration_s, arm_ctrl=target_q)

    def halt(self) -> None:
        """Stop: command the arm to stay where it is (velocity feed-forward dropped)."""
        if self.closed:
            return
        lo, hi = self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act]
        self._data.ctrl[self._arm_act] = np.clip(self.arm_qpos(), lo, hi)

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
        held = self.held_objects()
        return GripperResult(opening_m=opening, stalled=abs(opening - o) > 0.002, grasped=held[0] if held else None)

    # -- perception and perturbations (phyagentos.targets.perturbations) ---------------
    @property
    def perturbations(self):
        """The session's :class:`~phyagentos.targets.perturbations.ActivePerturbations`, or ``None``."""
        return self._perturbations

    def set_perturbations(self, active) -> None:
        """Restore nominal friction and mass, then install ``active`` (``None``: none).

        Called by the target pool for every session, since a target outlives its sessions.
        """
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

    # -- observation ------------------------------------------------------------------
    def observe(self) -> dict:
        """Current observation.

        Keys: ``time`` (s), ``arm_qpos`` (7,) rad, ``arm_qvel`` (7,) rad/s,
        ``gripper_opening_m`` (per finger), ``tcp_pose`` (4, 4), ``objects``
        {name: (4, 4) pose}, ``qpos`` (nq,) full configuration (for collision checkers),
        ``held`` tuple of held object names.
        """
        self._check_open()
        return {
            "time": self.sim_time,
            "arm_qpos": self.arm_qpos(),
            "arm_qvel": self.arm_qvel(),
            "gripper_opening_m": self.gripper_opening(),
            "tcp_pose": self.tcp_pose(),
            "objects": {n: self.object_pose(n) for n in self._obj_names},
            "qpos": self._data.qpos.copy(),
            "held": self.held_objects(),
        }

    def query_state(self) -> dict:
        """JSON-ready state: target name/kind, ``sim_time_s``, ``arm_qpos``,
        ``gripper_opening_m``, ``tcp`` {position, quat_wxyz}, ``objects`` {name:
        {position, quat_wxyz}}, ``relations`` (as in :meth:`snapshot`)."""
        self._check_open()
        snap = self.snapshot()
        tcp = next(e for e in snap["entities"] if e["kind"] == "robot")
        return {
            "target": self.name,
            "kind": self.kind,
            "sim_time_s": self.sim_time,
            "arm_qpos": [float(x) for x in self.arm_qpos()],
            "gripper_opening_m": self.gripper_opening(),
            "tcp": {"position": tcp["position"], "quat_wxyz": tcp["quat_wxyz"]},
            "objects": {
                e["name"]: {"position": e["position"], "quat_wxyz": e["quat_wxyz"]}
                for e in snap["entities"]
                if e["kind"] == "object"
            },
            "relations": snap["relations"],
        }

    def _quat(self, R) -> list[float]:
        q = np.empty(4)
        mujoco.mju_mat2Quat(q, np.asarray(R, dtype=float).reshape(-1))
        return [float(x) for x in q]

    def _object_bottom_z(self, name: str) -> tuple[float, float]:
        """(bottom z, top z) of an object's box in the world, metres."""
        T = self.object_pose(name)
        he = np.array(self._scene.object(name).half_extents)
        ext = float(np.abs(T[2, :3]) @ he)
        return float(T[2, 3] - ext), float(T[2, 3] + ext)

    def snapshot(self) -> dict:
        """Symbolic world state, plain Python types only (YAML/JSON ready).

        Returns ``{"sim_time_s": s, "time": s, "entities": [...], "relations": [...]}``.
        Entities: ``{"name", "kind", "position" (3,) m, "quat_wxyz" (4,), "size" (3,),
        "attributes"}`` with ``size`` the half extents in metres (MuJoCo's box
        convention), for the arm (``name='panda'``, kind ``robot``, attributes
        ``joint_positions`` (7,) rad and ``gripper_opening_m``), the robot tcp
        (``name='tcp'``, kind ``robot``, size 0), the gripper (kind ``gripper``,
        ``size[0]`` and ``attributes.opening_m`` = opening per finger), every object (kind
        ``object``), region (kind ``region``, z half extent 0) and obstacle (kind
        ``obstacle``); positions and orientations are world frame. Relations are
        ``{"subject", "relation", "object"}``:

        - ``gripper holding X``: X touches both finger pads;
        - ``X on table``: X rests on the table (bottom within 5 mm of z = 0);
        - ``X on R`` (region): X rests on the table and its footprint overlaps R;
        - ``X inside R``: X rests on the table and its centre is inside R's footprint;
        - ``X on Y`` (object): X's bottom is within 6 mm of Y's top and X's centre lies
          over Y's footprint.
        """
        self._check_open()
        d = self._data
        tcp = self.tcp_pose()
        opening = self.gripper_opening()
        ents: list[dict] = [
            {
                "name": "panda",
                "kind": "robot",
                "position": [0.0, 0.0, 0.0],
                "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                "size": [0.0, 0.0, 0.0],
                "attributes": {
                    "joint_positions": [round(float(q), 6) for q in self.arm_qpos()],
                    "gripper_opening_m": round(opening, 6),
                },
            },
            {
                "name": "tcp",
                "kind": "robot",
                "position": [float(x) for x in tcp[:3, 3]],
                "quat_wxyz": self._quat(tcp[:3, :3]),
                "size": [0.0, 0.0, 0.0],
            },
            {
                "name": "gripper",
                "kind": "gripper",
                "position": [float(x) for x in tcp[:3, 3]],
                "quat_wxyz": self._quat(tcp[:3, :3]),
                "size": [opening, 0.0, 0.0],
                "attributes": {"opening_m": round(opening, 6)},
            },
        ]
        for o in self._scene.objects:
            T = self.object_pose(o.name)
            ents.append(
                {
                    "name": o.name,
                    "kind": "object",
                    "position": [float(x) for x in T[:3, 3]],
                    "quat_wxyz": self._quat(T[:3, :3]),
                    "size": [float(h) for h in o.half_extents],
                }
            )
        for r in self._scene.regions:
            ents.append(
                {
                    "name": r.name,
                    "kind": "region",
                    "position": [float(r.center[0]), float(r.center[1]), 0.0],
                    "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                    "size": [float(r.half_extents[0]), float(r.half_extents[1]), 0.0],
                }
            )
        for ob in self._scene.obstacles:
            ents.append(
                {
                    "name": ob.name,
                    "kind": "obstacle",
                    "position": [float(c) for c in ob.center],
                    "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                    "size": [float(h) for h in ob.half_extents],
                }
            )
        rel: list[dict] = []
        held = set(self.held_objects())
        for name in sorted(held):
            rel.append({"subject": "gripper", "relation": "holding", "object": name})
        extents = {}
        for o in self._scene.objects:
            extents[o.name] = self._object_bottom_z(o.name)
        for o in self._scene.objects:
            if o.name in held:
                continue
            T = self.object_pose(o.name)
            xy = T[:2, 3]
            bottom, _ = extents[o.name]
            on_table = abs(bottom) < 0.005
            if on_table:
                rel.append({"subject": o.name, "relation": "on", "object": "table"})
                foot = max(o.half_extents[0], o.half_extents[1])
                for r in self._scene.regions:
                    if r.contains_xy(xy):
                        rel.append({"subject": o.name, "relation": "on", "object": r.name})
                        rel.append({"subject": o.name, "relation": "inside", "object": r.name})
                    elif r.contains_xy(xy, margin_m=-foot):
                        rel.append({"subject": o.name, "relation": "on", "object": r.name})
            for other in self._scene.objects:
                if other.name == o.name:
                    continue
                _, top = extents[other.name]
                To = self.object_pose(other.name)
                dxy = np.abs(xy - To[:2, 3])
                if abs(bottom - top) < 0.006 and dxy.max() <= max(other.half_extents[:2]) + 1e-3:
                    rel.append({"subject": o.name, "relation": "on", "object": other.name})
        return {"sim_time_s": float(d.time), "time": float(d.time), "entities": ents, "relations": rel}

    # -- persistence ----------------------------------------------------------------
    def _fingerprint(self) -> str:
        m = self._model
        return json.dumps({"nq": m.nq, "nv": m.nv, "nu": m.nu, "na": m.na, "scene": self._scene.to_dict()}, sort_keys=True)

    def save_state(self, path: str | os.PathLike) -> Path:
        """Write the simulated state to ``path`` (npz with ``qpos``, ``qvel``, ``ctrl``,
        ``act``, ``time``, plus MuJoCo's full integration state and a model fingerprint).
        The write is atomic (temporary file + rename). Returns the path."""
        self._check_open()
        m, d = self._model, self._data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, full, spec)
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez(
            buf,
            format=np.array(_STATE_FORMAT),
            qpos=d.qpos.copy(),
            qvel=d.qvel.copy(),
            ctrl=d.ctrl.copy(),
            act=d.act.copy(),
            time=np.array(d.time),
            full_state=full,
            fingerprint=np.array(self._fingerprint()),
        )
        atomic_write_bytes(p, buf.getvalue())  # temp file, fsync, rename, dir fsync
        return p

    def load_state(self, path: str | os.PathLike) -> None:
        """Restore a state written by :meth:`save_state` for the same scene.
        Raises TargetError if the file is missing, malformed or from another scene."""
        self._check_open()
        m, d = self._model, self._data
        p = Path(path)
        data = read_state_npz(p)
        missing = [k for k in ("qpos", "qvel", "ctrl", "act", "time") if k not in data]
        if missing:
            raise TargetError(f"state file {p} lacks {', '.join(missing)}")
        if "fingerprint" in data and str(data["fingerprint"]) != self._fingerprint():
            raise TargetError(f"state file {p} was saved from a different scene or model")
        for k, n in (("qpos", m.nq), ("qvel", m.nv), ("ctrl", m.nu), ("act", m.na)):
            if data[k].shape != (n,):
                raise TargetError(f"state file {p}: {k} has shape {data[k].shape}, expected ({n},)")
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = data.get("full_state")
        if full is not None and full.shape == (mujoco.mj_stateSize(m, spec),):
            mujoco.mj_setState(m, d, full, spec)
        else:
            d.qpos[:] = data["qpos"]
            d.qvel[:] = data["qvel"]
            d.ctrl[:] = data["ctrl"]
            d.act[:] = data["act"]
            d.time = float(data["time"])
        mujoco.mj_forward(m, d)

    # -- rendering --------------------------------------------------------------------
    def render(self, camera: str = "overview", width: int = 640, height: int = 480, *,
               shadows: bool = True) -> np.ndarray:
        """``(height, width, 3)`` uint8 image from ``camera``; ``shadows=False`` renders
        about 5x faster under OSMesa (evidence snapshots use it). Raises TargetError if no
        OpenGL backend is available or the camera is unknown."""
        self._check_open()
        m = self._model
        cams = [m.camera(i).name for i in range(m.ncam)]
        if camera not in cams:
            raise TargetError(f"unknown camera {camera!r}; cameras: {format_choices(cams)}")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # glfw warns before failing without a display
                if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
                    if self._renderer is not None:
                        self._renderer.close()
                    self._renderer = mujoco.Renderer(m, height=height, width=width)
                self._renderer.update_scene(self._data, camera=camera)
                self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = bool(shadows)
                return self._renderer.render().copy()
        except Exception as exc:
            self._renderer = None
            raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc

    # -- tools ----------------------------------------------------------------------
    def tools(self) -> tuple[str, ...]:
        """``('observe', 'move_joints', 'set_gripper', 'hold', 'snapshot')``."""
        return _TOOLS

    def _tool_observe(self) -> dict:
        return self.query_state()

    def _tool_move_joints(self, q: Sequence[float], tracking_tol_rad: float = 0.05, speed_scale: float = 1.0) -> dict:
        """Straight joint-space move to ``q`` (7,) rad, time-optimal within the
        actuators' velocity limits (scaled by ``speed_scale``); no collision checking."""
        from phyagentos.motion.retime import DEFAULT_ACCELERATION_LIMITS, retime  # noqa: PLC0415

        qg = np.asarray(q, dtype=float).reshape(-1)
        if qg.shape != (7,) or not np.all(np.isfinite(qg)):
            raise TargetError(f"move_joints: q must be 7 finite joint angles, got {q!r}")
        lo = self._model.jnt_range[self._jids, 0]
        hi = self._model.jnt_range[self._jids, 1]
        if np.any(qg < lo) or np.any(qg > hi):
            raise TargetError(f"move_joints: q outside the joint limits {lo.round(3).tolist()} .. {hi.round(3).tolist()}")
        if not 0 < speed_scale <= 1.0:
            raise TargetError(f"move_joints: speed_scale must be in (0, 1], got {speed_scale}")
        traj = retime(
            np.array([self.arm_qpos(), qg]),
            vel_limits=self.velocity_limits() * speed_scale,
            acc_limits=np.array(DEFAULT_ACCELERATION_LIMITS) * speed_scale,
            dt=self.timestep,
        )
        return self.execute_trajectory(traj, tracking_tol_rad=tracking_tol_rad).to_dict()

    def _tool_set_gripper(self, opening_m: float, settle_s: float = 0.5, force_n: float | None = None) -> dict:
        return self.set_gripper(opening_m=opening_m, settle_s=settle_s, force_n=force_n).to_dict()

    def _tool_hold(self, duration_s: float = 0.5, q: Sequence[float] | None = None) -> dict:
        """Hold ``q`` (default: the current configuration) for ``duration_s`` s."""
        n = self.hold(q, duration_s=duration_s)
        return {"steps": n, "sim_time_s": self.sim_time}

    def _tool_snapshot(self) -> dict:
        return self.snapshot()
