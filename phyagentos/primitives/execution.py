"""Execution leaves: they move the target, one control period per tick.

Long motions return RUNNING between ticks so the runner can check the cancel
token and the deadline (preemptive cancellation at control-period granularity).
"""

from __future__ import annotations

import math

import numpy as np
from py_trees.common import Status

from phyagentos.errors import IKError
from phyagentos.motion.cartesian import cartesian_path
from phyagentos.motion.retime import Trajectory, retime
from phyagentos.targets.contract import MuJoCoBacked, arm_dynamics_of, capabilities_of

from . import planning_world
from .base import Primitive, PrimitiveFailure
from .grasp_sense import (
    WIDTH_MARGIN_M,
    belief,
    closed_on_something,
    holding_problem,
    mass_estimate_kg,
    proprio_record,
    sample_while_holding,
    wrist_load_n,
)
from .motion import execution_limits, ik_options, session_checker
from .observation import has_cameras, save_tracks

__all__ = ["ExecuteTrajectory", "CartesianMove", "Gripper", "Hold", "WaitStill", "CheckHolding", "REACH_STEP_M",
           "STILL_DEPTH_M", "STILL_PIXELS", "STILL_RANGE_M"]

#: The step (m) by which a :class:`CartesianMove` with ``at_least_m`` shortens a line that
#: leaves the arm's reach.
REACH_STEP_M = 0.01
GRIPPER_OPEN_M = 0.04  # Franka Hand: 0.04 m per finger (80 mm stroke), datasheet


