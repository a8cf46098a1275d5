"""Time-optimal parameterisation of joint paths with toppra.

The waypoints are interpolated by a cubic spline in the joint-space arc length ``s``
(``toppra.SplineInterpolator``); TOPP-RA computes the fastest path velocity profile
subject to ``JointVelocityConstraint`` and ``JointAccelerationConstraint`` on a grid of
``s`` values and ``ParametrizeConstAccel`` turns it into a trajectory with piecewise
constant path acceleration. The trajectory is then sampled every ``dt`` seconds
(vectorised here rather than with toppra's per-sample loop).

Limits are only imposed at the grid points, so the samples are checked afterwards and,
if any joint exceeds a limit between grid points, the whole trajectory is slowed down by
uniform time scaling (which keeps the path and scales velocity by 1/k and acceleration
by 1/k^2), so the returned samples always respect the limits.

A cubic spline through polyline corners bulges a little (it may cut a corner or
overshoot it). When a ``checker`` is given the sampled trajectory is re-checked for
collisions; if it collides the path is densified (midpoints inserted, which pulls the
spline towards the straight segments) and re-timed, a few times, before
:class:`TimingError` is raised.

Franka limits (Franka Control Interface documentation, "Robot and interface
specifications", limits in joint space; https://frankaemika.github.io/docs/control_parameters.html):

- velocity (rad/s): 2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61 (:data:`FRANKA_VELOCITY_LIMITS`)
- acceleration (rad/s^2): 15, 7.5, 10, 12.5, 15, 20, 20 (:data:`FRANKA_ACCELERATION_LIMITS`)

:data:`DEFAULT_ACCELERATION_LIMITS` is the datasheet scaled by 0.25. Reason: the datasheet
values are the hardware's maximum; the simulated arm is driven by position actuators
whose torque limits (87 Nm / 12 Nm) must also cover the damping feed-forward, and the
tracking error from un-modelled inertia grows with ``M(q) q_dd / kp``; a quarter of
the datasheet keeps that below ~0.01 rad and the motion smooth (no saturation).
The same torque budget limits the sustainable joint velocity in the simulated model to
``forcerange / damping`` (0.87 rad/s for joints 1-4, 1.2 rad/s for 5-7); see
:func:`actuator_velocity_limits`.
"""

from __future__ import annotations

import importlib
import logging
import math
import sys
import types
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from phyagentos.errors import TimingError


def _defer_pyplot() -> None:
    """Let toppra import without ``matplotlib.pyplot``.

    toppra 0.6 imports ``matplotlib.pyplot`` at module level (``toppra/parametrizer.py``,
    ``toppra/algorithm/algorithm.py``) for plotting helpers that PhyAgentOS never calls.
    pyplot is about 0.35 s of the 0.53 s that ``import toppra`` costs (``python -X
    importtime``, this repository's 2-core machine), paid by every forkserver and every
    process that plans a motion. Until pyplot is imported by someone else, a placeholder
    module stands in for it: the first attribute read on the placeholder imports the real
    pyplot, puts it in ``sys.modules`` in the placeholder's place and answers from it, so
    a caller that does use pyplot (toppra's ``plot_*``, a benchmark figure) gets the real
    module one import later.
    """
    name = "matplotlib.pyplot"
    if name in sys.modules:
        return
    placeholder = types.ModuleType(name, "Stands in for matplotlib.pyplot until first use "
                                         "(phyagentos.motion.retime._defer_pyplot).")

    def __getattr__(attr: str) -> Any:
        if sys.modules.get(name) is placeholder:
            del sys.modules[name]
        return getattr(importlib.import_module(name), attr)

    placeholder.__getattr__ = __getattr__  # type: ignore[method-assign]
    sys.modules[name] = placeholder


_defer_pyplot()

import toppra as ta  # noqa: E402 - after the pyplot placeholder is in place
import toppra.algorithm as algo  # noqa: E402
import toppra.constraint as constraint  # noqa: E402

__all__ = [
    "Trajectory",
    "retime",
    "FRANKA_VELOCITY_LIMITS",
    "FRANKA_ACCELERATION_LIMITS",
    "DEFAULT_ACCELERATION_LIMITS",
    "actuator_velocity_limits",
    "franka_limits",
]

log = logging.getLogger(__name__)

