"""TargetAdapters: standard target-space actions -> a target's native interface.

The last element of the policy flow's chain (after the action bridges and the
SafetyGuard). An adapter declares, as class data that preflight reads without
touching a target, the drivers it serves, its native :class:`ActionSpec` and the
target operations it uses; at run time it streams admitted actions one control
period at a time, checking the e-stop latch and the cancel token before every period.

:class:`MuJoCoFrankaAdapter` drives :class:`~phyagentos.targets.MuJoCoTarget`: each
period it commands ``ctrl = q + (b / kp) * qd`` (the damping feed-forward the target's
position actuators need, see :mod:`phyagentos.targets.franka_tabletop`) with ``qd`` the
finite-difference velocity of the commanded positions, plus the gripper opening, and
steps the physics for one period.

:class:`LiberoOscAdapter` drives :class:`~phyagentos.targets.libero.LiberoTarget` in its
``osc_pose_delta`` action form: each period is one ``env.step(action)`` of LIBERO's own
OSC_POSE controller at LIBERO's 20 Hz (:meth:`LiberoTarget.osc_step`), the arm control the
VLAs trained on LIBERO expect (openpi's ``examples/libero/main.py`` steps the env the same
way). The builtin flow on the same target keeps its joint servos; the runtime chooses.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from phyagentos.targets.scene import ARM_JOINT_NAMES, GRIPPER_MAX_OPENING_M

from .bridges import ActionSpec

__all__ = ["StreamResult", "MuJoCoFrankaAdapter", "LiberoOscAdapter", "TARGET_ADAPTERS", "LIBERO_CONTROL_RATE_HZ"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class StreamResult:
    """How streaming ended: ``steps`` periods sent; ``stopped`` is ``""`` when every
    action was sent, else ``estop`` or ``cancel`` (the arm was halted at once)."""

    steps: int
    stopped: str = ""


def _interrupted(estop: Any, cancel: Any) -> str | None:
    """Why streaming stops before the next period: ``"estop"``, ``"cancel"`` or ``None``."""
    if estop.is_set():
        return "estop"
    if cancel is not None and cancel.is_set():
        return "cancel"
    return None


class MuJoCoFrankaAdapter:
    """Joint-position streaming to the simulated Franka (7 joints + gripper opening).

    Args:
        target: a :class:`~phyagentos.targets.MuJoCoTarget`.
    """

    name = "mujoco_franka"
    DRIVERS = ("mujoco_franka",)
    ACTION_FORM = "joint_position_chunk"
    #: The control rate is the target's (TARGETS.md ``action.control_rate_hz``, checked
    #: against the scene's physics timestep), not fixed by the driver.
    FIXED_RATE_HZ: float | None = None
    #: Target operations the policy flow uses through this adapter.
    OPERATIONS = ("observe", "stream_joint_positions", "halt")

    @staticmethod
    def native_spec(control_rate_hz: float) -> ActionSpec:
        """The target's action language: rad in joint order, gripper opening per finger in m."""
        return ActionSpec(space="joint_position", joint_names=tuple(ARM_JOINT_NAMES), units="rad", frame="joint",
                          gripper="opening_m", rate_hz=float(control_rate_hz), max_opening_m=GRIPPER_MAX_OPENING_M)

    @staticmethod
    def control_rate_hz(timestep_s: float) -> float:
        """One command per physics step: the control rate is ``1 / timestep``."""
        return 1.0 / timestep_s

    def __init__(self, target: Any):
        self.target = target
        self._ff = np.asarray(target.feedforward_gain, dtype=float)
        self._ctrl = np.empty(8)

    def stream(self, actions: np.ndarray, *, dt: float, q_ref: np.ndarray, estop, cancel=None) -> StreamResult:
        """Send ``actions`` ``(N, 8)`` (rad x 7, opening m), one per ``dt`` s.

        Args:
            actions: admitted actions (the SafetyGuard's output).
            dt: period, s; a multiple of the physics timestep.
            q_ref: ``(7,)`` rad, the command before the first action (velocity feed-forward).
            estop: latch with ``is_set()``, checked before every period.
            cancel: optional token with ``is_set()``, checked before every period.
        """
        target = self.target
        n_sub = max(1, int(round(dt / target.timestep)))
        ff, ctrl = self._ff, self._ctrl
        prev = np.asarray(q_ref, dtype=float)
        inv_dt = 1.0 / dt
        for k in range(len(actions)):
            why = _interrupted(estop, cancel)
            if why is not None:
                self.halt()
                return StreamResult(k, why)
            q = actions[k, :7]
            ctrl[:7] = q + ff * ((q - prev) * inv_dt)
            ctrl[7] = actions[k, 7]
            for _ in range(n_sub):
                target.step(ctrl)
            prev = q
        return StreamResult(len(actions))

    def halt(self, *, settle_s: float = 0.0) -> None:
        """Stop the arm where it is (the target's halt), then hold it ``settle_s`` s."""
        self.target.halt()
        if settle_s > 0 and math.isfinite(settle_s):
            self.target.hold(duration_s=settle_s)


