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
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from phyagentos.targets.scene import ARM_JOINT_NAMES, GRIPPER_MAX_OPENING_M

from .bridges import ActionSpec

__all__ = ["StreamResult", "MuJoCoFrankaAdapter", "TARGET_ADAPTERS"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class StreamResult:
    """How streaming ended: ``steps`` periods sent; ``stopped`` is ``""`` when every
    action was sent, else ``estop`` or ``cancel`` (the arm was halted at once)."""

    steps: int
    stopped: str = ""


class MuJoCoFrankaAdapter:
    """Joint-position streaming to the simulated Franka (7 joints + gripper opening).

    Args:
        target: a :class:`~phyagentos.targets.MuJoCoTarget`.
    """

    name = "mujoco_franka"
    DRIVERS = ("mujoco_franka",)
    ACTION_FORM = "joint_position_chunk"
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
            if estop.is_set():
                self.halt()
                return StreamResult(k, "estop")
            if cancel is not None and cancel.is_set():
                self.halt()
                return StreamResult(k, "cancel")
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


#: Target driver name (TARGETS.md ``driver``) -> the adapter that streams policy actions to it.
TARGET_ADAPTERS: dict[str, type] = {d: a for a in (MuJoCoFrankaAdapter,) for d in a.DRIVERS}