class _Tracking(Primitive):
    """Streams a timed trajectory to the target, ``control_period_s`` of simulated time per tick."""

    TOOLS = ("move_joints",)

    def _start(self, traj: Trajectory) -> None:
        traj = self._within_range(traj)
        if self.ctx.guard is not None:
            traj = self._guarded(traj)
        self._traj = traj
        self._t = 0.0
        self._max_err = 0.0
        self.ctx.trace.record("execute_start", leaf=self.name, duration_s=float(traj.duration))

    #: Largest amount a reference may lie outside the model's joint range and still be
    #: pulled back to it, rad: a timing spline through waypoints on a joint limit
    #: overshoots by about a milliradian; anything larger is a real request to leave the
    #: range and is left for the SafetyGuard to refuse.
    RANGE_ROUNDOFF_RAD = 5e-3

    def _within_range(self, traj: Trajectory) -> Trajectory:
        target = self.ctx.target
        if not isinstance(target, MuJoCoBacked):
            return traj
        model = target.model
        jids = [model.joint(n).id for n in target.arm_joint_names]
        lo, hi = model.jnt_range[jids, 0], model.jnt_range[jids, 1]
        q = np.asarray(traj.q, dtype=float)
        over = float(np.max(np.maximum(lo - q, q - hi)))
        if over <= 0.0 or over > self.RANGE_ROUNDOFF_RAD:
            return traj
        return Trajectory(t=traj.t, q=np.clip(q, lo, hi), qd=traj.qd, qdd=traj.qdd)

    def _guarded(self, traj: Trajectory) -> Trajectory:
        """SafetyGuard check of the whole trajectory, at the samples ``track`` streams,
        before any of it reaches the target; a clamped trajectory replaces it when
        ``safety.yaml`` authorises the clamp, otherwise the leaf fails with the code."""
        ctx = self.ctx
        guard, target = ctx.guard, ctx.target
        dt = float(target.timestep)
        t = np.asarray(traj.t, dtype=float) - float(traj.t[0])
        duration = float(t[-1])
        n = max(1, int(math.ceil(duration / dt - 1e-9)))
        times = np.minimum((np.arange(n) + 1) * dt, duration)

        def at(a):
            a = np.asarray(a, dtype=float)
            return np.column_stack([np.interp(times, t, a[:, j]) for j in range(a.shape[1])])

        qdd = getattr(traj, "qdd", None)
        guard.sync(target.arm_qpos())
        decision = guard.check(at(traj.q), dt=dt, qd=at(traj.qd), qdd=at(qdd) if qdd is not None else None,
                               source=self.name)
        if decision.outcome == "halt":
            target.halt()
        if not decision.admitted:
            raise PrimitiveFailure(decision.code, f"SafetyGuard {decision.outcome}: {decision.message}")
        if decision.outcome == "clamp":
            q = np.vstack([np.asarray(traj.q, dtype=float)[:1], decision.actions[:, :7]])
            ts = np.concatenate([[0.0], times[: len(q) - 1]])
            qd = np.gradient(q, ts, axis=0) if len(q) > 1 else np.zeros_like(q)
            traj = Trajectory(t=ts, q=q, qd=qd, qdd=np.gradient(qd, ts, axis=0) if len(q) > 1 else np.zeros_like(q))
        guard.commit(decision.actions, dt=dt, qd_end=np.asarray(traj.qd, dtype=float)[-1])
        return traj

    def _advance(self) -> Status:
        ctx = self.ctx
        if ctx.guard is not None and ctx.guard.estop_engaged():
            ctx.target.halt()
            raise PrimitiveFailure("safety.estop", f"e-stop engaged: {ctx.guard.estop.reason}")
        t_end = min(self._t + ctx.motion.control_period_s, self._traj.duration)
        with ctx.profiler.section("simulation"):
            result = ctx.target.track(self._traj, t_start=self._t, t_end=t_end, tracking_tol_rad=ctx.motion.tracking_tol_rad)
        self._max_err = max(self._max_err, result.max_tracking_error_rad)
        self._t = t_end
        sample_while_holding(ctx, self.name)  # proprio at >= 10 Hz of sim time while holding
        if ctx.guard is not None and ctx.guard.estop_engaged():
            ctx.target.halt()  # the target's own hook already stopped streaming mid-slice
            raise PrimitiveFailure("safety.estop", f"e-stop engaged: {ctx.guard.estop.reason}")
        if not result.completed and result.code:  # the target stopped itself (e.g. a real arm's bus guard)
            raise PrimitiveFailure(result.code, f"target stopped at t={t_end:.2f} s: {result.reason}")
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
        at_least_m: with ``offset``: where the line leaves the arm's reach (no IK solution
            on it), the move ends as far along it as the arm reaches, in steps of
            :data:`REACH_STEP_M`, when that is at least this far (m; more than the offset:
            all of it); ``None``: the whole offset or an ``ik.unreachable`` failure. A lift
            of a bowl out of a drawer near the edge of the Panda's workspace rises what it
            can (traced ``reach_limited``).
        offset_plus: with ``offset``: blackboard key of a length (m, >= 0) the move goes further
            along the offset's direction, ``at_least_m`` too (a retreat from a place lowered
            into a container rises by as much more as it was lowered: ``place_sunk_m`` of
            :class:`~phyagentos.primitives.perception.ComputePlace`); ``None``: the offset alone.
        grasp_kind: move only after a grasp of this kind was planned (``rim``, ``across``,
            ... as :func:`~phyagentos.primitives.grasp_sense.plan_grasp` records it); after
            another, or none, the leaf succeeds at once: no time passes, nothing is traced.
            ``None``: always.

    Raises (as failures): ``IKError`` when the line (or, with ``at_least_m``, its first
    ``at_least_m``) leaves the arm's reach.
    """

    def __init__(self, name: str, *, to: str | None = None, offset=None, velocity_scale: float = 0.3,
                 check_collisions: bool = False, at_least_m: float | None = None, grasp_kind: str | None = None,
                 offset_plus: str | None = None):
        super().__init__(name)
        if grasp_kind is not None and not isinstance(grasp_kind, str):
            raise ValueError(f"grasp_kind must be a grasp kind's name (e.g. rim) or null, got {grasp_kind!r}")
        self.grasp_kind = grasp_kind
        if (to is None) == (offset is None):
            raise ValueError("give exactly one of 'to' (blackboard pose key) or 'offset' ([dx, dy, dz] in m)")
        if offset is not None:
            offset = np.asarray(offset, dtype=float)
            if offset.shape != (3,) or not np.all(np.isfinite(offset)):
                raise ValueError(f"offset must be 3 finite numbers in m, got {offset!r}")
        if not 0 < velocity_scale <= 1:
            raise ValueError(f"velocity_scale must be in (0, 1], got {velocity_scale}")
        if at_least_m is not None:
            if offset is None:
                raise ValueError("at_least_m applies to an 'offset' move only")
            if not (isinstance(at_least_m, (int, float)) and not isinstance(at_least_m, bool)
                    and math.isfinite(float(at_least_m)) and float(at_least_m) >= 0.0):
                raise ValueError(f"at_least_m must be a number of m >= 0 or null, got {at_least_m!r}")
        if offset_plus is not None and (offset is None or not np.any(offset)):
            raise ValueError("offset_plus applies to a non-zero 'offset' move only")
        self.to, self.offset, self.offset_plus = to, offset, offset_plus
        # more than the offset asks: the whole offset
        self.at_least_m = None if at_least_m is None else min(float(at_least_m), float(np.linalg.norm(offset)))
        self.velocity_scale, self.check_collisions = float(velocity_scale), bool(check_collisions)
        if to is not None:
            self.reads(to)
        if offset_plus is not None:
            self.reads(offset_plus)

    def _skipped(self) -> bool:
        """Whether :attr:`grasp_kind` rules this move out (the planned grasp is of another kind)."""
        if self.grasp_kind is None:
            return False
        planned = self.ctx.target.runtime_notes.get("planned_grasp") or {}
        return planned.get("kind") != self.grasp_kind

    def on_enter(self):
        if self._skipped():
            return
        ctx = self.ctx
        target = ctx.target
        T_start = target.tcp_pose()
        if self.to is not None:
            T_goal = np.asarray(self.get(self.to))
        else:
            T_goal = T_start.copy()
            T_goal[:3, 3] += self._offset()
        with ctx.profiler.section("ik"):
            path = self._path(T_start, T_goal)
        vel, acc = execution_limits(ctx, self.velocity_scale, self.velocity_scale)
        with ctx.profiler.section("timing"):
            checker = session_checker(ctx) if self.check_collisions else None
            traj = retime(path, vel_limits=vel, acc_limits=acc,
                          dt=target.model.opt.timestep, checker=checker, dynamics=arm_dynamics_of(ctx.target))
        self._start(traj)

    def step(self):
        if self._skipped():
            return Status.SUCCESS
        return self._advance()

    def _offset(self) -> np.ndarray:
        """(3,) world m: :attr:`offset`, lengthened by the blackboard's :attr:`offset_plus`."""
        if self.offset_plus is None:
            return self.offset
        plus = self.get(self.offset_plus)
        if not isinstance(plus, (int, float)) or isinstance(plus, bool) or not math.isfinite(plus) or plus < 0.0:
            raise PrimitiveFailure("skill.blackboard", f"{self.offset_plus!r} must be a length >= 0 in m, got {plus!r}")
        full = float(np.linalg.norm(self.offset))
        return self.offset * ((full + float(plus)) / full)

    def _path(self, T_start: np.ndarray, T_goal: np.ndarray) -> np.ndarray:
        """The joint path of the line to ``T_goal``; with :attr:`at_least_m`, of the longest
        line along it in :data:`REACH_STEP_M` steps that the arm reaches."""
        target = self.ctx.target
        try:
            return cartesian_path(target.model, q_start=target.arm_qpos(), T_goal=T_goal, **ik_options(target))
        except IKError as exc:
            if self.at_least_m is None:
                raise
            offset = self._offset()
            full = float(np.linalg.norm(offset))
            at_least = self.at_least_m + (full - float(np.linalg.norm(self.offset)))
            reach = full - REACH_STEP_M
            while reach >= at_least - 1e-9:
                T = T_goal.copy()
                T[:3, 3] = T_start[:3, 3] + offset * (reach / full)
                try:
                    path = cartesian_path(target.model, q_start=target.arm_qpos(), T_goal=T, **ik_options(target))
                except IKError:
                    reach -= REACH_STEP_M
                    continue
                self.ctx.trace.record("reach_limited", leaf=self.name, asked_m=round(full, 4), moved_m=round(reach, 4),
                                      reason=str(exc)[:200])
                return path
            raise