#: LIBERO's control frequency (robosuite ``control_freq=20`` in LIBERO's ``ControlEnv``), Hz.
LIBERO_CONTROL_RATE_HZ = 20.0


class LiberoOscAdapter:
    """OSC_POSE delta streaming to a LIBERO world, one ``env.step`` per action.

    Actions ``(N, 7)``: ``dx dy dz drx dry drz`` in [-1, 1] (LIBERO's controller scales them
    to at most 0.05 m / 0.5 rad per step) and the gripper, -1 open .. +1 closed; one per
    LIBERO control period (:data:`LIBERO_CONTROL_RATE_HZ`). The e-stop latch and the cancel
    token are checked before every period (an ``env.step`` itself is 25 physics steps that
    robosuite runs in one call).

    Args:
        target: a :class:`~phyagentos.targets.libero.LiberoTarget`.
    """

    name = "libero_osc"
    DRIVERS = ("libero",)
    ACTION_FORM = "osc_pose_delta_chunk"
    OPERATIONS = ("observe", "stream_osc_pose_delta", "halt")
    #: Fixed by the driver: LIBERO's OSC runs at 20 Hz whatever TARGETS.md says about the
    #: joint servos of the builtin flow.
    FIXED_RATE_HZ: float | None = LIBERO_CONTROL_RATE_HZ

    @staticmethod
    def native_spec(control_rate_hz: float) -> ActionSpec:
        """LIBERO's action language: OSC_POSE deltas and a signed gripper column."""
        return ActionSpec(space="osc_pose_delta", joint_names=("dx", "dy", "dz", "drx", "dry", "drz"), units="rad",
                          frame="eef", gripper="signed_closed", rate_hz=float(control_rate_hz))

    @staticmethod
    def control_rate_hz(timestep_s: float | None = None) -> float:
        """:data:`LIBERO_CONTROL_RATE_HZ` (the physics timestep does not change it)."""
        return LIBERO_CONTROL_RATE_HZ

    def __init__(self, target: Any):
        self.target = target

    def stream(self, actions: np.ndarray, *, dt: float, q_ref: np.ndarray | None = None, estop, cancel=None) -> StreamResult:
        """Send ``actions`` ``(N, 7)`` in order, one ``env.step`` each (``dt`` must be
        LIBERO's period; ``q_ref`` is unused: the controller works from the measured pose).

        Raises:
            ValueError: ``dt`` is not LIBERO's control period.
        """
        if not math.isclose(dt, 1.0 / LIBERO_CONTROL_RATE_HZ, rel_tol=1e-6):
            raise ValueError(f"LIBERO's OSC steps at {1.0 / LIBERO_CONTROL_RATE_HZ} s, not {dt} s")
        for k in range(len(actions)):
            why = _interrupted(estop, cancel)
            if why is not None:
                self.halt()
                return StreamResult(k, why)
            self.target.osc_step(actions[k])
        return StreamResult(len(actions))

    def halt(self, *, settle_s: float = 0.0) -> None:
        """Stop where the arm is (the target's joint servos hold it), then hold ``settle_s`` s."""
        self.target.halt()
        if settle_s > 0 and math.isfinite(settle_s):
            self.target.hold(duration_s=settle_s)


#: Target driver name (TARGETS.md ``driver``) -> the adapter that streams policy actions to it.
TARGET_ADAPTERS: dict[str, type] = {d: a for a in (MuJoCoFrankaAdapter, LiberoOscAdapter) for d in a.DRIVERS}
