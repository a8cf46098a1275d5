"""A round body with a handle (``phyagentos.perception.handle``): a mug's cup axis and handle
from its footprint's points; a plain round thing or a box shows none. Synthetic footprints
sampled as a depth camera sees them from above (a rim ring, the inside of the wall, a handle
loop), with depth noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.perception.handle import RoundBody, round_body


def _mug(axis=(0.10, -0.05), r=0.042, handle_deg=30.0, handle_len=0.028, noise=0.0008, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.0, 2.0 * math.pi, 1500)
    rad = r - rng.uniform(0.0, 0.008, a.size)  # the rim and the inside of its wall
    ring = np.column_stack([np.cos(a), np.sin(a)]) * rad[:, None]
    u = np.array([math.cos(math.radians(handle_deg)), math.sin(math.radians(handle_deg))])
    v = np.array([-u[1], u[0]])
    t = rng.uniform(r, r + handle_len, 250)  # the handle's loop, 1.2 cm wide
    handle = t[:, None] * u + rng.uniform(-0.006, 0.006, t.size)[:, None] * v
    pts = np.vstack([ring, handle]) + np.asarray(axis)
    return pts + rng.normal(0.0, noise, pts.shape)


def test_a_mugs_axis_and_handle_come_from_its_outline_not_its_rectangles_centre():
    axis = np.array([0.10, -0.05])
    pts = _mug(axis=axis, handle_deg=30.0)
    rect_guess = 0.5 * (pts.min(axis=0) + pts.max(axis=0))  # pulled towards the handle
    assert np.linalg.norm(rect_guess - axis) > 0.008
    body = round_body(pts, rect_guess)
    assert body is not None
    assert np.linalg.norm(body.axis_xy - axis) < 0.002
    assert abs(body.radius_m - 0.042) < 0.004
    assert math.degrees(math.acos(float(body.handle_xy @ [math.cos(math.radians(30)), math.sin(math.radians(30))]))) < 5


@pytest.mark.parametrize("deg", [-150.0, -60.0, 95.0, 180.0])
def test_the_handle_is_found_whichever_way_it_points(deg):
    body = round_body(_mug(handle_deg=deg, seed=3), np.array([0.10, -0.05]))
    assert body is not None
    want = np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])
    assert float(body.handle_xy @ want) > math.cos(math.radians(5))


def test_a_round_thing_without_a_handle_and_a_box_show_none():
    rng = np.random.default_rng(1)
    a = rng.uniform(0.0, 2.0 * math.pi, 1500)
    bowl = np.column_stack([np.cos(a), np.sin(a)]) * rng.uniform(0.045, 0.054, a.size)[:, None]
    assert round_body(bowl, np.zeros(2)) is None
    box = rng.uniform(-1.0, 1.0, (1500, 2)) * [0.04, 0.04]  # a square box top, 8 cm a side
    assert round_body(box, np.zeros(2)) is None
    carton = rng.uniform(-1.0, 1.0, (1500, 2)) * [0.06, 0.025]
    assert round_body(carton, np.zeros(2)) is None
    assert round_body(bowl[:10], np.zeros(2)) is None  # too few points


def test_a_body_in_its_objects_frame_follows_the_object_when_it_moves():
    body = RoundBody(np.array([0.30, 0.10]), 0.04, np.array([1.0, 0.0]))
    local = body.local(np.array([0.31, 0.10]), yaw=math.pi / 2)  # the object's centre 1 cm towards the handle
    np.testing.assert_allclose(local.placed(_pose((0.31, 0.10), math.pi / 2)).axis_xy, body.axis_xy, atol=1e-12)
    moved = local.placed(_pose((0.0, 0.5), math.pi))  # the object turned a half turn more, elsewhere
    np.testing.assert_allclose(moved.axis_xy, [0.0, 0.49], atol=1e-12)
    np.testing.assert_allclose(moved.handle_xy, [0.0, 1.0], atol=1e-12)


def _pose(xy, yaw) -> np.ndarray:
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = xy
    return T


def test_a_track_keeps_a_hidden_handle_where_it_last_pointed_when_its_round_sighting_resets_the_yaw():
    """A mug let go turned a quarter turn (its track's yaw from the hand) is seen next with the
    handle behind its cup: a round sighting (yaw 0) keeps the handle pointing where it did."""
    from phyagentos.perception import PerceptionConfig
    from phyagentos.perception.detect import Detection
    from phyagentos.perception.tracks import Track

    def det(body=None):
        return Detection(position=np.array([0.30, 0.10, 0.05]), yaw=0.0, half_extents=np.array([0.045, 0.045, 0.05]),
                         shape="cylinder", colour_rgb=np.full(3, 0.5), colour_lab=np.zeros(3), points=800, cameras=2,
                         position_std_m=0.003, yaw_std_rad=math.pi, view_agreement=1.0, bottom_m=0.0, body=body)

    seen = RoundBody(np.array([0.29, 0.10]), 0.042, np.array([1.0, 0.0]))
    t = Track.start("mug_1", det(seen), 0.9, 0.0, ("agentview",))
    t.yaw = math.pi / 2  # let go a quarter turn round: the handle now points along +y
    assert t.update(det(), 0.9, 1.0, ("agentview",), PerceptionConfig.default())
    world = t.body.placed(_pose(t.position[:2], t.yaw))
    np.testing.assert_allclose(world.handle_xy, [0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(world.axis_xy - t.position[:2], [0.0, -0.01], atol=1e-9)


def test_a_track_restarted_for_its_shape_where_it_stands_keeps_the_handle_it_saw():
    """LIBERO-10 task 4 (development seed 508): the yellow and white mug let go on its plate was
    seen round with its handle (mug and plate rim one segment), then, from the arm's home pose,
    only its near side: a box. Its second sighting of another shape restarts the track; one at
    the same place, showing no handle, keeps the handle the first saw where it was, in the world
    (before: lost, the mug's origin taken at its centre with the handle's 1.75 cm as its
    uncertainty, and its place on the plate left undecided)."""
    from phyagentos.perception import PerceptionConfig
    from phyagentos.perception.detect import Detection
    from phyagentos.perception.tracks import Track, object_pose

    def det(xy, shape, yaw=0.0, body=None):
        return Detection(position=np.array([xy[0], xy[1], 0.05]), yaw=yaw, half_extents=np.array([0.05, 0.04, 0.05]),
                         shape=shape, colour_rgb=np.full(3, 0.5), colour_lab=np.zeros(3), points=800, cameras=2,
                         position_std_m=0.003, yaw_std_rad=0.05, view_agreement=1.0, bottom_m=0.0, body=body)

    seen = RoundBody(np.array([0.0057, 0.3200]), 0.051, np.array([0.96, -0.28]))
    t = Track.start("mug_1", det((0.0088, 0.3159), "cylinder", body=seen), 0.99, 0.0, ("agentview", "wrist"))
    assert not t.update(det((0.0057, 0.3127), "box", yaw=0.7), 0.98, 1.4, ("agentview",), PerceptionConfig.default())
    assert t.shape == "box" and t.body is not None
    world = t.body.placed(object_pose(t.position, t.yaw))
    np.testing.assert_allclose(world.axis_xy, seen.axis_xy, atol=1e-9)
    np.testing.assert_allclose(world.handle_xy, seen.handle_xy / np.linalg.norm(seen.handle_xy), atol=1e-9)
    # moved away (outside the gate): a new object for all the track knows, no handle carried
    t = Track.start("mug_1", det((0.0088, 0.3159), "cylinder", body=seen), 0.99, 0.0, ("agentview", "wrist"))
    assert not t.update(det((0.2, 0.0), "box"), 0.98, 1.4, ("agentview",), PerceptionConfig.default())
    assert t.body is None


def test_a_handles_reach_is_where_its_outer_face_stands_from_the_axis():
    axis = np.array([0.10, -0.05])
    body = round_body(_mug(axis=axis, handle_deg=-90.0, handle_len=0.04, noise=0.0005, seed=5), axis + [0.0, -0.01])
    assert body is not None and body.reach_m is not None
    assert abs(body.reach_m - (0.042 + 0.04)) < 0.004  # the loop's outer end, 8.2 cm out
    moved = body.local(np.array([0.1, -0.05]), 0.3).placed(np.eye(4))
    assert moved.reach_m == body.reach_m  # a length: it moves with the body unchanged
