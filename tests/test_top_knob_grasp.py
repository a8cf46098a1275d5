"""A knob on top: found from points, and the grasp that takes an object too wide by it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.errors import IKError
from phyagentos.motion.grasp import FINGERTIP_BELOW_TCP_M, hand_yaw
from phyagentos.motion.top_knob_grasp import (
    KNOB_PREFERRED_MARGIN_M,
    KNOB_TIP_CLEARANCE_M,
    top_knob_grasp_candidates,
    top_knob_graspable,
    top_knob_preshape_m,
)
from phyagentos.perception.top_knob import KNOB_MAX_RADIUS_M, reach_axis, top_knob

RNG = np.random.default_rng(7)


def _box_points(centre, half, top, *, step=0.004, noise=0.001):
    """(N, 2) xy and (N,) heights of a box's top face and sides, as a depth camera samples them."""
    cx, cy = centre
    hx, hy = half
    xs, ys = np.meshgrid(np.arange(cx - hx, cx + hx, step), np.arange(cy - hy, cy + hy, step))
    xy = [np.column_stack([xs.ravel(), ys.ravel()])]
    h = [np.full(xs.size, top)]
    for z in np.arange(0.0, top, step):  # the near side
        x = np.arange(cx - hx, cx + hx, step)
        xy.append(np.column_stack([x, np.full(x.size, cy - hy)]))
        h.append(np.full(x.size, z))
    xy, h = np.concatenate(xy), np.concatenate(h)
    return xy + RNG.normal(0, noise, xy.shape), h + RNG.normal(0, noise, h.shape)


def test_a_knob_standing_on_a_lid_is_found_where_it_stands():
    body_xy, body_h = _box_points((0.10, -0.20), (0.034, 0.033), 0.133)
    knob_xy, knob_h = _box_points((0.102, -0.199), (0.005, 0.006), 0.152, step=0.002)
    keep = knob_h > 0.130  # the knob's own points: the part above the lid
    knob = top_knob(np.r_[body_xy, knob_xy[keep]], np.r_[body_h, knob_h[keep]])
    assert knob is not None
    # within the knob's half width: its near side, which the camera sees too, pulls the median
    assert np.linalg.norm(knob.xy - (0.102, -0.199)) < 0.006
    assert abs(knob.top_m - 0.152) < 0.003 and knob.radius_m <= KNOB_MAX_RADIUS_M
    assert abs(knob.base_m - 0.133) < 0.003  # the lid it stands on


def test_a_knob_seen_close_from_above_still_stands_on_the_lid_below_it():
    """From the wrist camera over it, the knob's top face is sampled densely: the segment's top
    is the knob's, and the body's top under it is read around it."""
    body_xy, body_h = _box_points((0.0, 0.0), (0.034, 0.033), 0.133)
    knob_xy, knob_h = _box_points((0.0, 0.0), (0.005, 0.006), 0.152, step=0.0007)
    keep = knob_h > 0.130
    knob = top_knob(np.r_[body_xy, knob_xy[keep]], np.r_[body_h, knob_h[keep]])
    assert knob is not None and abs(knob.top_m - 0.152) < 0.003 and abs(knob.base_m - 0.133) < 0.003


def test_a_flat_top_or_an_open_rim_is_no_knob():
    assert top_knob(*_box_points((0.0, 0.0), (0.035, 0.035), 0.10)) is None  # a box's top
    a = np.linspace(0, 2 * math.pi, 200, endpoint=False)
    ring = np.column_stack([0.05 * np.cos(a), 0.05 * np.sin(a)])
    floor = RNG.uniform(-0.03, 0.03, (300, 2))
    assert top_knob(np.r_[ring, floor], np.r_[np.full(200, 0.05), np.full(300, 0.01)]) is None  # a bowl


def test_a_lone_post_with_no_body_under_it_is_no_knob():
    xy, h = _box_points((0.0, 0.0), (0.005, 0.005), 0.15, step=0.002)
    assert top_knob(xy, h) is None


def test_only_an_object_too_wide_or_nearly_is_taken_by_its_knob():
    attrs = {"top_knob_xy": [0.1, -0.2], "top_knob_z_m": 1.06, "top_knob_radius_m": 0.006}
    wide = 0.5 * (0.08 - 0.004 - KNOB_PREFERRED_MARGIN_M) + 0.002
    assert top_knob_graspable(attrs, (0.06, wide, 0.07))
    assert not top_knob_graspable(attrs, (0.06, wide - 0.004, 0.07))  # the across grasp has room
    assert not top_knob_graspable({}, (0.06, 0.05, 0.07))  # no knob seen
    assert not top_knob_graspable(attrs, (0.05, 0.05, 0.05), shape="sphere")


