"""A LeRobot calibration file is read bounded and a bad one is refused with its file and line
before anything touches the bus (issues 32 and 33: deploy-time files)."""

from __future__ import annotations

import json
import os
import threading

import numpy as np
import pytest

from phyagentos.targets.so101_real.calibration import (
    MAX_CALIBRATION_BYTES,
    Calibration,
    CalibrationError,
    MotorCalibration,
)
from phyagentos.targets.so101_real.protocol import MOTOR_NAMES

RANGES = np.array([[-1.9, 1.9], [-1.7, 1.7], [-1.6, 1.6], [-1.6, 1.6], [-2.7, 2.8], [-0.17, 1.7]])


def _good() -> dict:
    return {n: {"id": k + 1, "drive_mode": 0, "homing_offset": 0, "range_min": 800, "range_max": 3200}
            for k, n in enumerate(MOTOR_NAMES)}


def _write(tmp_path, data) -> os.PathLike:
    path = tmp_path / "so101.json"
    path.write_text(data if isinstance(data, str) else json.dumps(data, indent=4), encoding="utf-8")
    return path


def test_a_lerobot_calibration_file_round_trips(tmp_path):
    path = _write(tmp_path, _good())
    cal = Calibration.load(path, joint_ranges=RANGES)
    assert cal.motors["gripper"] == MotorCalibration(id=6, drive_mode=0, homing_offset=0, range_min=800, range_max=3200)
    again = Calibration.load(cal.save(tmp_path / "again.json"), joint_ranges=RANGES)
    assert again.motors == cal.motors


def test_a_motor_missing_a_key_is_reported_at_its_line(tmp_path):
    data = _good()
    del data["elbow_flex"]["range_max"]
    path = _write(tmp_path, data)
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if '"elbow_flex"' in text)
    with pytest.raises(CalibrationError) as exc:
        Calibration.load(path, joint_ranges=RANGES)
    assert exc.value.code == "calibration.malformed"
    assert f"{path}:{line}: motor 'elbow_flex' needs keys" in str(exc.value) and "'range_max'" in str(exc.value)


def test_a_broken_json_file_is_reported_at_its_line(tmp_path):
    text = json.dumps(_good(), indent=4).replace('"wrist_roll": {', '"wrist_roll": {,', 1)
    path = _write(tmp_path, text)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if '"wrist_roll"' in t)
    with pytest.raises(CalibrationError, match=rf"{path}:{line}: not a JSON calibration file"):
        Calibration.load(path, joint_ranges=RANGES)


@pytest.mark.parametrize("value, why", [(True, "must be an integer, got True"), (2.5, "must be an integer, got 2.5"),
                                        ("7", "must be an integer, got '7'")])
def test_a_non_integer_field_is_refused(tmp_path, value, why):
    data = _good()
    data["shoulder_pan"]["homing_offset"] = value
    with pytest.raises(CalibrationError, match=why):
        Calibration.load(_write(tmp_path, data), joint_ranges=RANGES)


def test_an_oversized_or_deeply_nested_file_is_refused_before_parsing(tmp_path):
    big = tmp_path / "big.json"
    big.write_text(" " * (MAX_CALIBRATION_BYTES + 1) + "{}", encoding="utf-8")
    with pytest.raises(CalibrationError, match="larger than the limit"):
        Calibration.load(big, joint_ranges=RANGES)
    deep = _write(tmp_path, "[" * 5000 + "]" * 5000)
    with pytest.raises(CalibrationError, match="nested 5000 levels deep"):
        Calibration.load(deep, joint_ranges=RANGES)


def test_a_fifo_or_a_directory_named_as_the_calibration_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    result: dict = {}

    def load():
        try:
            Calibration.load(fifo, joint_ranges=RANGES)
        except CalibrationError as exc:
            result["error"] = exc

    t = threading.Thread(target=load, daemon=True)
    t.start()
    t.join(10)
    assert not t.is_alive(), "reading a FIFO with no writer blocked"
    assert "not a regular file" in str(result["error"])
    with pytest.raises(CalibrationError, match="not a regular file"):
        Calibration.load(tmp_path, joint_ranges=RANGES)
