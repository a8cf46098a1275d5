"""The stove and its knob perceived on a recorded cloud of a generated LIBERO scene (issue 28).

``tests/data/libero_knob_cloud.npz``: the perceiver's object cloud, its height crop raised for
the fixtures, of one generated LIBERO-90 scene (task 20, "turn on the stove"; LIBERO's
placement sampler with seed 71000: never an init state) with the stove's knob set to 0.9 rad,
recorded by ``bench/libero_knob.py --record``, with the true knob angle and axis, the cook
region's true centre (scoring only) and the looks as ``measure_fixture_looks`` measured them
(the stove alone on other generated scenes; its ``knob`` from its model).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from libero_clouds import libero_perception_config

from phyagentos.perception import PerceptionConfig
from phyagentos.perception.cloud import Cloud
from phyagentos.perception.fixtures import KNOB_SIGMA_RAD, detect_fixtures, find_by_knob, fixtures_from_declared, knob_reading

DATA = Path(__file__).parent / "data" / "libero_knob_cloud.npz"
TABLE_Z = 0.9  # LIBERO's kitchen table top (bench.libero.LIBERO_CELLS), the support plane of the recording


def _recorded(top_m=None):
    z = np.load(DATA)
    meta = json.loads(str(z["meta"]))
    points = z["points_mm"].astype(np.float64) / 1000.0
    heights = z["heights_mm"].astype(np.float64) / 1000.0
    cloud = Cloud(points.astype(np.float32), z["rgb"], np.ones(len(points), np.float32), np.zeros(len(points), np.int64))
    stove = dict(meta["looks"]["flat_stove"])
    if top_m is not None:
        stove["size_m"] = [*stove["size_m"][:2], top_m]
    looks = fixtures_from_declared({"fixtures": [{"name": meta["stove"], "class": "flat_stove", **stove}]})
    return cloud, heights, meta, looks[0]


def _config() -> PerceptionConfig:
    return libero_perception_config(TABLE_Z)


def _place_error(look, sighting, meta) -> float:
    centre, _, _ = look.place_patch(sighting.position[:2], sighting.half_xy_world)
    return float(np.linalg.norm(centre - np.asarray(meta["cook_region"])))


def test_the_stove_is_found_and_its_knob_read_at_the_angle_it_was_turned_to():
    cloud, heights, meta, look = _recorded()
    found = detect_fixtures(cloud, heights, [look], _config())
    s = found[look.name]
    assert s.found_by == "size" and _place_error(look, s, meta) < 0.03
    yaw, points = knob_reading(cloud.points, heights, look.knob, s.position[:2])
    assert points >= 30
    assert abs(look.knob.joint_position(yaw) - meta["angle_rad"]) <= 2 * KNOB_SIGMA_RAD


def test_the_stove_is_found_by_its_knob_alone():
    cloud, heights, meta, look = _recorded()
    s = find_by_knob(cloud.points, heights, look)
    assert s is not None and s.found_by == "knob" and _place_error(look, s, meta) < 0.03


def test_a_stove_sized_thing_with_no_bar_where_the_knob_should_be_is_not_taken_but_a_hidden_knob_is_no_veto():
    cloud, heights, meta, look = _recorded()
    axis = np.asarray(meta["axis"])
    bar = (np.linalg.norm(cloud.points[:, :2] - axis, axis=1) <= 0.06) & (heights >= 0.036)  # the knob's band
    # a round can stands where the knob is (a 6 cm disc of points over the knob's height): no bar
    rng = np.random.default_rng(0)
    r, a = 0.03 * np.sqrt(rng.uniform(0, 1, 400)), rng.uniform(0, 2 * np.pi, 400)
    h = rng.uniform(0.036, 0.07, 400)
    can = np.column_stack([axis[0] + r * np.cos(a), axis[1] + r * np.sin(a), TABLE_Z + h])
    points = np.concatenate([cloud.points[~bar], can]).astype(np.float32)
    rgb = np.concatenate([cloud.rgb[~bar], np.full((400, 3), 90, cloud.rgb.dtype)])
    with_can = Cloud(points, rgb, np.ones(len(points), np.float32), np.zeros(len(points), np.int64))
    assert detect_fixtures(with_can, np.concatenate([heights[~bar], h]), [look], _config()) == {}
    # the knob hidden (its bar's points gone: the arm in the way) is no reason to refuse the stove
    # (its look's top here the burner's, 3.2 cm, as libero_goal's and libero_spatial's scenes measure it)
    cloud, heights, meta, look = _recorded(top_m=0.0318)
    hidden = cloud.select(~bar)
    found = detect_fixtures(hidden, heights[~bar], [look], _config())
    assert _place_error(look, found[look.name], meta) < 0.03


def test_a_stove_standing_the_other_way_round_is_found_by_its_knob_with_its_burner_and_knob_turned():
    # the recorded scene turned by pi about the stove (LIBERO-PRO's libero_goal_swap sets the stove
    # down with its knob away from the robot): the look, measured the usual way round, still finds it
    cloud, heights, meta, look = _recorded()
    pivot = 0.5 * (np.asarray(meta["axis"]) + np.asarray(meta["cook_region"]))
    turned = cloud.points.astype(np.float64).copy()
    turned[:, :2] = 2.0 * pivot - turned[:, :2]
    rotated = Cloud(turned.astype(np.float32), cloud.rgb, cloud.range_m, cloud.camera)
    found = detect_fixtures(rotated, heights, [look], _config())
    s = found[look.name]
    assert s.turn == pytest.approx(np.pi)
    centre, _, _ = look.place_patch(s.position[:2], s.half_xy_world, s.turn)
    assert np.linalg.norm(centre - (2.0 * pivot - np.asarray(meta["cook_region"]))) < 0.03
    yaw, _ = knob_reading(rotated.points, heights, look.knob, s.position[:2], s.turn)
    assert abs(look.knob.joint_position(yaw, s.turn) - meta["angle_rad"]) <= 2 * KNOB_SIGMA_RAD
