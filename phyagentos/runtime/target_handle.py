"""TargetSessionHandle: the agent-directed flow's only door to a target.

In the agent-directed flow an agent (or scripted logic) decides step by step which
operation to invoke next: observe, decide, invoke, observe again. It never holds the
target itself; it holds a handle that

- exposes only the operations of the session's :class:`TargetToolManifest` (what
  preflight granted under the target's tool policy; ``halt`` is always allowed),
- validates every argument (types, shapes, ranges) before anything moves,
- routes every motion through the session's SafetyGuard (a joint move is timed here
  and the whole trajectory checked before it is streamed; a raw ``step`` command is
  checked as a single action),
- refreshes the target state after each call (:attr:`state`), beats the session
  heartbeat, and records each call in the trace and each refusal in the events.

Refusals raise :class:`~phyagentos.errors.TargetError` (operation not granted, bad
arguments) or :class:`~phyagentos.errors.SafetyError` (the guard's violation code).
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from phyagentos.errors import SafetyError, TargetError, format_choices
from phyagentos.motion.retime import DEFAULT_ACCELERATION_LIMITS, retime
from phyagentos.targets.contract import arm_dynamics_of

from .safety_guard import SafetyGuard

__all__ = ["TargetSessionHandle", "ALWAYS_ALLOWED", "WORLD_KEYS"]

logger = logging.getLogger(__name__)

#: Stopping is never withheld.
ALWAYS_ALLOWED = ("halt",)
#: Keys of a target's ``query_state()`` a session handle never passes on: a simulation's own
#: account of the world (object poses, the contacts' relations), ground truth.
WORLD_KEYS = frozenset({"objects", "relations"})


def _floats(value: Any, n: int, what: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise TargetError(f"{what} must be {n} numbers, got {value!r}") from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise TargetError(f"{what} must be {n} finite numbers, got {value!r}")
    return arr


def _number(value: Any, what: str, lo: float, hi: float, *, lo_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise TargetError(f"{what} must be a finite number, got {value!r}")
    if value < lo or value > hi or (lo_open and value <= lo):
        raise TargetError(f"{what} must be in {'(' if lo_open else '['}{lo}, {hi}], got {value}")
    return float(value)


class TargetSessionHandle:
    """A target as one session may use it.

    Args:
        target: the session's target (a :class:`~phyagentos.targets.MuJoCoTarget`).
        operations: the granted operations (``TargetToolManifest.operations``).
        guard: the session's SafetyGuard (shares the session's event list).
        trace: the session's trace recorder (``record(kind, **data)``), optional.
        heartbeat: called after every call (renews the session lease).
    """

    def __init__(self, target: Any, operations: Sequence[str], *, guard: SafetyGuard, trace: Any = None,
                 heartbeat: Callable[[], None] | None = None):
        self._target = target
        self._ops = tuple(sorted(set(operations) | set(ALWAYS_ALLOWED)))
        self._guard = guard
        self._trace = trace
        self._heartbeat = heartbeat
        self.events = guard.events
        self.state: dict[str, Any] = {}
        self.calls = 0
        self._perceiver: Any = None
        self._handlers: dict[str, Callable[..., Any]] = {
            "observe": self._observe, "query_state": self._query_state, "snapshot": self._snapshot,
            "render": self._render, "move_joints": self._move_joints, "set_gripper": self._set_gripper,
            "hold": self._hold, "step": self._step, "halt": self._halt, "reset": self._reset,
        }

    @property
    def operations(self) -> tuple[str, ...]:
        """What this session may invoke."""
        return self._ops

    def call(self, operation: str, **kwargs: Any) -> Any:
        """Invoke ``operation`` with keyword arguments.

        Raises:
            TargetError: the operation is not granted (valid ones listed), or an
                argument is missing, unknown or out of range.
            SafetyError: the SafetyGuard refused the motion (``code`` says why).
        """
        t0 = time.perf_counter()
        if operation not in self._ops:
            self._refuse("handle.not_permitted", operation,
                         f"operation {operation!r} is not granted to this session; granted: {format_choices(self._ops)}")
        handler = self._handlers.get(operation)
        if handler is None:
            self._refuse("handle.not_permitted", operation, f"operation {operation!r} has no handler in the handle")
        try:
            result = handler(**kwargs)
        except TypeError as exc:
            self._refuse("handle.bad_arguments", operation, f"bad arguments for {operation!r}: {exc}")
        except TargetError as exc:
            self._refuse("handle.bad_arguments", operation, str(exc))
        self.calls += 1
        if operation != "halt":
            self.state = self._robot_state()
        if self._trace is not None:
            self._trace.record("handle_call", operation=operation, ok=True, wall_ms=round((time.perf_counter() - t0) * 1e3, 3))
        if self._heartbeat is not None:
            self._heartbeat()
        return result

    def _refuse(self, code: str, operation: str, message: str) -> None:
        self.events.append({"code": code, "layer": "target_session_handle", "operation": operation, "message": message})
        if self._trace is not None:
            self._trace.record("handle_call", operation=operation, ok=False, code=code)
        logger.info("TargetSessionHandle refused %s: %s", operation, message)
        raise TargetError(message)

    # -- operations -------------------------------------------------------------------
    def _robot_state(self) -> dict:
        """The target's ``query_state()`` without what a simulation knows of the world
        (:data:`WORLD_KEYS`: a tabletop target reports its objects' true poses and contact
        relations there, ground truth); what the session may know of the world is the perceived
        ``snapshot``."""
        return {k: v for k, v in self._target.query_state().items() if k not in WORLD_KEYS}

    def _observe(self) -> dict:
        return self._robot_state()

    def _query_state(self) -> dict:
        return self._robot_state()

    def _snapshot(self) -> dict:
        """What the session may know of the world: on a target with cameras, what a perceiver
        makes of one look (:func:`~phyagentos.primitives.observation.perceive_now`; the
        simulator's poses are ground truth, for scoring only, never handed to a session);
        otherwise the target's own snapshot (a game's symbolic view, a camera-less world)."""
        from phyagentos.primitives.observation import has_cameras, make_perceiver, perceive_now  # noqa: PLC0415

        target = self._target
        if not has_cameras(target):
            return target.snapshot()
        if self._perceiver is None:  # one per session: its tracks carry from look to look
            self._perceiver = make_perceiver(target)
        return perceive_now(target, self._perceiver)

    def _render(self, camera: str = "overview", width: int = 224, height: int = 224) -> np.ndarray:
        for name, v in (("width", width), ("height", height)):
            if isinstance(v, bool) or not isinstance(v, int) or not 16 <= v <= 2048:
                raise TargetError(f"render: {name} must be an integer in [16, 2048], got {v!r}")
        return self._target.render(camera=camera, width=width, height=height)

    def _move_joints(self, q: Sequence[float], speed_scale: float = 0.5, tracking_tol_rad: float = 0.05) -> dict:
        target, guard = self._target, self._guard
        goal = _floats(q, len(guard.limits.joint_names), "move_joints: q")
        scale = _number(speed_scale, "move_joints: speed_scale", 0.0, 1.0, lo_open=True)
        tol = _number(tracking_tol_rad, "move_joints: tracking_tol_rad", 0.0, 0.5, lo_open=True)
        start = target.arm_qpos()
        dt = float(target.timestep)
        traj = retime(np.array([start, goal]), vel_limits=target.velocity_limits() * scale,
                      acc_limits=np.array(DEFAULT_ACCELERATION_LIMITS) * scale, dt=dt,
                      dynamics=arm_dynamics_of(target))
        # Bounds first: a goal outside the joint range is refused as such, not as the
        # spline's overshoot near it.
        guard.sync(start)
        decision = guard.check(goal[None, :], dt=max(traj.duration, dt), qd=np.zeros((1, goal.size)),
                               qdd=np.zeros((1, goal.size)), source="handle.move_joints")
        if decision.admitted:
            guard.sync(start)
            decision = guard.check(np.asarray(traj.q[1:], dtype=float), dt=dt, qd=np.asarray(traj.qd[1:], dtype=float),
                                   qdd=np.asarray(traj.qdd[1:], dtype=float), source="handle.move_joints")
        if not decision.admitted or decision.outcome == "clamp":
            if decision.outcome == "halt":
                target.halt()
            raise SafetyError(f"move_joints refused: {decision.message}", code=decision.code or "safety.unknown")
        result = target.execute_trajectory(traj, tracking_tol_rad=tol)
        guard.commit(np.asarray(traj.q, dtype=float), dt=dt, qd_end=np.zeros(goal.size))
        return result.to_dict()

    def _set_gripper(self, opening_m: float) -> dict:
        lo, hi = self._guard.limits.gripper_range
        o = _number(opening_m, "set_gripper: opening_m", lo, hi)
        if self._guard.estop_engaged():
            self._target.halt()
            raise SafetyError("set_gripper refused: e-stop engaged", code="safety.estop")
        return self._target.set_gripper(opening_m=o).to_dict()

    def _hold(self, duration_s: float = 0.5) -> dict:
        d = _number(duration_s, "hold: duration_s", 0.0, self._guard._max_duration)
        if self._guard.estop_engaged():
            self._target.halt()
            raise SafetyError("hold refused: e-stop engaged", code="safety.estop")
        n = self._target.hold(duration_s=d)
        return {"steps": n, "sim_time_s": self._target.sim_time}

    def _step(self, ctrl: Sequence[float]) -> None:
        guard, target = self._guard, self._target
        arr = np.asarray(ctrl, dtype=float).reshape(1, -1)
        decision = guard.check(arr, dt=float(target.timestep), source="handle.step")
        if not decision.admitted:
            if decision.outcome == "halt":
                target.halt()
            raise SafetyError(f"step refused: {decision.message}", code=decision.code or "safety.unknown")
        target.step(decision.actions[0])
        guard.commit(decision.actions, dt=float(target.timestep))

    def _halt(self) -> None:
        self._target.halt()
        self._guard.sync(self._target.arm_qpos())

    def _reset(self, seed: int | None = None) -> dict:
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
            raise TargetError(f"reset: seed must be an integer or None, got {seed!r}")
        out = self._target.reset(seed=seed)
        self._guard.sync(self._target.arm_qpos())
        return out

    def describe(self) -> Mapping[str, Any]:
        """What the agent may do: operations and the current state."""
        return {"operations": list(self._ops), "state": self.state}