class Gripper(Primitive):
    """Open, pre-shape or close the gripper; closing on ``object`` checks the grasp by
    proprioception.

    Args:
        command: ``open``, ``close`` or ``preshape``: open each finger only as far as the
            grasp of ``object`` planned last asks (``preshape_m`` of the planned grasp, by
            :class:`~phyagentos.primitives.perception.ComputeGrasp`: a rim grasp whose fully
            open fingers would meet something beside the object); nothing happens (no time
            passes, nothing is traced) when that grasp goes down fully open.
        object: when closing, the object that must end up between the fingers. The
            grasp is judged from the robot's own sensing (never simulator contacts): the
            fingers stop above 2 mm per finger, within the object's perceived width (as
            :class:`~phyagentos.primitives.perception.ComputeGrasp` planned it) + 1 cm,
            and squeeze with more than 1 N; otherwise ``grasp.missed``.
        force_n: when closing, the grip force per finger in N (the target's
            ``set_gripper(force_n=...)``); ``None`` closes on position alone.

    Trace: ``proprio`` right before and after, and ``gripper`` {command, object,
    opening_m, effort_n, stalled, closed_on_something, force_n}.
    """

    TOOLS = ("set_gripper",)
    COMMANDS = ("close", "open", "preshape")

    def __init__(self, name: str, *, command: str, object: str | None = None, force_n: float | None = None):
        super().__init__(name)
        if command not in self.COMMANDS:
            raise ValueError(f"unknown gripper command {command!r}; valid: {', '.join(self.COMMANDS)}")
        if force_n is not None and (not isinstance(force_n, (int, float)) or isinstance(force_n, bool) or force_n < 0):
            raise ValueError(f"force_n must be a number of newtons >= 0 or null, got {force_n!r}")
        self.command, self.object = command, object
        self.force_n = float(force_n) if force_n is not None and command == "close" else None

    def _preshape(self) -> None:
        """Open each finger ``preshape_m`` of the planned grasp of ``object`` (none: nothing)."""
        ctx, target = self.ctx, self.ctx.target
        planned = target.runtime_notes.get("planned_grasp") or {}
        opening = planned.get("preshape_m")
        if opening is None or planned.get("object") != self.object:
            return
        with ctx.profiler.section("simulation"):
            result = target.set_gripper(opening_m=float(opening))
        ctx.trace.record("gripper", leaf=self.name, command=self.command, object=self.object,
                         opening_m=round(float(result.opening_m), 5), effort_n=None, stalled=bool(result.stalled),
                         closed_on_something=False, force_n=None)

    def step(self):
        ctx = self.ctx
        target = ctx.target
        if self.command == "preshape":
            self._preshape()
            return
        sensed = capabilities_of(target).has_sensor("proprioception")
        b = belief(target)
        if sensed:
            p0 = target.proprioception()
            ctx.trace.record("proprio", **proprio_record(target, p0, phase=f"before_{self.command}", leaf=self.name))
            if self.command == "close" and b.object is None and p0.wrist_force_n is not None:
                b.set(baseline_force_n=float(np.linalg.norm(p0.wrist_force_n)))  # open, still hand
        opening = GRIPPER_OPEN_M if self.command == "open" else 0.0
        with ctx.profiler.section("simulation"):
            if self.force_n is None:
                result = target.set_gripper(opening_m=opening)
            else:
                result = target.set_gripper(opening_m=opening, force_n=self.force_n)
        if not sensed:  # a target without proprioception reports only its opening
            ctx.trace.record("gripper", leaf=self.name, command=self.command, object=self.object,
                             opening_m=round(float(result.opening_m), 5), effort_n=None, stalled=bool(result.stalled),
                             closed_on_something=bool(result.stalled), force_n=self.force_n)
            return
        p1 = target.proprioception()
        planned = target.runtime_notes.get("planned_grasp") or {}
        width = planned.get("width_m") if self.object is not None and planned.get("object") == self.object else None
        # a rim grasp closes on a thin wall: "nothing between the fingers" is judged against it
        closed_on = closed_on_something(p1, width)
        ctx.trace.record("gripper", leaf=self.name, command=self.command, object=self.object,
                         opening_m=round(float(p1.gripper_opening_m), 5), effort_n=round(float(p1.gripper_effort_n), 3),
                         stalled=bool(result.stalled), closed_on_something=bool(closed_on), force_n=self.force_n)
        ctx.trace.record("proprio", **proprio_record(target, p1, phase=f"after_{self.command}", leaf=self.name))
        if self.command == "open":
            planning_world.note_release(target)  # what the hand held stays where it let it go
            base = b.baseline_force_n
            b.clear()
            if base is not None:
                b.set(baseline_force_n=base)
            return
        if self.object is None:
            return
        if not closed_on:
            raise PrimitiveFailure("grasp.missed", f"closed on nothing instead of {self.object!r} (opening "
                                                   f"{p1.gripper_opening_m * 1000:.1f} mm, effort {p1.gripper_effort_n:.1f} N)")
        if width is not None and p1.gripper_opening_m > width / 2.0 + WIDTH_MARGIN_M:
            raise PrimitiveFailure("grasp.missed", f"closed on something {2000 * p1.gripper_opening_m:.0f} mm wide, "
                                                   f"not {self.object!r} ({width * 1000:.0f} mm)")
        b.set(object=self.object, width_m=width, closed_opening_m=float(p1.gripper_opening_m), lifted_load_n=None,
              slipped=False, last_sample_s=float(p1.stamp_s))
        perceiver = getattr(ctx, "perceiver", None)
        if perceiver is not None and hasattr(perceiver, "note_grasp_close"):
            # where the hand closed: the object's pose in the hand, for a hold seen only after the lift
            perceiver.note_grasp_close(p1)
            save_tracks(target, perceiver)


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


