"""``wait_still``: a pick waits until its cameras see the scene at rest (a LIBERO world just
reset still drops its tall cartons onto the table). Judged on depth images alone: a moving
thing is a blob of changed depth in a camera that stayed put; flickering single pixels, the far
room and a camera that moved with the arm do not count."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import phyagentos.primitives.execution as execution
from phyagentos.primitives.execution import STILL_PIXELS, STILL_RANGE_M, WaitStill


class _Room:
    """A fake camera target: a 64 x 64 depth image of a table 1 m away; ``falling`` holds drop
    a 10 x 10 blob 5 cm each, then it rests; every capture flickers ``flicker`` single pixels
    by 3 cm, and a far wall (2.5 m) changes by 3 cm at every capture."""

    def __init__(self, *, falling: int, flicker: int = 30, camera_moves: bool = False):
        self.falling, self.flicker, self.camera_moves = falling, flicker, camera_moves
        self.t, self.holds, self.captures = 0.0, 0, 0
        self.rng = np.random.default_rng(0)

    def camera_names(self):
        return ("scene",)

    def arm_qpos(self):
        return np.zeros(7)

    def hold(self, q, *, duration_s):
        self.t += duration_s
        self.holds += 1

    def capture(self, name):
        self.captures += 1
        depth = np.full((64, 64), 1.0, dtype=np.float32)
        depth[:8] = 2.5 + 0.03 * (self.captures % 2)  # the far wall, flickering
        drop = min(self.holds, self.falling)
        depth[30:40, 30:40] = 0.9 - 0.05 * drop  # the carton, nearer the camera as it falls... then still
        ys, xs = self.rng.integers(8, 64, self.flicker), self.rng.integers(0, 64, self.flicker)
        depth[ys, xs] += 0.03
        T = np.eye(4)
        if self.camera_moves:
            T[0, 3] = 0.01 * self.captures
        return SimpleNamespace(depth_m=depth, T_world_camera=T)


def _run(room, monkeypatch, **params):
    monkeypatch.setattr(execution, "has_cameras", lambda target: True)
    leaf = WaitStill("WaitUntilStill", **params)
    records = []
    leaf.ctx = SimpleNamespace(target=room, profiler=SimpleNamespace(section=lambda name: _Null()),
                               trace=SimpleNamespace(record=lambda kind, **f: records.append({"kind": kind, **f})))
    from py_trees.common import Status

    leaf.on_enter()
    ticks = 1
    while leaf.step() == Status.RUNNING:  # one look per tick
        ticks += 1
        assert ticks < 100
    return records


class _Null:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_the_wait_ends_at_the_first_look_that_sees_nothing_move(monkeypatch):
    room = _Room(falling=3)
    [record] = _run(room, monkeypatch, max_s=1.5, step_s=0.1)
    # the carton moves over the first three holds and stands still over the fourth
    assert record["still"] is True and record["waited_s"] == pytest.approx(0.4) and room.holds == 4
    assert record["moving_pixels"] <= STILL_PIXELS


def test_a_scene_that_keeps_moving_is_waited_for_max_s_and_no_longer(monkeypatch):
    room = _Room(falling=100)
    [record] = _run(room, monkeypatch, max_s=0.5, step_s=0.1)
    assert record["still"] is False and record["waited_s"] == pytest.approx(0.5) and record["moving_pixels"] > 50


def test_flicker_the_far_room_and_a_camera_on_the_moving_arm_are_no_motion(monkeypatch):
    assert STILL_RANGE_M < 2.5
    [record] = _run(_Room(falling=0, flicker=300), monkeypatch, max_s=1.0)
    assert record["still"] is True and record["waited_s"] == pytest.approx(0.1)
    [record] = _run(_Room(falling=100, camera_moves=True), monkeypatch, max_s=1.0)
    assert record["still"] is True and record["moving_pixels"] == 0


def test_no_wait_is_asked_by_default_and_bad_arguments_are_refused(monkeypatch):
    room = _Room(falling=3)
    assert _run(room, monkeypatch) == [] and room.holds == 0 and room.captures == 0
    with pytest.raises(ValueError, match="max_s must be a number >= 0"):
        WaitStill("w", max_s=-1.0)
    with pytest.raises(ValueError, match="step_s must be a number > 0"):
        WaitStill("w", max_s=1.0, step_s=0.0)
