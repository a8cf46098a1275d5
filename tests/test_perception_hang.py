"""A round body held by its rim hangs under the pads: where its base is, read from the cameras off
the hand (``phyagentos.perception.hang``), on synthetic clouds of a tapered cup seen from one side."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.perception.hang import (
    HANG_MAX_M,
    HANG_SLICES,
    base_profile,
    hang_offset,
    scene_camera_mask,
)

CAMERA = np.array([0.6, 0.0, 0.95])  # where LIBERO's agentview stands, world m


def _cup(axis_xy, base_z, *, tilt_rad=0.0, pivot=None, arc_rad=math.radians(150.0), seed=0, height=0.06):
    """(N, 3) points on the side of a cup (radius 3.0 cm at its base widening 0.6 mm per mm up,
    as LIBERO's porcelain mug) facing ``CAMERA`` across ``arc_rad``, every 2 mm up, turned
    ``tilt_rad`` about the horizontal axis through ``pivot`` across the camera's view."""
    rng = np.random.default_rng(seed)
    axis = np.asarray(axis_xy, float)
    view = math.atan2(CAMERA[1] - axis[1], CAMERA[0] - axis[0])
    pts = []
    for h in np.arange(0.0, height, 0.002):
        r = 0.030 + 0.6 * h
        for a in np.linspace(view - arc_rad / 2, view + arc_rad / 2, 24):
            pts.append((axis[0] + r * math.cos(a), axis[1] + r * math.sin(a), base_z + h))
    p = np.asarray(pts) + rng.normal(0.0, 0.0007, (len(pts), 3))
    return _turned(p, view, tilt_rad, pivot) if tilt_rad else p


def _turned(p, view, tilt_rad, pivot):
    """``p`` (N, 3) turned ``tilt_rad`` about the horizontal axis through ``pivot`` across the
    bearing ``view`` (Rodrigues)."""
    k = np.array([-math.sin(view), math.cos(view), 0.0])
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + math.sin(tilt_rad) * K + (1 - math.cos(tilt_rad)) * K @ K
    return (np.asarray(p, float).reshape(-1, 3) - pivot) @ R.T + pivot


def test_a_cup_hung_under_the_pads_is_found_where_its_base_swung_not_where_it_stood():
    stood = np.array([0.10, -0.05])
    profile = base_profile(_cup(stood, 0.44, seed=1), axis_xy=stood, outline_radius_m=0.05)
    assert profile is not None and profile.shape == (HANG_SLICES,)
    assert np.all(np.diff(profile[profile > 0]) > 0)  # it widens upwards, slice by slice
    # lifted 17 cm by the rim on its far side, it turned 8 degrees about the pads, 10 cm over its base
    view = math.atan2(CAMERA[1] - stood[1], CAMERA[0] - stood[0])
    pivot = np.r_[stood - 0.03 * np.array([math.cos(view), math.sin(view)]), 0.61 + 0.10]
    tilt = math.radians(8.0)
    hung = _cup(stood, 0.61, tilt_rad=tilt, pivot=pivot, seed=2)
    shift = hang_offset(hung, axis_xy=stood, profile=profile)
    assert shift is not None
    base = _turned(np.r_[stood, 0.61], view, tilt, pivot)[0, :2]  # the axis at its base
    assert np.linalg.norm(stood - base) > 0.012  # where the carried pose puts it
    assert np.linalg.norm(stood + shift - base) <= 0.003, (stood + shift, base)


def test_a_cup_that_hangs_where_it_is_carried_is_left_there():
    at = np.array([0.0, 0.1])
    profile = base_profile(_cup(at, 0.44, seed=3), axis_xy=at, outline_radius_m=0.05)
    shift = hang_offset(_cup(at, 0.62, seed=4), axis_xy=at, profile=profile)
    assert shift is not None and np.linalg.norm(shift) <= 0.0015


@pytest.mark.parametrize("why", ["few points", "short arc", "too far", "no profile"])
def test_what_does_not_tell_leaves_the_carried_pose(why):
    at = np.array([0.0, 0.1])
    profile = base_profile(_cup(at, 0.44, seed=5), axis_xy=at, outline_radius_m=0.05)
    hung = _cup(at + np.array([0.01, 0.0]), 0.62, seed=6)
    if why == "few points":
        hung = hung[::80]
    elif why == "short arc":
        hung = _cup(at + np.array([0.01, 0.0]), 0.62, arc_rad=math.radians(30.0), seed=6)
    elif why == "too far":  # another thing's points, or a fit gone astray, beyond any swing
        hung = _cup(at + np.array([HANG_MAX_M + 0.012, 0.0]), 0.62, seed=6)
    elif why == "no profile":
        profile = np.zeros(HANG_SLICES)
    assert hang_offset(hung, axis_xy=at, profile=profile) is None


def test_a_base_seen_in_fewer_than_two_slices_has_no_profile():
    at = np.array([0.0, 0.1])
    assert base_profile(_cup(at, 0.44, height=0.004), axis_xy=at, outline_radius_m=0.05) is None


def test_a_camera_riding_on_the_hand_is_not_a_scene_camera():
    tcp = np.array([0.0, 0.0, 0.7])
    cams = np.array([[0.6, 0.0, 0.95], [0.0, 0.05, 0.78]])  # agentview; eye-in-hand, 9 cm from the tcp
    assert scene_camera_mask(np.array([0, 1, 1, 0]), cams, tcp).tolist() == [True, False, False, True]