#: ``wait_still``: a pixel whose depth changed by more than this (m) between two looks moved
#: (a scene at rest renders the same depth twice; things still settling move millimetres).
STILL_DEPTH_M = 0.005
#: ``wait_still``: the scene moves when more than this many pixels of one camera moved (after
#: an erosion by 3 x 3 pixels: a moving thing is a blob, while single pixels of depth flicker
#: from render to render).
STILL_PIXELS = 20
#: ``wait_still``: only returns nearer than this (m) count: the workspace. Beyond it, LIBERO's
#: scene camera (OSMesa) returns depths that differ by 1-5 cm from one render of a still room to
#: the next (measured: about 9000 of 65536 pixels, median 2.3 m away; none nearer than 1.5 m once
#: the scene was at rest).
STILL_RANGE_M = 1.5


class WaitStill(Primitive):
    """Hold the arm where it is until the cameras see the scene at rest, at most ``max_s`` of
    simulated time (a world just reset may still be settling: LIBERO's living-room scenes
    drop tall cartons and bottles from up to 0.6 m above the table, and they land about a
    second after the reset).

    Each look captures the depth of every camera, holds ``step_s`` and captures again; the
    scene is at rest when no camera that stayed where it was (a hand camera moves with the
    held arm's sway) has more than :data:`STILL_PIXELS` pixels whose depth changed by more
    than :data:`STILL_DEPTH_M` (both returns valid and nearer than :data:`STILL_RANGE_M`; blobs
    only, after a 3 x 3 erosion). Only the target's own
    cameras are used: nothing of the simulator's state. ``max_s`` 0 (the default) does
    nothing; a target without cameras holds nothing either. When the scene still moves after
    ``max_s``, the leaf succeeds all the same (the observation after it says what is where).

    Args:
        max_s: the longest wait, simulated s (>= 0).
        step_s: the time between the two captures of a look, simulated s (> 0).

    The trace records ``wait_still`` {leaf, waited_s, still, moving_pixels}.
    """

    TOOLS = ("hold",)

    def __init__(self, name: str, *, max_s: float = 0.0, step_s: float = 0.1):
        super().__init__(name)
        if not isinstance(max_s, (int, float)) or isinstance(max_s, bool) or not math.isfinite(max_s) or max_s < 0:
            raise ValueError(f"max_s must be a number >= 0, got {max_s!r}")
        if not isinstance(step_s, (int, float)) or isinstance(step_s, bool) or not step_s > 0:
            raise ValueError(f"step_s must be a number > 0, got {step_s!r}")
        self.max_s, self.step_s = float(max_s), float(step_s)

    def _frames(self) -> list:
        target = self.ctx.target
        with self.ctx.profiler.section("perception"):
            return [target.capture(name) for name in target.camera_names()]

    @staticmethod
    def _moving(before, after) -> int:
        """The most pixels that moved in one camera between two captures; a camera that moved
        itself (its pose 1 mm or 1 mrad apart: one on the hand, the arm held by a compliant
        controller) sees everything move, and does not count."""
        import cv2  # noqa: PLC0415 - OpenCV only where a wait looks

        most = 0
        for a, b in zip(before, after):
            if a.depth_m is None or b.depth_m is None:
                continue
            Ta, Tb = np.asarray(a.T_world_camera), np.asarray(b.T_world_camera)
            if np.abs(Ta[:3, 3] - Tb[:3, 3]).max() > 1e-3 or np.abs(Ta[:3, :3] - Tb[:3, :3]).max() > 1e-3:
                continue
            da, db = a.depth_m, b.depth_m
            moved = ((da > 0) & (db > 0) & (np.minimum(da, db) < STILL_RANGE_M)
                     & (np.abs(da - db) > STILL_DEPTH_M)).astype(np.uint8)
            most = max(most, int(np.count_nonzero(cv2.erode(moved, np.ones((3, 3), np.uint8)))))
        return most

    def on_enter(self):
        self._active = self.max_s > 0.0 and has_cameras(self.ctx.target)
        self._q = self.ctx.target.arm_qpos() if self._active else None
        self._before = self._frames() if self._active else None
        self._waited = 0.0

    def step(self):
        """One look per tick: hold ``step_s``, capture again, compare (the runner's heartbeat
        and cancellation go on between looks)."""
        if not self._active:
            return Status.SUCCESS
        target = self.ctx.target
        with self.ctx.profiler.section("simulation"):
            target.hold(self._q, duration_s=self.step_s)
        self._waited += self.step_s
        after = self._frames()
        moving = self._moving(self._before, after)
        if moving > STILL_PIXELS and self._waited < self.max_s - 1e-9:
            self._before = after
            return Status.RUNNING
        self.ctx.trace.record("wait_still", leaf=self.name, waited_s=round(self._waited, 3),
                              still=moving <= STILL_PIXELS, moving_pixels=moving)
        return Status.SUCCESS


