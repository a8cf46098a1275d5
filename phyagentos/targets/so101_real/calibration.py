"""SO-101 calibration files in LeRobot's format, and the steps <-> radians map.

The file is LeRobot's ``MotorCalibration`` JSON, one object per motor name, written by
``lerobot-calibrate --robot.type=so101_follower --robot.id=ID`` to
``~/.cache/huggingface/lerobot/calibration/robots/so101_follower/ID.json``::

    {"shoulder_pan": {"id": 1, "drive_mode": 0, "homing_offset": -1391,
                      "range_min": 761, "range_max": 3305}, ...}

``homing_offset`` is what LeRobot writes into each servo's ``Homing_Offset`` register
(so the pose held at "move to the middle of the range" reads 2047, LeRobot's half-turn
homing); ``range_min`` / ``range_max`` are the extreme ``Present_Position`` readings seen
while the user moved each joint through its range, steps. ``drive_mode`` 1 reverses the
direction. A user who ran ``lerobot-calibrate`` points ``--calibration`` at that file;
``phyagentos calibrate`` writes the same format.

Joint angles: for every joint the middle of the calibrated range is the middle of the
twin's joint range (the ``so101_new_calib`` model's ranges are the physical stops, nearly
symmetric about 0, which is LeRobot's degrees convention: 0 at mid-range)::

    q [rad] = sign * (steps - (range_min + range_max) / 2) * 2 pi / 4096 + q_mid_model

A full-turn entry (0..4095, what LeRobot records for ``wrist_roll``) has no physical
middle; its zero is the homing pose (2047.5 maps to 0 rad).
"""

from __future__ import annotations

import json
import os
import re
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.untrusted import NotRegular, loads_json, quote, read_regular

from .protocol import MOTOR_IDS, MOTOR_NAMES, RESOLUTION, STEPS_PER_RAD

__all__ = ["MotorCalibration", "Calibration", "CalibrationError", "default_calibration_path", "calibrate",
           "twin_joint_ranges"]

_KEYS = ("id", "drive_mode", "homing_offset", "range_min", "range_max")
#: Largest calibration file read, bytes (LeRobot's six motors take about 1 KB), and its
#: deepest JSON nesting (an object of motors of objects).
MAX_CALIBRATION_BYTES = 64 * 1024
MAX_CALIBRATION_DEPTH = 4


def _key_line(text: str, key: str) -> int:
    """1-based line of the first ``"key":`` in JSON ``text`` (1 when not found)."""
    m = re.search(re.escape(json.dumps(key)) + r"\s*:", text)
    return text.count("\n", 0, m.start()) + 1 if m else 1