#: Franka datasheet joint velocity limits, rad/s (joints 1..7).
FRANKA_VELOCITY_LIMITS: tuple[float, ...] = (2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61)
#: Franka datasheet joint acceleration limits, rad/s^2 (joints 1..7).
FRANKA_ACCELERATION_LIMITS: tuple[float, ...] = (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
#: Conservative default: datasheet accelerations x 0.25, rad/s^2.
DEFAULT_ACCELERATION_LIMITS: tuple[float, ...] = tuple(0.25 * a for a in FRANKA_ACCELERATION_LIMITS)


@dataclass(frozen=True)
class Trajectory:
    """A timed joint trajectory sampled on a fixed grid.

    Attributes:
        t: ``(M,)`` seconds from the start, ``t[0] == 0``, increasing.
        q: ``(M, 7)`` joint positions, rad.
        qd: ``(M, 7)`` joint velocities, rad/s.
        qdd: ``(M, 7)`` joint accelerations, rad/s^2.

    Arrays are stored read-only. ``M >= 1``; a single sample means "stay here".
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    def __post_init__(self) -> None:
        arrs = {}
        for name in ("t", "q", "qd", "qdd"):
            a = np.array(getattr(self, name), dtype=float)
            a.setflags(write=False)
            arrs[name] = a
        t, q = arrs["t"], arrs["q"]
        if t.ndim != 1 or len(t) < 1:
            raise TimingError(f"Trajectory.t must be a non-empty 1-D array, got shape {t.shape}")
        for name in ("q", "qd", "qdd"):
            if arrs[name].ndim != 2 or arrs[name].shape[0] != len(t) or arrs[name].shape != q.shape:
                raise TimingError(f"Trajectory.{name} must have shape ({len(t)}, dof), got {arrs[name].shape}")
        if len(t) > 1 and np.any(np.diff(t) <= 0):
            raise TimingError("Trajectory.t must be strictly increasing")
        for name, a in arrs.items():
            object.__setattr__(self, name, a)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last sample."""
        return float(self.t[-1] - self.t[0])

    @property
    def dof(self) -> int:
        return int(self.q.shape[1])

    def __len__(self) -> int:
        return len(self.t)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Linearly interpolated ``(q (7,), qd (7,))`` at time ``t`` s (clamped to the ends)."""
        if t <= self.t[0]:
            return self.q[0].copy(), self.qd[0].copy()
        if t >= self.t[-1]:
            return self.q[-1].copy(), self.qd[-1].copy()
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        a = (t - self.t[i]) / (self.t[i + 1] - self.t[i])
        return (1 - a) * self.q[i] + a * self.q[i + 1], (1 - a) * self.qd[i] + a * self.qd[i + 1]


def franka_limits() -> tuple[np.ndarray, np.ndarray]:
    """Franka datasheet limits as arrays: ``(velocity (7,) rad/s, acceleration (7,) rad/s^2)``.

    These are the hardware maxima; scale them down for execution (see the module
    docstring, :data:`DEFAULT_ACCELERATION_LIMITS`, and, for the MuJoCo model,
    :func:`actuator_velocity_limits`).
    """
    return np.array(FRANKA_VELOCITY_LIMITS), np.array(FRANKA_ACCELERATION_LIMITS)


#: The MuJoCo Franka's arm joints (gymnasium-robotics' model), in order.
_FRANKA_JOINT_NAMES: tuple[str, ...] = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))


def actuator_velocity_limits(
    model,
    joint_names: Sequence[str] = _FRANKA_JOINT_NAMES,
    *,
    torque_fraction: float = 0.6,
    datasheet: Sequence[float] = FRANKA_VELOCITY_LIMITS,
) -> np.ndarray:
    """Joint speeds (7,) rad/s the simulated position actuators can sustain.

    A position actuator tracking ``q_dot`` with damping feed-forward must produce the
    torque ``b q_dot`` (joint damping ``b``); only ``torque_fraction`` of its force range
    is spent on that, the rest stays available for acceleration. Returns
    ``min(datasheet, torque_fraction * forcerange / b)`` per joint, all read from
    ``model``.
    """
    import mujoco  # noqa: PLC0415

    out = np.array(datasheet, dtype=float)
    for i, name in enumerate(joint_names):
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise TimingError(f"unknown joint {name!r}")
        b = float(model.dof_damping[model.jnt_dofadr[jid]])
        acts = [a for a in range(model.nu) if model.actuator_trnid[a, 0] == jid]
        if b <= 0 or not acts:
            continue
        a = acts[0]
        if model.actuator_forcelimited[a]:
            fmax = float(min(abs(model.actuator_forcerange[a, 0]), abs(model.actuator_forcerange[a, 1])))
            out[i] = min(out[i], torque_fraction * fmax / b)
    return out


def _dedupe(P: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    keep = [0]
    for k in range(1, len(P)):
        if np.max(np.abs(P[k] - P[keep[-1]])) > eps:
            keep.append(k)
    return P[keep]


def _densify(P: np.ndarray) -> np.ndarray:
    out = np.empty((2 * len(P) - 1, P.shape[1]))
    out[0::2] = P
    out[1::2] = 0.5 * (P[:-1] + P[1:])
    return out


def _toppra(P: np.ndarray, v: np.ndarray, a: np.ndarray, dt: float, grid_step: float, dynamics=None):
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    path = ta.SplineInterpolator(s, P)
    n_grid = int(np.clip(math.ceil(s[-1] / grid_step), 60, 2000)) + 1
    grid = np.unique(np.concatenate([np.linspace(0.0, s[-1], n_grid), s]))
    pc_vel = constraint.JointVelocityConstraint(np.column_stack([-v, v]))
    pc_acc = constraint.JointAccelerationConstraint(np.column_stack([-a, a]))
    constraints = [pc_vel, pc_acc]
    if dynamics is not None:  # the actuators' torques, drag and inertia included (motion/dynamics.py)
        lim = np.asarray(dynamics.torque_limits, dtype=float)
        constraints.append(constraint.JointTorqueConstraint(dynamics.inverse, np.column_stack([-lim, lim]),
                                                            np.zeros(len(lim))))
    inst = algo.TOPPRA(constraints, path, gridpoints=grid, parametrizer="ParametrizeConstAccel")
    _, sd, _ = inst.compute_parameterization(0.0, 0.0)
    if sd is None or np.any(~np.isfinite(sd)):
        raise TimingError(f"toppra could not parameterise the path (return code {inst.problem_data.return_code})")
    sd = np.maximum(np.asarray(sd, dtype=float), 0.0)
    # Piecewise-constant path acceleration between grid points (ParametrizeConstAccel).
    ds = np.diff(grid)
    x = sd**2
    us = 0.5 * (x[1:] - x[:-1]) / ds
    vsum = sd[:-1] + sd[1:]
    if np.any(vsum <= 0):
        raise TimingError("toppra returned a zero path velocity inside the path")
    tg = np.concatenate([[0.0], np.cumsum(2.0 * ds / vsum)])
    duration = float(tg[-1])
    n = max(1, int(math.ceil(duration / dt - 1e-9)))
    ts = np.minimum(np.arange(n + 1) * dt, duration)
    idx = np.clip(np.searchsorted(tg, ts, side="right") - 1, 0, len(us) - 1)
    tau = ts - tg[idx]
    u = us[idx]
    sdt = np.maximum(sd[idx] + u * tau, 0.0)
    st = np.clip(grid[idx] + sd[idx] * tau + 0.5 * u * tau**2, 0.0, s[-1])
    q = path(st)
    qs = path(st, 1)
    qss = path(st, 2)
    qd = qs * sdt[:, None]
    qdd = qss * (sdt**2)[:, None] + qs * u[:, None]
    q[0], q[-1] = P[0], P[-1]
    qd[0] = qd[-1] = 0.0
    # Final sample times: make the last one exactly the duration (dt grid otherwise).
    return ts, q, qd, qdd


def _scale_into_limits(ts, qd, qdd, v, a, tol: float):
    r_v = float(np.max(np.abs(qd) / v)) if len(qd) else 0.0
    r_a = float(np.max(np.abs(qdd) / a)) if len(qdd) else 0.0
    k = max(1.0, r_v / (1.0 - tol), math.sqrt(r_a / (1.0 - tol)) if r_a > 0 else 1.0)
    return k


def retime(
    path: np.ndarray,
    *,
    vel_limits: Sequence[float] = FRANKA_VELOCITY_LIMITS,
    acc_limits: Sequence[float] = DEFAULT_ACCELERATION_LIMITS,
    dt: float = 0.002,
    checker=None,
    resolution_rad: float = 0.02,
    max_densify: int = 3,
    grid_step_rad: float = 0.01,
    dynamics=None,
) -> Trajectory:
    """Time-parameterise a joint path as fast as the limits allow, starting and ending at rest.

    Args:
        path: ``(N, 7)`` waypoints in rad (``N >= 1``; consecutive duplicates are dropped).
        vel_limits: ``(7,)`` symmetric joint velocity limits, rad/s (default: Franka
            datasheet, see the module docstring).
        acc_limits: ``(7,)`` symmetric joint acceleration limits, rad/s^2 (default:
            datasheet x 0.25).
        dt: sample period of the returned trajectory, s.
        checker: optional :class:`~phyagentos.motion.collision.CollisionChecker`; the
            sampled trajectory must then be collision free. Give it a smaller margin
            than the planner's: a shortcut path runs along the planning margin and the
            spline may leave the polyline by a fraction of a millimetre.
        resolution_rad: joint change between collision-checked samples.
        max_densify: how many times the path may be densified after a collision.
        grid_step_rad: spacing of the TOPP-RA grid along the path arc length, rad.
        dynamics: optional :class:`~phyagentos.motion.dynamics.ArmDynamics` of the arm in
            its world: the timing then also keeps every joint's torque (inertia, gravity
            not compensated, damping and a medium's drag) within its ``torque_limits`` at
            the grid points (toppra's ``JointTorqueConstraint``, collocation).

    Returns:
        :class:`Trajectory` sampled every ``dt`` (the last interval may be shorter), with
        every sampled ``|qd| <= vel_limits`` and ``|qdd| <= acc_limits`` (and, with
        ``dynamics``, the torques within its limits at the grid points).

    Raises:
        TimingError: bad inputs, toppra failure, or a trajectory still in collision
            after ``max_densify`` densifications.
    """
    P = np.asarray(path, dtype=float)
    if P.ndim != 2 or P.shape[0] < 1 or not np.all(np.isfinite(P)):
        raise TimingError(f"path must be a finite (N, dof) array with N >= 1, got shape {P.shape}")
    dof = P.shape[1]
    v = np.asarray(vel_limits, dtype=float).reshape(-1)
    a = np.asarray(acc_limits, dtype=float).reshape(-1)
    if v.shape != (dof,) or a.shape != (dof,):
        raise TimingError(f"vel_limits and acc_limits must have shape ({dof},), got {v.shape} and {a.shape}")
    if np.any(v <= 0) or np.any(a <= 0) or not np.all(np.isfinite(v)) or not np.all(np.isfinite(a)):
        raise TimingError("vel_limits and acc_limits must be finite and > 0")
    if not dt > 0:
        raise TimingError(f"dt must be > 0, got {dt}")
    P = _dedupe(P)
    if len(P) == 1:
        z = np.zeros((1, dof))
        return Trajectory(t=np.zeros(1), q=P.copy(), qd=z, qdd=z.copy())
    if checker is not None and not checker.is_valid(P[0]):
        raise TimingError(f"path start is in collision: {checker.colliding_pairs(P[0])}")

    tol = 1e-3
    last_bad = None
    for attempt in range(max_densify + 1):
        try:
            ts, q, qd, qdd = _toppra(P, v, a, dt, grid_step_rad, dynamics)
        except TimingError:
            raise
        except Exception as exc:  # toppra raises assorted errors on degenerate input
            raise TimingError(f"toppra failed: {exc}") from exc
        k = _scale_into_limits(ts, qd, qdd, v, a, tol)
        if k > 1.0 + 1e-12:
            duration = float(ts[-1]) * k
            # Re-sample the slowed-down trajectory on the dt grid.
            n = max(1, int(math.ceil(duration / dt - 1e-9)))
            tn = np.minimum(np.arange(n + 1) * dt, duration)
            src = tn / k
            q = np.column_stack([np.interp(src, ts, q[:, j]) for j in range(dof)])
            qd = np.column_stack([np.interp(src, ts, qd[:, j]) for j in range(dof)]) / k
            qdd = np.column_stack([np.interp(src, ts, qdd[:, j]) for j in range(dof)]) / k**2
            ts = tn
        if len(ts) > 1 and ts[-1] - ts[-2] < 1e-9:
            ts, q, qd, qdd = ts[:-1], q[:-1], qd[:-1], qdd[:-1]
            q[-1] = P[-1]
            qd[-1] = 0.0
        if checker is None:
            return Trajectory(t=ts, q=q, qd=qd, qdd=qdd)
        last_bad = _first_collision(checker, q, resolution_rad)
        if last_bad is None:
            return Trajectory(t=ts, q=q, qd=qd, qdd=qdd)
        log.debug("retime attempt %d collides at t=%.3f s; densifying", attempt, ts[last_bad])
        P = _densify(P)
    pairs = checker.colliding_pairs(q[last_bad]) if last_bad is not None else ()
    raise TimingError(
        f"timed trajectory collides after {max_densify} densifications "
        f"({', '.join(f'{x} <-> {y}' for x, y in pairs) or 'unknown contact'})"
    )


def _first_collision(checker, q: np.ndarray, resolution_rad: float) -> int | None:
    """Index of the first colliding sample, checking a sample whenever the joints have
    moved by up to ``resolution_rad`` (summed max-joint change) since the last check."""
    n = len(q)
    if n == 1:
        return None if checker.is_valid(q[0]) else 0
    step = np.max(np.abs(np.diff(q, axis=0)), axis=1)
    bucket = np.floor(np.concatenate([[0.0], np.cumsum(step)]) / resolution_rad).astype(np.int64)
    idx = np.nonzero(np.diff(bucket) > 0)[0] + 1
    for i in np.unique(np.concatenate([[0], idx, [n - 1]])):
        if not checker.is_valid(q[i]):
            return int(i)
    return None