class CheckHolding(Primitive):
    """Succeed only if proprioception says the gripper holds ``object`` now
    (``grasp.slipped`` otherwise): see :func:`~phyagentos.primitives.grasp_sense.holding_problem`.

    Records the wrist ``load`` {object, wrist_load_n, baseline_n, mass_estimate_kg}: the
    first check after the grasp (the arm lifted and still) sets the load the slip
    detector compares with.
    """

    TOOLS = ("snapshot",)

    def __init__(self, name: str, *, object: str):
        super().__init__(name)
        self.object = object

    def step(self):
        target = self.ctx.target
        if not capabilities_of(target).has_sensor("proprioception"):  # pragma: no cover - every MuJoCo arm has it
            raise PrimitiveFailure("grasp.slipped", f"target {target.name!r} cannot sense a grasp")
        p = target.proprioception()
        b = belief(target)
        planned = target.runtime_notes.get("planned_grasp") or {}
        width = planned.get("width_m") if planned.get("object") == self.object else None
        if b.object is None and closed_on_something(p, width):
            # a session that starts holding (place after pick in a fresh runtime): adopt it
            b.set(object=self.object, width_m=width, closed_opening_m=float(p.gripper_opening_m), slipped=False)
        self.ctx.trace.record("proprio", **proprio_record(target, p, phase="check_holding", leaf=self.name))
        load = wrist_load_n(target, p)
        if b.object == self.object and b.lifted_load_n is None and load is not None:
            b.set(lifted_load_n=float(load))
        # the unloaded hand's reading: from the robot model where the target predicts it
        base = target.unloaded_wrist_force_n()
        if base is None:
            base = b.baseline_force_n
        self.ctx.trace.record("load", leaf=self.name, object=self.object,
                              wrist_load_n=None if load is None else round(load, 3),
                              baseline_n=None if base is None else round(float(base), 3),
                              mass_estimate_kg=None if load is None else round(mass_estimate_kg(load), 4))
        why = holding_problem(target, p, expected=self.object, after_lift=True)
        if why is not None:
            raise PrimitiveFailure("grasp.slipped", f"expected to hold {self.object!r}: {why}")
