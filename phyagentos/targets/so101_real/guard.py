"""The bus-level SafetyGuard of the real SO-101: every goal and every reading is checked.

The runtime's :class:`~phyagentos.runtime.safety_guard.SafetyGuard` checks whole
commands against the twin's model before they reach the target; this guard sits in the
target's control loop, right before the bytes go on the bus, and is bound to the
*calibrated* arm:

=======================  ===============================================================
``bus.joint_range``      a goal outside the calibrated range intersected with the twin's
                         joint range (rejected: nothing is sent)
``bus.step``             a goal further than ``max_step_rad`` from the last goal sent
``bus.velocity``         a goal implying more than ``max_velocity_rad_s`` over one period
``bus.nan``              a goal that is not 6 finite numbers
``bus.reading_range``    a measured position more than ``reading_margin_rad`` outside the
                         calibrated range (a sensor fault, a slipped horn)
``bus.load``             an arm joint's ``|Present_Load|`` above ``max_load_permille`` for
                         ``load_periods`` consecutive periods (a stall, a collision); the
                         jaw is exempt: closing on an object is a deliberate stall
``bus.overload``         a servo reports its overload bit (32)
``bus.servo_error``      any other status bit (voltage, angle sensor, overheat, current)
``bus.temperature``      a servo above ``max_temperature_c``
``bus.timeout`` /        the bus did not answer / answered garbage (from
``bus.corrupt``          :class:`~.driver.BusError`)
``safety.estop``         the e-stop latch
=======================  ===============================================================

A command violation rejects that command. A reading violation, a bus failure or the
e-stop *stops the arm* by the declared ``stop_policy``: ``hold`` (goals := the last good
measured positions, torque stays on: the arm does not sag) or ``torque_off`` (every
servo limp: the arm falls onto whatever is under it). The stop latches: no goal is sent
again until :meth:`BusSafetyGuard.clear` (an operator decision). Every intervention is an
event ``{code, outcome, message, t}`` (the evidence the verifier reads).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from phyagentos.errors import SafetyError, format_choices

from .protocol import ERR_OVERLOAD, MOTOR_NAMES

__all__ = ["BusLimits", "BusSafetyGuard", "BusSafetyStop", "STOP_POLICIES"]

log = logging.getLogger(__name__)

STOP_POLICIES: tuple[str, ...] = ("hold", "torque_off")


class BusSafetyStop(SafetyError):
    """The guard refused a command or stopped the arm; ``code`` as in the module table,
    ``outcome`` ``reject`` or ``stop``."""

    def __init__(self, message: str, *, code: str, outcome: str):
        super().__init__(message, code=code)
        self.outcome = outcome


@dataclass(frozen=True)
class BusLimits:
    """Limits of the bus guard (units in the names). ``stop_policy``: ``hold`` or
    ``torque_off``. Defaults fit an SO-101 on a 12 V supply at a 50 Hz control period."""

    max_step_rad: float = 0.25
    max_velocity_rad_s: float = 4.0
    max_load_permille: int = 850
    load_periods: int = 3
    max_temperature_c: int = 65
    range_margin_rad: float = 0.0
    reading_margin_rad: float = 0.15
    stop_policy: Literal["hold", "torque_off"] = "hold"

    def __post_init__(self) -> None:
        if self.stop_policy not in STOP_POLICIES:
            raise SafetyError(f"unknown stop_policy {self.stop_policy!r}; valid: {format_choices(STOP_POLICIES)}",
                              code="bus.config")

    @classmethod
    def from_dict(cls, raw: dict | None) -> "BusLimits":
        """From a mapping (e.g. TARGETS.md ``constraints.bus_limits``); unknown keys raise."""
        raw = dict(raw or {})
        names = set(cls.__dataclass_fields__)
        bad = sorted(set(raw) - names)
        if bad:
            raise SafetyError(f"unknown bus limit(s) {bad}; valid: {format_choices(sorted(names))}", code="bus.config")
        return cls(**raw)


@dataclass
class BusSafetyGuard:
    """Checks goals (rad, joint order :data:`MOTOR_NAMES`) and readings of one arm.

    Args:
        ranges_rad: (6, 2) allowed joint ranges, rad (calibrated range x twin range).
        limits: :class:`BusLimits`.
        dt: control period, s.
    """

    ranges_rad: np.ndarray
    limits: BusLimits = field(default_factory=BusLimits)
    dt: float = 0.02
    events: list = field(default_factory=list)
    stopped: str | None = None  # code of the latched stop
    _last_goal: np.ndarray | None = None
    _load_count: np.ndarray = field(default_factory=lambda: np.zeros(6, dtype=int))

    def event(self, code: str, outcome: str, message: str) -> dict:
        ev = {"code": code, "outcome": outcome, "message": message, "t": time.time(), "layer": "bus"}
        self.events.append(ev)
        log.warning("bus guard %s (%s): %s", code, outcome, message)
        return ev

    def sync(self, q: np.ndarray) -> None:
        """The last goal := the measured ``q`` (6,) rad (at connect, after a stop)."""
        self._last_goal = np.asarray(q, float).copy()

    def check_goal(self, q: np.ndarray) -> np.ndarray:
        """Admit goal ``q`` (6,) rad or raise :class:`BusSafetyStop` (outcome ``reject``;
        ``stop`` when a stop is latched)."""
        if self.stopped is not None:
            raise BusSafetyStop(f"the arm is stopped ({self.stopped}); clear the stop first", code=self.stopped,
                                outcome="stop")
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            self._reject("bus.nan", f"goal must be 6 finite angles, got {q!r}")
        lo = self.ranges_rad[:, 0] - self.limits.range_margin_rad
        hi = self.ranges_rad[:, 1] + self.limits.range_margin_rad
        out = np.flatnonzero((q < lo - 1e-9) | (q > hi + 1e-9))
        if out.size:
            k = int(out[0])
            self._reject("bus.joint_range", f"{MOTOR_NAMES[k]} goal {q[k]:+.3f} rad outside its calibrated range "
                                            f"{lo[k]:+.3f}..{hi[k]:+.3f} rad")
        if self._last_goal is not None:
            step = np.abs(q - self._last_goal)
            k = int(np.argmax(step[:5]))  # the jaw may snap; the arm may not
            if step[k] > self.limits.max_step_rad:
                self._reject("bus.step", f"{MOTOR_NAMES[k]} goal jumps {step[k]:.3f} rad in one command "
                                         f"(max {self.limits.max_step_rad} rad)")
            if step[k] / self.dt > self.limits.max_velocity_rad_s:
                self._reject("bus.velocity", f"{MOTOR_NAMES[k]} goal implies {step[k] / self.dt:.2f} rad/s "
                                             f"(max {self.limits.max_velocity_rad_s} rad/s)")
        self._last_goal = q.copy()
        return q

    def check_reading(self, q: np.ndarray, state) -> None:
        """Check a reading: ``q`` (6,) rad and the raw :class:`~.driver.BusState`; raises
        :class:`BusSafetyStop` (outcome ``stop``) and latches the stop on a violation."""
        m = self.limits.reading_margin_rad
        out = np.flatnonzero((q < self.ranges_rad[:, 0] - m) | (q > self.ranges_rad[:, 1] + m))
        if out.size:
            k = int(out[0])
            self._stop("bus.reading_range", f"{MOTOR_NAMES[k]} reads {q[k]:+.3f} rad, outside its range "
                                            f"{self.ranges_rad[k, 0]:+.3f}..{self.ranges_rad[k, 1]:+.3f} rad "
                                            f"(+-{m} rad): sensor fault or slipped horn")
        st = np.asarray(state.status)
        if np.any(st & ERR_OVERLOAD):
            k = int(np.flatnonzero(st & ERR_OVERLOAD)[0])
            self._stop("bus.overload", f"{MOTOR_NAMES[k]} reports overload (status bit 32): its protection "
                                       f"dropped the torque")
        if np.any(st):
            k = int(np.flatnonzero(st)[0])
            self._stop("bus.servo_error", f"{MOTOR_NAMES[k]} reports status error bits {int(st[k]):#04x}")
        hot = np.flatnonzero(np.asarray(state.temperature) > self.limits.max_temperature_c)
        if hot.size:
            k = int(hot[0])
            self._stop("bus.temperature", f"{MOTOR_NAMES[k]} at {int(state.temperature[k])} C "
                                          f"(max {self.limits.max_temperature_c} C)")
        over = np.abs(np.asarray(state.load)) > self.limits.max_load_permille
        over[5] = False  # the jaw squeezing an object is a deliberate stall (its grip is bounded by the servo)
        self._load_count = np.where(over, self._load_count + 1, 0)
        if np.any(self._load_count >= self.limits.load_periods):
            k = int(np.argmax(self._load_count))
            self._stop("bus.load", f"{MOTOR_NAMES[k]} load {int(state.load[k]) / 10:.1f} % above "
                                   f"{self.limits.max_load_permille / 10:.1f} % for {self.limits.load_periods} "
                                   f"periods: stalled or in collision")

    def stop(self, code: str, message: str) -> dict:
        """Latch a stop (bus failures, e-stop) and record it; returns the event."""
        if self.stopped is None:
            self.stopped = code
        return self.event(code, "stop", message)

    def clear(self) -> None:
        """Release a latched stop (an operator decision after fixing the cause)."""
        self.stopped = None
        self._load_count[:] = 0

    def _reject(self, code: str, message: str) -> None:
        self.event(code, "reject", message)
        raise BusSafetyStop(message, code=code, outcome="reject")

    def _stop(self, code: str, message: str) -> None:
        self.stop(code, message)
        raise BusSafetyStop(message, code=code, outcome="stop")

