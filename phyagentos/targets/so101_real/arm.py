"""The SO-101's control loop on the bus: read, check, command, once per control period.

:class:`SO101Arm` joins the :class:`~.driver.FeetechBus`, the
:class:`~.calibration.Calibration` and the :class:`~.guard.BusSafetyGuard`. Each control
period of :meth:`SO101Arm.follow`:

1. the e-stop latch is checked (and polled every millisecond while the loop waits for
   the next period, so an e-stop reaches the bus within one period); a latch that takes
   listeners (:class:`~phyagentos.runtime.safety_guard.EStopLatch`) has the stop put on the
   bus by the thread that engages it, at once, whether or not this loop is being scheduled
   (the bus work of both is serialised by one lock);
2. one GROUP_SYNC_READ of the state block; the reading is converted to radians and
   checked (range, load, status bits, temperature);
3. the period's goal is checked (calibrated range, step, velocity) and sent as one
   GROUP_SYNC_WRITE of ``Goal_Position``.

Periods are paced on ``time.perf_counter``. A period that would start more than one period
late (this process was descheduled, the bus answered late) starts now instead: the missed
periods are not made up by sending their goals back to back (:meth:`SO101Arm._slot`), so
the servos never get several periods of motion within milliseconds and the guard's
velocity check, which takes goals to be one period apart, holds.

Any stop (a reading violation, a bus failure, the e-stop) applies the declared
``stop_policy`` at once (``hold``: arm goals := last good measured positions, the jaw keeps
its goal so a held object stays held; ``torque_off``)
and latches: no goal is sent until :meth:`SO101Arm.clear_stop`. With ``dry_run`` the
arm reads (positions, faults) but never enables torque and never writes a goal.

Joint vectors are (6,) rad in :data:`~.protocol.MOTOR_NAMES` order (five arm joints,
then the jaw angle).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field, replace

import numpy as np

from phyagentos.errors import TargetError

from .calibration import Calibration
from .driver import BusError, BusState, FeetechBus
from .guard import BusLimits, BusSafetyGuard, BusSafetyStop
from .protocol import MOTOR_NAMES, RESOLUTION

__all__ = ["SO101Arm", "FollowResult"]

log = logging.getLogger(__name__)


@dataclass
class FollowResult:
    """Outcome of :meth:`SO101Arm.follow`: ``completed``; ``periods`` run; ``code`` and
    ``reason`` of a stop (empty when completed); ``max_tracking_error_rad`` (measured vs
    the goal sent one period earlier, arm joints); ``overruns`` periods whose bus work
    took longer than the period; ``late`` periods that started more than a period late
    (the schedule moved on to now: the motion ends that much later); ``io_s`` per-period
    read+write durations, s."""

    completed: bool
    periods: int
    code: str = ""
    reason: str = ""
    max_tracking_error_rad: float = 0.0
    overruns: int = 0
    late: int = 0
    io_s: list = field(default_factory=list)


class SO101Arm:
    """A calibrated SO-101 on a Feetech bus (module docstring).

    Args:
        port: serial device.
        calibration: the arm's :class:`Calibration` (ids, offsets, ranges).
        limits: bus guard limits and ``stop_policy``.
        control_period_s: the period of :meth:`follow`, s.
        estop: an e-stop latch (anything with ``is_set()``), checked every period; one with
            ``add_listener`` / ``remove_listener`` also applies the stop from the engaging
            thread while the arm is connected.
        dry_run: read only: never torque on, never a goal on the bus.
    """

    def __init__(self, port: str, *, calibration: Calibration, limits: BusLimits | None = None,
                 control_period_s: float = 0.02, estop=None, dry_run: bool = False, retries: int = 2):
        if not (0.002 <= control_period_s <= 0.5):
            raise TargetError(f"control_period_s must be in [0.002, 0.5] s, got {control_period_s}")
        self.calibration = calibration
        self.bus = FeetechBus(port, ids=calibration.ids, retries=retries)
        self.limits = limits or BusLimits()
        self.dt = float(control_period_s)
        self.guard = BusSafetyGuard(calibration.safe_ranges_rad(), self.limits, self.dt)
        self._bus_lock = threading.RLock()  # one bus transaction at a time: the loop's and an e-stop's
        self._connected = False
        self._estop = None
        self.estop = estop
        self.dry_run = bool(dry_run)
        self.last_q: np.ndarray | None = None
        self.goal_q: np.ndarray | None = None  # the servos' goals after connect, rad
        self.last_state: BusState | None = None
        self.estop_handled_at: float | None = None  # perf_counter when the e-stop's bus write went out
        self._next_period: float | None = None  # perf_counter of the next period (paces consecutive calls)
        self._prev_sent: np.ndarray | None = None  # goal sent in the previous period (tracking reference)
        self._jaw_steps: int | None = None  # the jaw's goal on the bus, steps
        self._pos_shift = np.zeros(6, dtype=np.int64)  # dry run: servo offsets vs the file's, steps

    # -- lifecycle ------------------------------------------------------------------------
    def connect(self) -> list[dict]:
        """Open, check ids and models, write the calibration (if the servos do not hold it
        already), read the pose, and (unless ``dry_run``) make sure torque is on: an arm
        already holding keeps its goals (a grasp stays a grasp between sessions); a limp one
        is enabled holding its present pose. :attr:`goal_q` is the servos' goal after this.
        Returns the servos found.

        Raises:
            BusError: ``bus.port``, ``bus.id_mismatch``, ``bus.model``, ``bus.timeout``...
            BusSafetyStop: the first reading is already out of range (nothing enabled).
        """
        found = self.bus.connect()
        wrote = False if self.dry_run else self.bus.write_calibration(self.calibration)
        if self.dry_run:  # nothing is written: apply the file's homing offsets in software instead
            regs = np.array(self.bus.read_all("Homing_Offset"))
            self._pos_shift = regs - np.array([self.calibration.motors[n].homing_offset for n in MOTOR_NAMES])
        q, state = self._read_checked()
        goals = [int(p) for p in state.position]
        if not self.dry_run:
            if not wrote and all(self.bus.read_all("Torque_Enable")):
                goals = self.bus.read_all("Goal_Position")
            else:
                self.bus.torque(True, goals=goals)
        self.goal_q = self.calibration.to_radians(goals)
        self._jaw_steps = int(goals[5])
        self.guard.sync(self.goal_q)
        self._connected = True
        self._listen(True)
        return found

    def close(self) -> None:
        """Close the port. The servos keep their last goal (holding); torque is not dropped,
        so the arm does not fall when the program ends (``release()`` first for that)."""
        self._listen(False)
        self._connected = False
        with self._bus_lock:
            self.bus.close()

    # -- e-stop ---------------------------------------------------------------------------
    @property
    def estop(self):
        """The e-stop latch (``None``: none); setting it moves the listener to the new one."""
        return self._estop

    @estop.setter
    def estop(self, latch) -> None:
        self._listen(False)
        self._estop = latch
        self._listen(True)

    def _listen(self, on: bool) -> None:
        """(Un)register :meth:`_on_estop` with the latch, where it takes listeners (only while
        connected: a closed port has no bus to stop)."""
        latch = self._estop
        if latch is None or not hasattr(latch, "add_listener"):
            return
        if on and self._connected:
            latch.add_listener(self._on_estop)
        elif not on:
            latch.remove_listener(self._on_estop)

    def _on_estop(self, reason: str) -> None:
        """The latch's listener: the stop on the bus from the engaging thread."""
        self._apply_stop("safety.estop", f"e-stop engaged: {reason}" if reason else "e-stop engaged")

    def release(self) -> None:
        """Torque off on every servo (the arm goes limp)."""
        self.bus.torque(False)

    # -- one period -----------------------------------------------------------------------
    def _read_checked(self) -> tuple[np.ndarray, BusState]:
        state = self.bus.sync_read_state()
        if self._pos_shift.any():
            state = replace(state, position=(state.position + self._pos_shift) % RESOLUTION)
        q = self.calibration.to_radians(state.position)
        self.guard.check_reading(q, state)
        self.last_q, self.last_state = q, state
        return q, state

    def read(self) -> tuple[np.ndarray, BusState]:
        """One checked sync read: ``(q (6,) rad, BusState)``. A bus failure or a reading
        violation stops the arm (policy) and raises (:class:`BusError` / :class:`BusSafetyStop`)."""
        try:
            with self._bus_lock:
                return self._read_checked()
        except BusError as exc:
            self._apply_stop(exc.code, str(exc))
            raise
        except BusSafetyStop as exc:
            self._apply_stop(exc.code, str(exc), already_latched=True)
            raise

    def send(self, q_goal) -> np.ndarray:
        """Check and send one goal (6,) rad; returns the admitted goal. A rejection sends
        nothing and raises :class:`BusSafetyStop` (outcome ``reject``)."""
        with self._bus_lock:  # checked and sent as one: an e-stop between them would be overtaken
            q = self.guard.check_goal(q_goal)
            self._prev_sent = q
            if not self.dry_run:
                steps = self.calibration.to_steps(q)
                self._jaw_steps = int(steps[5])
                try:
                    self.bus.sync_write_goals(steps)
                except BusError as exc:
                    self._apply_stop(exc.code, str(exc))
                    raise
        return q

    def engage_estop(self, reason: str = "e-stop") -> None:
        """Stop now (the e-stop path): latch and apply the stop policy on the bus."""
        self._apply_stop("safety.estop", reason)

    def clear_stop(self) -> None:
        """Release a latched stop (operator decision) and re-sync the guard to the pose."""
        self.guard.clear()
        q, _ = self.read()
        self.guard.sync(q)
        self._prev_sent = None

    @property
    def stopped(self) -> str | None:
        return self.guard.stopped

    def _apply_stop(self, code: str, message: str, *, already_latched: bool = False) -> None:
        with self._bus_lock:  # the loop's thread or the e-stop's: the first one applies it
            first = self.guard.stopped is None or already_latched
            if not already_latched:
                self.guard.stop(code, message)
            self._prev_sent = None
            if not first or self.dry_run:
                return
            try:
                if self.limits.stop_policy == "torque_off":
                    self.bus.torque(False)
                elif self.last_state is not None:  # arm where it is; the jaw keeps squeezing what it holds
                    goals = [int(p) for p in self.last_state.position]
                    if self._jaw_steps is not None:
                        goals[5] = self._jaw_steps
                    self.bus.sync_write_goals(goals)
                self.guard.event(code, self.limits.stop_policy, f"stop applied on the bus ({self.limits.stop_policy})")
            except BusError as exc:  # the bus itself is gone: nothing more can be sent
                self.guard.event("bus.stop_failed", "stop", f"could not apply {self.limits.stop_policy}: {exc}")
            if code == "safety.estop":
                self.estop_handled_at = time.perf_counter()

    # -- streaming --------------------------------------------------------------------------
    def _wait(self, deadline: float) -> bool:
        """Sleep until ``deadline`` (perf_counter), polling the e-stop every ms; True if engaged."""
        while True:
            if self.estop is not None and self.estop.is_set():
                return True
            left = deadline - time.perf_counter()
            if left <= 0:
                return False
            time.sleep(min(left, 0.001))

    def follow(self, Q, *, tracking_tol_rad: float = 0.15, on_period=None) -> FollowResult:
        """Stream goals ``Q`` (N, 6) rad, one per control period, reading before each.

        ``on_period(k, q_measured)`` runs after each period's bus work (the target mirrors
        the twin there). Stops on the e-stop, a guard violation, a bus failure or a
        tracking error above ``tracking_tol_rad`` (arm joints, against the goal sent one
        period earlier; a stall or a collision). Never raises for those: the result says.
        A period more than one period late starts now (:meth:`_slot`): no catch-up burst.
        """
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != 6:
            raise TargetError(f"follow: goals must have shape (N, 6), got {Q.shape}")
        res = FollowResult(completed=False, periods=0)
        t_next = self._period_start()
        prev_goal = self._prev_sent
        for k in range(len(Q)):
            t_next = self._slot(t_next, res)
            if self._wait(t_next):
                self._apply_stop("safety.estop", "e-stop engaged")
                return self._end(res, "safety.estop", "e-stop engaged")
            t0 = time.perf_counter()
            try:
                q, _ = self.read()
                if prev_goal is not None:
                    err = float(np.max(np.abs(q[:5] - prev_goal[:5])))
                    res.max_tracking_error_rad = max(res.max_tracking_error_rad, err)
                    if err > tracking_tol_rad:
                        self._apply_stop("bus.tracking", f"tracking error {err:.3f} rad above {tracking_tol_rad} rad")
                        return self._end(res, "bus.tracking", f"tracking error {err:.3f} rad above "
                                                              f"{tracking_tol_rad} rad at period {k}")
                prev_goal = self.send(Q[k])
            except (BusError, BusSafetyStop) as exc:
                return self._end(res, exc.code, str(exc))
            io = time.perf_counter() - t0
            res.io_s.append(io)
            res.overruns += io > self.dt
            res.periods = k + 1
            if on_period is not None:
                on_period(k, q)
            t_next += self.dt
            self._next_period = t_next
        res.completed = True
        return res

    def _period_start(self) -> float:
        """When the next period starts: the paced slot after the previous call's last period,
        or now when that slot is more than a period in the past (the caller paused)."""
        return self._slot(self._next_period)

    def _slot(self, t: float | None, res: FollowResult | None = None) -> float:
        """The start of a period, perf_counter s: ``t``, or now when ``t`` is more than one
        period in the past (this loop, or the bus's answer, was held up: a descheduled
        process, a busy machine); such a period is counted in ``res.late``.

        Missed periods are not made up. Sending their goals back to back would hand the
        servos several periods of motion within a few milliseconds: they lunge at full speed
        (load near its limit, a tracking error that is only the lunge's), and the guard's
        velocity check, which takes goals to be one period apart, would not see it. The
        motion resumes where it stopped, one goal per period; it ends that much later.
        """
        now = time.perf_counter()
        if t is None or t > now - self.dt:
            return now if t is None else t
        if res is not None:
            res.late += 1
            log.debug("so101 arm: period %d started %.0f ms late; the schedule moves on to now",
                      res.periods, (now - t) * 1000.0)
        return now

    def settle(self, q_goal, *, timeout_s: float = 1.0, tol_rad: float = 0.03, on_period=None) -> FollowResult:
        """Hold goal ``q_goal`` (6,) until the arm joints are within ``tol_rad`` or
        ``timeout_s``; the result's ``completed`` says whether they got there."""
        n = max(1, int(round(timeout_s / self.dt)))
        goal = np.asarray(q_goal, float)
        res = FollowResult(completed=False, periods=0)
        t_next = self._period_start()
        for k in range(n):
            t_next = self._slot(t_next, res)
            if self._wait(t_next):
                self._apply_stop("safety.estop", "e-stop engaged")
                return self._end(res, "safety.estop", "e-stop engaged")
            try:
                q, _ = self.read()
                self.send(goal)
            except (BusError, BusSafetyStop) as exc:
                return self._end(res, exc.code, str(exc))
            res.periods = k + 1
            if on_period is not None:
                on_period(k, q)
            t_next += self.dt
            self._next_period = t_next
            if float(np.max(np.abs(q[:5] - goal[:5]))) < tol_rad:
                res.completed = True
                return res
        return res

    @staticmethod
    def _end(res: FollowResult, code: str, reason: str) -> FollowResult:
        res.code, res.reason = code, reason
        return res