def test_the_fingertips_stay_above_the_lid_and_the_hand_squares_up_to_the_knob_as_a_place_sets_down():
    plans = top_knob_grasp_candidates((0.1, -0.2), 1.052, 0.006, body_top_z_m=1.033, long_axis_yaw_rad=1.3,
                                  approach_height_m=0.1)
    assert len(plans) == 4
    for p in plans:
        assert p.grasp[2, 3] - FINGERTIP_BELOW_TCP_M == pytest.approx(1.033 + KNOB_TIP_CLEARANCE_M)
        assert np.allclose(p.grasp[:2, 3], (0.1, -0.2)) and p.pregrasp[2, 3] == pytest.approx(p.grasp[2, 3] + 0.1)
        assert p.width_m == pytest.approx(0.012)
        # square to the knob's faces: the hand's x along the handle's axis or across it
        assert abs(math.sin(2.0 * (hand_yaw(p.grasp) - 1.3))) < 1e-9
    # the one nearest yaw 0 first (a place tries yaw 0 first: the object goes down as it stood)
    assert hand_yaw(plans[0].grasp) == pytest.approx(1.3 - 0.5 * math.pi)
    assert top_knob_preshape_m(0.006) == pytest.approx(0.026)


def test_a_knob_too_low_for_the_pads_is_refused_with_why():
    with pytest.raises(IKError, match="pads would hold"):
        top_knob_grasp_candidates((0.0, 0.0), 1.038, 0.006, body_top_z_m=1.033, long_axis_yaw_rad=0.0)


def test_the_way_a_pot_reaches_farthest_from_its_knob_is_its_handles_axis_and_a_disc_has_none():
    a = np.linspace(0, 2 * math.pi, 300, endpoint=False)
    disc = np.column_stack([0.04 * np.cos(a), 0.04 * np.sin(a)])
    handle = np.column_stack([RNG.uniform(-0.006, 0.006, 40), RNG.uniform(0.065, 0.08, 40)])
    spout = np.column_stack([RNG.uniform(-0.006, 0.006, 20), RNG.uniform(-0.057, -0.045, 20)])
    turn = np.array([[math.cos(0.3), -math.sin(0.3)], [math.sin(0.3), math.cos(0.3)]])
    axis = reach_axis(np.r_[disc, handle, spout] @ turn.T)
    assert axis is not None and abs(math.sin(axis - (0.5 * math.pi + 0.3))) < math.sin(math.radians(3))
    assert reach_axis(disc) is None


def _pot(centre):
    body_xy, body_h = _box_points(centre, (0.034, 0.033), 0.133)
    knob_xy, knob_h = _box_points((centre[0], centre[1] + 0.001), (0.005, 0.006), 0.152, step=0.002)
    keep = knob_h > 0.130
    return np.r_[body_xy, knob_xy[keep]], np.r_[body_h, knob_h[keep]]


def test_two_pots_side_by_side_in_one_segment_show_two_knobs_and_one_pot_one():
    """Two moka pots set next to each other on a stove join in one segment; the split finds
    one knob on each (its ``knobs`` partition), and a lone pot or a flat top none to split by."""
    from phyagentos.perception.split import top_knobs

    (a_xy, a_h), (b_xy, b_h) = _pot((0.0, 0.0)), _pot((0.0, 0.085))
    knobs = top_knobs(np.r_[a_xy, b_xy], np.r_[a_h, b_h])
    assert len(knobs) == 2
    # each within its knob's half width (the near sides the camera sees pull the median)
    assert sorted(float(k[1]) for k in knobs) == [pytest.approx(0.001, abs=0.006), pytest.approx(0.086, abs=0.006)]
    assert len(top_knobs(a_xy, a_h)) == 1
    assert top_knobs(*_box_points((0.0, 0.0), (0.07, 0.035), 0.1)) == []


def test_a_tracks_knob_stays_where_it_was_seen_when_a_sighting_names_the_box_yaw_a_quarter_turn_off():
    """A square-ish box's yaw is known modulo its period: a sighting may call it a quarter turn
    off what the track holds. The knob is kept in the track's own frame, so it is placed where
    it was seen, not turned with the sighting's name for the yaw."""
    from phyagentos.geometry import turned_xy
    from phyagentos.perception.colour import srgb_to_lab
    from phyagentos.perception.config import PerceptionConfig
    from phyagentos.perception.detect import Detection
    from phyagentos.perception.top_knob import Knob
    from phyagentos.perception.tracks import Track

    def det(yaw, half):
        return Detection(position=np.array([0.05, 0.02, 0.07]), yaw=yaw, half_extents=np.array(half), shape="box",
                         colour_rgb=np.array([0.6, 0.6, 0.6]), colour_lab=srgb_to_lab(np.array([[0.6, 0.6, 0.6]]))[0],
                         points=500, cameras=2, position_std_m=0.002, yaw_std_rad=0.05, view_agreement=1.0,
                         bottom_m=0.0, top_knob=Knob(xy=np.array([0.05, 0.034]), top_m=0.152, radius_m=0.007,
                                                     base_m=0.133))

    t = Track.start("pot", det(0.0, (0.04, 0.039, 0.07)), 0.9, 0.0, ("agentview",))
    t.update(det(0.5 * math.pi - 1e-3, (0.04, 0.039, 0.07)), 0.9, 0.1, ("agentview",), PerceptionConfig.default())
    placed = t.position[:2] + turned_xy(t.top_knob[:2], t.yaw)
    assert placed == pytest.approx([0.05, 0.034], abs=1e-6)
