"""Inverse kinematics of the Franka arm with mink (differential IK iterated to convergence).

Each iteration solves one mink QP (``FrameTask`` on the tcp site, a weak ``PostureTask``
towards the seed, ``ConfigurationLimit`` for the joint ranges) with ``dt = 1`` so that a
step is a damped Gauss-Newton step, and integrates it. Every degree of freedom that is
not an arm joint (fingers, free objects) is frozen with an exact ``DofFreezingTask``
equality constraint, so the fingers stay where they are.

QP backend: ``daqp`` when qpsolvers has it (it is a dependency of mink), else the first
backend qpsolvers reports.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Sequence

import mink
import mujoco
import numpy as np
import qpsolvers
from numpy.typing import ArrayLike

from phyagentos.errors import IKError, format_choices

__all__ = ["IKSolution", "solve_ik", "qp_solver_name", "pose_error", "DEFAULT_ARM_JOINT_NAMES",
           "POSITION_PRIORITY_ORIENTATION_COST", "forget_model"]

#: Orientation cost of the frame task in the second phase of ``position_priority``
#: (position cost 1): a 0.3 rad orientation residual then weighs like 0.6 mm of position
#: error, so the position converges while the orientation stays as close as it can.
POSITION_PRIORITY_ORIENTATION_COST = 0.002

log = logging.getLogger(__name__)

DEFAULT_ARM_JOINT_NAMES: tuple[str, ...] = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))


def qp_solver_name() -> str:
    """The qpsolvers backend used for the IK QPs (``'daqp'`` preferred)."""
    available = list(qpsolvers.available_solvers)
    if "daqp" in available:
        return "daqp"
    if not available:  # pragma: no cover - mink depends on daqp
        raise IKError("no QP solver backend is installed for qpsolvers (install 'daqp')")
    return available[0]


@dataclass(frozen=True)
class IKSolution:
    """Result of :func:`solve_ik`.

    Attributes:
        q: ``(n,)`` arm joint angles in radians, one per name in ``arm_joint_names``
            (7 for the Panda, 5 for the SO-101; read-only array).
        iterations: number of QP iterations used.
        position_error_m: remaining tcp position error, metres.
        orientation_error_rad: remaining tcp orientation error (rotation angle), radians.
    """

    q: np.ndarray
    iterations: int
    position_error_m: float
    orientation_error_rad: float


def pose_error(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """Position (m) and orientation (rad, rotation angle) difference of two (4, 4) poses."""
    dp = float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]))
    R = T_a[:3, :3].T @ T_b[:3, :3]
    c = (np.trace(R) - 1.0) / 2.0
    return dp, float(np.arccos(np.clip(c, -1.0, 1.0)))


class _IKContext:
    """Per-(model, frame, joints) mink objects, reused between calls."""

    def __init__(self, model: mujoco.MjModel, frame: str, arm_joint_names: tuple[str, ...]):
        self.model = model  # keep alive so id(model) is not reused while cached
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, frame)
        if sid < 0:
            sites = [model.site(i).name for i in range(model.nsite)]
            raise IKError(f"unknown IK frame {frame!r}; sites in the model: {format_choices(sites)}")
        self.arm_qadr = np.empty(len(arm_joint_names), dtype=int)
        self.arm_dadr = np.empty(len(arm_joint_names), dtype=int)
        jnames = [model.joint(i).name for i in range(model.njnt)]
        for i, name in enumerate(arm_joint_names):
            jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0:
                raise IKError(f"unknown arm joint {name!r}; joints: {format_choices(jnames)}")
            self.arm_qadr[i] = model.jnt_qposadr[jid]
            self.arm_dadr[i] = model.jnt_dofadr[jid]
        self.lower = model.jnt_range[[model.joint(n).id for n in arm_joint_names], 0].copy()
        self.upper = model.jnt_range[[model.joint(n).id for n in arm_joint_names], 1].copy()
        self.config = mink.Configuration(model)
        self.frame_task = mink.FrameTask(frame, "site", position_cost=1.0, orientation_cost=0.5, lm_damping=1e-4)
        self.posture_task = mink.PostureTask(model, cost=np.zeros(model.nv))
        frozen = sorted(set(range(model.nv)) - set(int(i) for i in self.arm_dadr))
        self.constraints = [mink.DofFreezingTask(model, frozen)] if frozen else []
        self.limits = [mink.ConfigurationLimit(model, gain=0.95)]
        self.lock = threading.Lock()


_CACHE: OrderedDict[tuple[int, str, tuple[str, ...]], _IKContext] = OrderedDict()
_CACHE_LOCK = threading.Lock()
#: IK contexts kept, least recently used out (building one takes about 0.7 ms). Each holds
#: its model, so this also bounds the models of closed targets it keeps alive (about
#: 24 MiB each for the Franka tabletop scene; a runner builds new targets run after run).
_CACHE_MAX = 4


def _context(model: mujoco.MjModel, frame: str, names: tuple[str, ...]) -> _IKContext:
    key = (id(model), frame, names)
    with _CACHE_LOCK:
        ctx = _CACHE.get(key)
        if ctx is None or ctx.model is not model:
            while len(_CACHE) >= _CACHE_MAX:
                _CACHE.popitem(last=False)
            ctx = _IKContext(model, frame, names)
            _CACHE[key] = ctx
        else:
            _CACHE.move_to_end(key)
        return ctx


def forget_model(model: mujoco.MjModel) -> int:
    """Drop the cached IK contexts of ``model`` (its target is closed): each holds the
    model, so the cache would keep a closed world's model alive (a LIBERO world's: about
    250 MB) until newer models push it out. Returns how many contexts were dropped."""
    with _CACHE_LOCK:
        stale = [key for key, ctx in _CACHE.items() if ctx.model is model]
        for key in stale:
            del _CACHE[key]
    return len(stale)


def solve_ik(
    model: mujoco.MjModel,
    *,
    q_seed: ArrayLike,
    target: np.ndarray,
    frame: str = "tcp",
    position_tol_m: float = 1e-3,
    orientation_tol_rad: float = 1e-2,
    max_iters: int = 200,
    posture_weight: float = 1e-3,
    arm_joint_names: Sequence[str] = DEFAULT_ARM_JOINT_NAMES,
    qpos_full: Sequence[float] | None = None,
    position_priority: bool = False,
) -> IKSolution:
    """Arm joint angles that put site ``frame`` at pose ``target``.

    Args:
        model: a MuJoCo model holding the arm joints and the site ``frame``.
        q_seed: ``(n,)`` rad (one per ``arm_joint_names``), start of the iteration (usually the current arm angles);
            clipped into the joint range first. The posture regulariser pulls towards it.
        target: ``(4, 4)`` homogeneous world pose of the site.
        frame: site name (default ``'tcp'``).
        position_tol_m, orientation_tol_rad: convergence tolerances.
        max_iters: iteration budget.
        posture_weight: cost of the posture task relative to the frame task (unitless).
        arm_joint_names: the 7 joints the solver may move; all other dofs stay fixed.
        qpos_full: optional ``(nq,)`` full configuration for the fixed dofs (fingers,
            objects); defaults to ``model.qpos0`` with fingers as there.
        position_priority: for arms with fewer than 6 joints, where some orientations
            cannot be reached: the solver first asks for the exact pose (orientation
            within 0.01 rad); if that stalls, it lowers the orientation cost to
            :data:`POSITION_PRIORITY_ORIENTATION_COST`, meets the position, and accepts
            any orientation within ``orientation_tol_rad``.

    Returns:
        :class:`IKSolution` with ``q`` inside the joint limits.

    Raises:
        IKError: invalid inputs, unknown frame/joints, or no convergence within
            ``max_iters`` (or stalled progress); the message gives the residuals.
    """
    names = tuple(arm_joint_names)
    T = np.asarray(target, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise IKError(f"target must be a finite (4, 4) pose, got shape {T.shape}")
    q0 = np.asarray(q_seed, dtype=float).reshape(-1)
    if q0.shape != (len(names),) or not np.all(np.isfinite(q0)):
        raise IKError(f"q_seed must be a finite ({len(names)},) vector, got shape {q0.shape}")
    if max_iters < 1:
        raise IKError(f"max_iters must be >= 1, got {max_iters}")
    ctx = _context(model, frame, names)
    with ctx.lock:
        return _solve(ctx, q0, T, position_tol_m, orientation_tol_rad, max_iters, posture_weight, qpos_full,
                      position_priority)


def _solve(ctx: _IKContext, q0, T, pos_tol, ori_tol, max_iters, posture_weight, qpos_full,
           position_priority=False) -> IKSolution:
    model = ctx.model
    qfull = np.array(model.qpos0 if qpos_full is None else qpos_full, dtype=float)
    if qfull.shape != (model.nq,):
        raise IKError(f"qpos_full must have shape ({model.nq},), got {qfull.shape}")
    qfull[ctx.arm_qadr] = np.clip(q0, ctx.lower, ctx.upper)
    config = ctx.config
    config.update(qfull)
    ctx.frame_task.set_target(mink.SE3.from_matrix(T))
    ctx.frame_task.set_orientation_cost(0.5)
    # Position priority first asks for the exact orientation (as without it); if that
    # stalls, a second phase drops the orientation cost to meet the position and accepts
    # any orientation within the tolerance.
    ori_goal = min(ori_tol, 1e-2) if position_priority else ori_tol
    cost = np.zeros(model.nv)
    cost[ctx.arm_dadr] = posture_weight
    ctx.posture_task.set_cost(cost)
    ctx.posture_task.set_target(qfull)
    tasks = [ctx.frame_task, ctx.posture_task]
    solver = qp_solver_name()
    site = ctx.frame_task.frame_name

    def errors() -> tuple[float, float]:
        xpos = config.data.site(site).xpos
        xmat = config.data.site(site).xmat.reshape(3, 3)
        dp = float(np.linalg.norm(xpos - T[:3, 3]))
        c = (np.trace(T[:3, :3].T @ xmat) - 1.0) / 2.0
        return dp, float(np.arccos(np.clip(c, -1.0, 1.0)))

    dp, dr = errors()
    it = 0
    phases = 2 if position_priority else 1
    while phases:
        phases -= 1
        it, dp, dr = _iterate(ctx, config, tasks, solver, errors, it, max_iters, pos_tol, ori_goal, dp, dr)
        if phases and (dp > pos_tol or dr > ori_goal):
            ctx.frame_task.set_orientation_cost(POSITION_PRIORITY_ORIENTATION_COST)
            ori_goal = ori_tol
        else:
            break
    # On a bound the QP can overshoot by solver round-off (~1e-5 rad); exact-range checks
    # downstream (SafetyGuard) must never see that.
    q = np.clip(config.q[ctx.arm_qadr], ctx.lower, ctx.upper)
    if dp > pos_tol or dr > ori_tol:
        raise IKError(
            f"IK did not converge to the target pose of {site!r} after {it} iterations: "
            f"position error {dp * 1000:.1f} mm (tol {pos_tol * 1000:.1f} mm), "
            f"orientation error {dr:.4f} rad (tol {ori_tol:.4f} rad); target position "
            f"{np.round(T[:3, 3], 3).tolist()}"
        )
    q.setflags(write=False)
    return IKSolution(q=q, iterations=it, position_error_m=dp, orientation_error_rad=dr)


def _iterate(ctx, config, tasks, solver, errors, it, max_iters, pos_tol, ori_goal, dp, dr):
    """Damped Gauss-Newton steps until within tolerance, ``max_iters`` or 25 steps without progress."""
    best = (dp + dr * 0.1, it)
    while (dp > pos_tol or dr > ori_goal) and it < max_iters:
        try:
            v = mink.solve_ik(
                config,
                tasks,
                1.0,
                solver,
                damping=1e-6,
                limits=ctx.limits,
                constraints=ctx.constraints,
            )
        except Exception as exc:  # mink.NoSolutionFound and qpsolvers errors
            raise IKError(f"IK QP failed at iteration {it}: {exc}") from exc
        config.integrate_inplace(v, 1.0)
        it += 1
        dp, dr = errors()
        score = dp + dr * 0.1
        if score < best[0] - 1e-7:
            best = (score, it)
        elif it - best[1] >= 25:
            break  # no progress for 25 iterations: unreachable or stuck at a limit
    return it, dp, dr
