"""How far off the plane a thing stands on its support (``Track.rest_gap_m``), and its own height
from it: LIBERO's living-room table puts what rests on it 1.2 cm above the top the cameras see,
its kitchen tables do not (heights of the lowest points on generated scenes, docs/libero.md)."""

from __future__ import annotations

import numpy as np

from phyagentos.perception.tracks import REST_GAP_MIN_M, Track

CUT_M = 0.005  # table.object_min_height_m: the cloud keeps points this far above the plane


def _track(height_m: float) -> Track:
    return Track(name="cream_cheese_1", position=np.zeros(3), var_xy=1e-6, yaw=0.0, var_yaw=1e-4,
                 half_extents=np.array([0.042, 0.022, 0.5 * height_m]), shape="box", colour_rgb=np.zeros(3),
                 points=400, confidence=1.0, last_seen_s=0.0, bottom_m=0.0)


def _box_points(foot_m: float, top_m: float, n: int = 400) -> np.ndarray:
    return np.linspace(foot_m, top_m, n)


def test_a_thing_whose_foot_reaches_the_cut_stands_on_the_plane_and_keeps_its_height():
    t = _track(0.0196)
    t.note_rest_gap(_box_points(CUT_M + 0.0004, 0.0196), CUT_M)  # a kitchen table: down to the cut
    assert t.rest_gap_m == 0.0 and t.standing_height_m() == 0.0196


def test_the_gap_under_its_foot_is_the_least_seen_and_comes_off_its_height():
    t = _track(0.031)  # its look on the living-room table: 1.9 cm of box over 1.2 cm of gap
    assert t.standing_height_m() == 0.031  # never seen standing: nothing taken off
    t.note_rest_gap(_box_points(0.016, 0.031), CUT_M)  # its foot hidden by a neighbour: seen higher
    t.note_rest_gap(_box_points(0.0123, 0.031), CUT_M)
    t.note_rest_gap(_box_points(0.020, 0.031), CUT_M)  # a later, worse view does not raise it again
    assert abs(t.rest_gap_m - 0.0123) < 1e-4
    assert abs(t.standing_height_m() - (0.031 - 0.0123)) < 1e-4
    t.note_rest_gap(_box_points(CUT_M + 0.5 * REST_GAP_MIN_M, 0.031), CUT_M)  # seen down to the cut once
    assert t.rest_gap_m == 0.0


def test_a_gap_never_takes_more_than_half_its_height():
    t = _track(0.02)
    t.note_rest_gap(_box_points(0.015, 0.02), CUT_M)
    assert t.standing_height_m() == 0.01
