"""Execution leaves: they move the target, one control period per tick.

Long motions return RUNNING between ticks so the runner can check the cancel
token and the deadline (preemptive cancellation at control-period granularity).
"""

from __future__ import annotations

import numpy as np
from py_trees.common import Status

from phyagentos.motion.cartesian import cartesian_path
from phyagentos.motion.retime import Trajectory, retime

from .base import Primitive, PrimitiveFailure
from .motion import execution_limits, held_object, session_checker

__all__ = ["ExecuteTrajectory", "CartesianMove", "Gripper", "Hold", "CheckHolding"]

GRIPPER_OPEN_M = 0.04  # Franka Hand: 0.04 m per finger (80 mm stroke), datasheet


class _Tracking(Primitive):
    """Streams a timed trajectory to the target, ``control_period_s`` of simulated time per tick."""

    TOOLS = ("move_joints",)

    def _start(self, traj: Trajectory) -> None:
        self._traj = traj
        self._t = 0.0
        self._max_err = 0.0
        self.ctx.trace.record("execute_start", leaf=self.name, duration_s=float(traj.duration))

    def _advance(self) -> Status:
        ctx = self.ctx
        t_end = min(self._t + ctx.motion.control_period_s, self._traj.duration)
        with ctx.profiler.section("simulation"):
            result = ctx.target.track(self._traj, t_start=self._t, t_end=t_end, tracking_tol_rad=ctx.motion.tracking_tol_rad)
        self._max_err = max(self._max_err, result.max_tracking_error_rad)
        self._t = t_end
        if not result.completed:
            raise PrimitiveFailure("execution.tracking",
                                   f"tracking error {result.max_tracking_error_rad:.3f} rad exceeded "
                                   f"{ctx.motion.tracking_tol_rad} rad at t={t_end:.2f} s; contacts {list(result.contacts)}")
        if self._t < self._traj.duration - 1e-9:
            return Status.RUNNING
        with ctx.profiler.section("simulation"):
            ctx.target.settle(self._traj.q[-1])
        ctx.trace.record("execute_end", leaf=self.name, max_tracking_error_rad=round(self._max_err, 5),
                         q=np.round(ctx.target.arm_qpos(), 4).tolist())
        return Status.SUCCESS


class ExecuteTrajectory(_Tracking):
    """Execute the Trajectory at blackboard key ``trajectory`` with a tracking check.

    Fails with ``execution.tracking`` when the joint tracking error exceeds the
    session's ``tracking_tol_rad`` (a collision or a blocked joint).
    """

    def __init__(self, name: str, *, trajectory: str = "trajectory"):
        super().__init__(name)
        self.key = trajectory
        self.reads(trajectory)

    def on_enter(self):
        self._start(self.get(self.key))

    def step(self):
        return self._advance()


class CartesianMove(_Tracking):
    """Straight-line tcp motion: to a blackboard pose (``to``) or by a world ``offset``.

    Used for approach, lift and retreat: IK along the line (mink), timed with
    toppra, collision-checked with the held object attached, executed with tracking.

    Args:
        to: blackboard key of a (4, 4) world tcp pose; or
        offset: (3,) world-frame displacement of the tcp in m (orientation kept).
        velocity_scale: fraction (0, 1] of the joint velocity limits (slow near contact).
        check_collisions: re-check the timed motion against the scene. Off for
            approaches that must end in contact with the object being grasped.
    """

    def __init__(self, name: str, *, to: str | None = None, offset=None, velocity_scale: float = 0.3,
                 check_collisions: bool = False):
        super().__init__(name)
        if (to is None) == (offset is None):
            raise ValueError("give exactly one of 'to' (blackboard pose key) or 'offset' ([dx, dy, dz] in m)")
        if offset is not None:
            offset = np.asarray(offset, dtype=float)
            if offset.shape != (3,) or not np.all(np.isfinite(offset)):
                raise ValueError(f"offset must be 3 finite numbers in m, got {offset!r}")
        if not 0 < velocity_scale <= 1:
            raise ValueError(f"velocity_scale must be in (0, 1], got {velocity_scale}")
        self.to, self.offset = to, offset
        self.velocity_scale, self.check_collisions = float(velocity_scale), bool(check_collisions)
        if to is not None:
            self.reads(to)

    def on_enter(self):
        ctx = self.ctx
        target = ctx.target
        T_start = target.tcp_pose()
        if self.to is not None:
            T_goal = np.asarray(self.get(self.to))
        else:
            T_goal = T_start.copy()
            T_goal[:3, 3] += self.offset
        with ctx.profiler.section("ik"):
            path = cartesian_path(target.model, q_start=target.arm_qpos(), T_goal=T_goal)
        vel, acc = execution_limits(ctx, self.velocity_scale, self.velocity_scale)
        with ctx.profiler.section("timing"):
            checker = session_checker(ctx) if self.check_collisions else None
            traj = retime(path, vel_limits=vel, acc_limits=acc,
                          dt=target.model.opt.timestep, checker=checker)
        self._start(traj)

    def step(self):
        return self._advance()


class Gripper(Primitive):
    """Open or close the gripper; closing on ``object`` checks the grasp.

    Args:
        command: ``open`` or ``close``.
        object: when closing, the object that must end up between the fingers;
            a miss fails with ``grasp.missed``.
    """

    TOOLS = ("set_gripper",)
    COMMANDS = ("close", "open")

    def __init__(self, name: str, *, command: str, object: str | None = None):
        super().__init__(name)
        if command not in self.COMMANDS:
            raise ValueError(f"unknown gripper command {command!r}; valid: {', '.join(self.COMMANDS)}")
        self.command, self.object = command, object

    def step(self):
        ctx = self.ctx
        with ctx.profiler.section("simulation"):
            result = ctx.target.set_gripper(opening_m=GRIPPER_OPEN_M if self.command == "open" else 0.0)
        ctx.trace.record("gripper", command=self.command, opening_m=round(float(result.opening_m), 5),
                         grasped=result.grasped)
        if self.command == "close" and self.object is not None and result.grasped != self.object:
            raise PrimitiveFailure("grasp.missed", f"closed on {result.grasped or 'nothing'} instead of {self.object!r} "
                                                   f"(opening {result.opening_m * 1000:.1f} mm)")


class Hold(Primitive):
    """Hold the current joint configuration for ``duration_s`` of simulated time."""

    TOOLS = ("hold",)

    def __init__(self, name: str, *, duration_s: float = 1.0):
        super().__init__(name)
        if not isinstance(duration_s, (int, float)) or duration_s < 0:
            raise ValueError(f"duration_s must be a number >= 0, got {duration_s!r}")
        self.duration_s = float(duration_s)

    def on_enter(self):
        self._remaining = self.duration_s
        self._q = self.ctx.target.arm_qpos()

    def step(self):
        dt = min(self.ctx.motion.control_period_s, self._remaining)
        with self.ctx.profiler.section("simulation"):
            self.ctx.target.hold(self._q, duration_s=dt)
        self._remaining -= dt
        return Status.RUNNING if self._remaining > 1e-9 else Status.SUCCESS


class CheckHolding(Primitive):
    """Succeed only if the gripper holds ``object`` now (``grasp.slipped`` otherwise)."""

    TOOLS = ("snapshot",)

    def __init__(self, name: str, *, object: str):
        super().__init__(name)
        self.object = object

    def step(self):
        held = held_object(self.ctx.target)
        if held != self.object:
            raise PrimitiveFailure("grasp.slipped", f"expected to hold {self.object!r}, holding {held or 'nothing'}")