def _integer(value: object, key: str) -> int:
    """``value`` as an int: LeRobot writes integers; a bool, a fraction or a string is refused."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
        raise ValueError(f"{key} must be an integer, got {quote(value)}")
    return int(value)


class CalibrationError(TargetError):
    """A calibration file is missing, malformed or does not fit the arm. ``code`` names
    the check (``calibration.missing``, ``calibration.malformed``, ``calibration.ids``)."""

    def __init__(self, message: str, *, code: str):
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class MotorCalibration:
    """One motor's entry (LeRobot's ``MotorCalibration``): steps, ints."""

    id: int
    drive_mode: int
    homing_offset: int
    range_min: int
    range_max: int

    @property
    def full_turn(self) -> bool:
        return self.range_min <= 0 and self.range_max >= RESOLUTION - 1


def default_calibration_path(robot_id: str = "so101") -> Path:
    """Where ``lerobot-calibrate`` writes an ``so101_follower``'s file
    (``$HF_LEROBOT_CALIBRATION`` or ``$HF_HOME/lerobot/calibration``, default
    ``~/.cache/huggingface/lerobot/calibration``) ``/robots/so101_follower/<robot_id>.json``."""
    root = os.environ.get("HF_LEROBOT_CALIBRATION")
    if not root:
        hf_home = os.environ.get("HF_HOME", str(Path.home() / ".cache" / "huggingface"))
        root = str(Path(hf_home) / "lerobot" / "calibration")
    return Path(root) / "robots" / "so101_follower" / f"{robot_id}.json"


def twin_joint_ranges() -> np.ndarray:
    """(6, 2) joint ranges of the shipped SO-101 model in :data:`MOTOR_NAMES` order, rad."""
    import mujoco  # noqa: PLC0415

    from phyagentos.targets.so101 import so101_asset_path  # noqa: PLC0415

    m = mujoco.MjModel.from_xml_path(str(so101_asset_path()))
    return np.array([m.jnt_range[m.joint(n).id] for n in MOTOR_NAMES], dtype=float)


class Calibration:
    """The six motors' calibration and the steps <-> radians map (module docstring).

    Args:
        motors: ``{name: MotorCalibration}`` for every name in :data:`MOTOR_NAMES`.
        joint_ranges: (6, 2) twin joint ranges, rad (default: the shipped model's).

    Raises:
        CalibrationError: a motor missing or an entry inconsistent (``range_min >= range_max``).
    """

    def __init__(self, motors: Mapping[str, MotorCalibration], *, joint_ranges: np.ndarray | None = None):
        missing = [n for n in MOTOR_NAMES if n not in motors]
        if missing:
            raise CalibrationError(f"calibration lacks motors {missing}; an SO-101 has {format_choices(MOTOR_NAMES)}",
                                   code="calibration.malformed")
        self.motors = {n: motors[n] for n in MOTOR_NAMES}
        for n, mc in self.motors.items():
            if not (0 <= mc.range_min < mc.range_max <= RESOLUTION - 1):
                raise CalibrationError(f"calibration of {n}: need 0 <= range_min < range_max <= 4095, got "
                                       f"{mc.range_min}..{mc.range_max}", code="calibration.malformed")
        self.joint_ranges = twin_joint_ranges() if joint_ranges is None else np.asarray(joint_ranges, float)
        mc = [self.motors[n] for n in MOTOR_NAMES]
        self.ids = tuple(m.id for m in mc)
        self._sign = np.array([-1.0 if m.drive_mode else 1.0 for m in mc])
        self._mid_steps = np.array([(m.range_min + m.range_max) / 2.0 for m in mc])
        self._mid_q = np.array([0.0 if m.full_turn else 0.5 * (lo + hi)
                                for m, (lo, hi) in zip(mc, self.joint_ranges)])
        self.range_steps = np.array([[m.range_min, m.range_max] for m in mc], dtype=float)

    # -- file ---------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike, **kwargs) -> "Calibration":
        """Read a LeRobot calibration JSON.

        Raises:
            CalibrationError: missing file (``calibration.missing``; the message says how
                to make one) or malformed content (``calibration.malformed``).
        """
        p = Path(path)
        if not p.exists():
            raise CalibrationError(
                f"no calibration file at {p}; run `phyagentos calibrate --port PORT --out {p}` (or LeRobot's "
                f"`lerobot-calibrate --robot.type=so101_follower`) with the arm powered", code="calibration.missing")
        try:
            text = read_regular(p, limit=MAX_CALIBRATION_BYTES).decode("utf-8")
            raw = loads_json(text, max_bytes=MAX_CALIBRATION_BYTES, max_depth=MAX_CALIBRATION_DEPTH)
        except NotRegular as exc:
            raise CalibrationError(f"{p}: not a regular file ({exc}); a calibration is a JSON file",
                                   code="calibration.malformed") from exc
        except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
            where = re.search(r"line (\d+)", str(exc))
            raise CalibrationError(f"{p}{':' + where.group(1) if where else ''}: not a JSON calibration file: {exc}",
                                   code="calibration.malformed") from exc
        if not isinstance(raw, dict):
            raise CalibrationError(f"{p}:1: expected an object of motors, got {type(raw).__name__}",
                                   code="calibration.malformed")
        motors = {}
        for name, entry in raw.items():
            at = f"{p}:{_key_line(text, name)}"
            if not isinstance(entry, dict) or any(k not in entry for k in _KEYS):
                raise CalibrationError(f"{at}: motor {quote(name)} needs keys {format_choices(_KEYS)}, "
                                       f"got {quote(entry)}", code="calibration.malformed")
            try:
                motors[name] = MotorCalibration(**{k: _integer(entry[k], k) for k in _KEYS})
            except (TypeError, ValueError) as exc:
                raise CalibrationError(f"{at}: motor {quote(name)}: {exc}", code="calibration.malformed") from exc
        return cls(motors, **kwargs)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the LeRobot JSON (4-space indent, as LeRobot writes it); returns the path."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps({n: asdict(m) for n, m in self.motors.items()}, indent=4) + "\n", encoding="utf-8")
        return p

    # -- maps -----------------------------------------------------------------------------
    def to_radians(self, steps: Sequence[float]) -> np.ndarray:
        """(6,) ``Present_Position`` steps -> (6,) joint angles, rad."""
        return self._sign * (np.asarray(steps, float) - self._mid_steps) / STEPS_PER_RAD + self._mid_q

    def to_steps(self, q: Sequence[float]) -> np.ndarray:
        """(6,) joint angles, rad -> (6,) goal positions, steps (rounded ints)."""
        return np.rint(self._sign * (np.asarray(q, float) - self._mid_q) * STEPS_PER_RAD + self._mid_steps).astype(int)

    def calibrated_ranges_rad(self) -> np.ndarray:
        """(6, 2) calibrated ranges in rad (sorted lo, hi)."""
        a = self.to_radians(self.range_steps[:, 0])
        b = self.to_radians(self.range_steps[:, 1])
        return np.column_stack([np.minimum(a, b), np.maximum(a, b)])

    def safe_ranges_rad(self) -> np.ndarray:
        """(6, 2) intersection of the calibrated ranges and the twin's joint ranges, rad."""
        c = self.calibrated_ranges_rad()
        return np.column_stack([np.maximum(c[:, 0], self.joint_ranges[:, 0]),
                                np.minimum(c[:, 1], self.joint_ranges[:, 1])])

    def compare_with_twin(self, *, tol_rad: float = 0.1) -> list[str]:
        """Problems of this calibration against the twin's ranges (empty: consistent).
        A calibrated range reaching more than ``tol_rad`` beyond the model's joint range,
        or covering less than half of it, is reported with the fix."""
        out = []
        c = self.calibrated_ranges_rad()
        for k, n in enumerate(MOTOR_NAMES):
            lo, hi = self.joint_ranges[k]
            if self.motors[n].full_turn:
                continue
            if c[k, 0] < lo - tol_rad or c[k, 1] > hi + tol_rad:
                out.append(f"{n}: calibrated range {c[k, 0]:+.2f}..{c[k, 1]:+.2f} rad reaches beyond the twin's "
                           f"{lo:+.2f}..{hi:+.2f} rad; re-run calibration moving the joint only to its stops "
                           f"(the guard clamps to the twin's range meanwhile)")
            if (c[k, 1] - c[k, 0]) < 0.5 * (hi - lo):
                out.append(f"{n}: calibrated range covers {c[k, 1] - c[k, 0]:.2f} rad of the twin's {hi - lo:.2f} "
                           f"rad; move the joint through its whole range while calibrating")
        return out


def calibrate(bus, *, at_middle: Callable[[], None], sweep_done: Callable[[], bool],
              sample_period_s: float = 0.02, max_duration_s: float = 600.0) -> Calibration:
    """LeRobot's calibration procedure on ``bus`` (a connected :class:`~.driver.FeetechBus`).

    1. torque off and EPROM unlocked on every servo;
    2. ``at_middle()`` returns once the arm stands in the middle of its range (the CLI
       waits for Enter); every ``Homing_Offset`` is reset to 0, the positions read, and
       ``homing_offset = position - 2047`` written (half-turn homing);
    3. positions are sampled every ``sample_period_s`` while the user moves every joint
       through its whole range, until ``sweep_done()`` is true; the extremes are
       ``range_min`` / ``range_max``, also written as the servos' position limits.

    Returns the calibration (not yet saved). Raises :class:`~.driver.BusError` on a bus
    failure and :class:`CalibrationError` (``calibration.sweep``) when a joint did not move.
    """
    bus.torque(False)
    at_middle()
    bus.write_all("Homing_Offset", [0] * 6)
    pos = np.asarray(bus.read_all("Present_Position"), dtype=int)
    homing = pos - (RESOLUTION // 2 - 1)
    bus.write_all("Homing_Offset", [int(h) for h in homing])
    start = np.asarray(bus.read_all("Present_Position"), dtype=int)
    lo, hi = start.copy(), start.copy()
    t_end = time.monotonic() + max_duration_s
    while not sweep_done() and time.monotonic() < t_end:
        p = np.asarray(bus.read_all("Present_Position"), dtype=int)
        lo, hi = np.minimum(lo, p), np.maximum(hi, p)
        time.sleep(sample_period_s)
    still = [n for k, n in enumerate(MOTOR_NAMES) if hi[k] - lo[k] < 20]
    if still:
        raise CalibrationError(f"joints {still} did not move during the range sweep; move each joint to both of its "
                               f"stops before confirming", code="calibration.sweep")
    motors = {n: MotorCalibration(id=MOTOR_IDS[n] if bus.ids is None else bus.ids[k], drive_mode=0,
                                  homing_offset=int(homing[k]), range_min=int(lo[k]), range_max=int(hi[k]))
              for k, n in enumerate(MOTOR_NAMES)}
    bus.write_all("Min_Position_Limit", [int(v) for v in lo])
    bus.write_all("Max_Position_Limit", [int(v) for v in hi])
    return Calibration(motors)

