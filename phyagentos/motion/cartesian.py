"""Straight-line tool motions: Cartesian interpolation solved by successive IK.

The tcp moves from its pose at ``q_start`` to ``T_goal`` along a straight line (position
linearly interpolated, orientation spherically interpolated), one IK solve per waypoint
seeded with the previous solution, so the joint path follows the line closely and stays
on one IK branch.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Sequence

import mujoco
import numpy as np

from phyagentos.errors import IKError
from phyagentos.geometry import matrix_to_quat

from .ik import DEFAULT_ARM_JOINT_NAMES, solve_ik

__all__ = ["cartesian_path", "forward_kinematics", "interpolate_pose"]

log = logging.getLogger(__name__)


def forward_kinematics(
    model: mujoco.MjModel,
    q: Sequence[float] | np.ndarray,
    *,
    frame: str = "tcp",
    arm_joint_names: Sequence[str] = DEFAULT_ARM_JOINT_NAMES,
    qpos_full: Sequence[float] | None = None,
) -> np.ndarray:
    """World (4, 4) pose of site ``frame`` at arm configuration ``q`` (7,) rad."""
    d = mujoco.MjData(model)
    d.qpos[:] = model.qpos0 if qpos_full is None else np.asarray(qpos_full, dtype=float)
    for i, name in enumerate(arm_joint_names):
        d.qpos[model.jnt_qposadr[model.joint(name).id]] = q[i]
    mujoco.mj_kinematics(model, d)
    sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, frame)
    if sid < 0:
        raise IKError(f"unknown frame {frame!r}")
    T = np.eye(4)
    T[:3, 3] = d.site_xpos[sid]
    T[:3, :3] = d.site_xmat[sid].reshape(3, 3)
    return T


def _slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    d = float(np.dot(q0, q1))
    if d < 0.0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + s * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(min(1.0, d))
    return (math.sin((1 - s) * th) * q0 + math.sin(s * th) * q1) / math.sin(th)


def interpolate_pose(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Pose at fraction ``s`` in [0, 1] from ``T0`` to ``T1`` (lerp + slerp)."""
    q = _slerp(np.asarray(matrix_to_quat(T0[:3, :3])), np.asarray(matrix_to_quat(T1[:3, :3])), s)
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, q)
    T = np.eye(4)
    T[:3, :3] = R.reshape(3, 3)
    T[:3, 3] = (1 - s) * T0[:3, 3] + s * T1[:3, 3]
    return T


def cartesian_path(
    model: mujoco.MjModel,
    *,
    q_start: Sequence[float],
    T_goal: np.ndarray,
    step_m: float = 0.01,
    step_rad: float = 0.05,
    frame: str = "tcp",
    max_joint_step_rad: float = 0.25,
    position_tol_m: float = 1e-3,
    orientation_tol_rad: float = 1e-2,
    arm_joint_names: Sequence[str] = DEFAULT_ARM_JOINT_NAMES,
    qpos_full: Sequence[float] | None = None,
    stats: dict | None = None,
    position_priority: bool = False,
) -> np.ndarray:
    """Joint path moving site ``frame`` in a straight line to ``T_goal``.

    Args:
        model: scene model.
        q_start: ``(7,)`` rad start configuration (first row of the result).
        T_goal: ``(4, 4)`` world goal pose of the site.
        step_m: maximum tcp translation between waypoints, metres (+1 % slack for
            IK round-off).
        step_rad: maximum tcp rotation between waypoints, rad.
        max_joint_step_rad: largest allowed change of any joint between consecutive
            waypoints (guards against IK branch flips).
        position_tol_m, orientation_tol_rad: IK tolerances per waypoint.
        qpos_full: optional full configuration for the fixed dofs.
        stats: optional dict that accumulates ``ik_calls``, ``ik_iterations`` (list),
            ``ik_solve_ms`` (list, per solve) and ``ik_s`` (seconds).
        position_priority: passed to :func:`~phyagentos.motion.ik.solve_ik` (arms that
            cannot reach every orientation).

    Returns:
        ``(N, 7)`` rad, ``N >= 2``.

    Raises:
        IKError: a waypoint has no IK solution or the joints jump by more than
            ``max_joint_step_rad`` between waypoints.
    """
    q0 = np.asarray(q_start, dtype=float).reshape(-1)
    Tg = np.asarray(T_goal, dtype=float)
    if Tg.shape != (4, 4):
        raise IKError(f"T_goal must be (4, 4), got {Tg.shape}")
    if step_m <= 0 or step_rad <= 0:
        raise IKError("step_m and step_rad must be > 0")
    T0 = forward_kinematics(model, q0, frame=frame, arm_joint_names=arm_joint_names, qpos_full=qpos_full)
    dist = float(np.linalg.norm(Tg[:3, 3] - T0[:3, 3]))
    c = (np.trace(T0[:3, :3].T @ Tg[:3, :3]) - 1.0) / 2.0
    ang = float(np.arccos(np.clip(c, -1.0, 1.0)))
    # (a tolerance of 1 % of a step avoids an extra waypoint for IK round-off)
    n = max(1, int(math.ceil(dist / step_m - 0.01)), int(math.ceil(ang / step_rad - 0.01)))
    path = [q0]
    q = q0
    t0 = time.perf_counter()
    iters: list[int] = []
    solve_ms: list[float] = []
    for k in range(1, n + 1):
        T = Tg if k == n else interpolate_pose(T0, Tg, k / n)
        ts = time.perf_counter()
        try:
            sol = solve_ik(
                model,
                q_seed=q,
                target=T,
                frame=frame,
                position_tol_m=position_tol_m,
                orientation_tol_rad=orientation_tol_rad,
                arm_joint_names=arm_joint_names,
                qpos_full=qpos_full,
                position_priority=position_priority,
            )
        except IKError as exc:
            raise IKError(f"Cartesian path: waypoint {k}/{n} at {np.round(T[:3, 3], 3).tolist()} failed: {exc}") from exc
        solve_ms.append((time.perf_counter() - ts) * 1e3)
        iters.append(sol.iterations)
        jump = float(np.max(np.abs(sol.q - q)))
        if jump > max_joint_step_rad:
            raise IKError(
                f"Cartesian path: joint jump of {jump:.3f} rad (max {max_joint_step_rad} rad) at waypoint {k}/{n}"
            )
        q = np.array(sol.q)
        path.append(q)
    if stats is not None:
        stats["ik_calls"] = stats.get("ik_calls", 0) + n
        stats.setdefault("ik_iterations", []).extend(iters)
        stats.setdefault("ik_solve_ms", []).extend(solve_ms)
        stats["ik_s"] = stats.get("ik_s", 0.0) + time.perf_counter() - t0
    return np.array(path)
