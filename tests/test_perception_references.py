"""Spatial references in association: which of two identical declared objects is meant,
decided from the perceived positions of the landmarks a relation names (never from an
index order or a guess), on synthetic detections."""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.perception import ObjectDescriptor, PerceptionConfig, PerceptionError, SpatialReference
from phyagentos.perception.association import (
    Landmark,
    associate,
    cost_matrix,
    forbid_except,
    part_landmark,
    resolve_reference,
    track_costs,
)
from phyagentos.perception.cloud import Plane
from phyagentos.perception.colour import srgb_to_lab
from phyagentos.perception.detect import Detection
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics
from phyagentos.perception.perceiver import Perceiver, table_centre, viewer_right

BLACK, WHITE, RED = (0.08, 0.08, 0.08), (0.95, 0.95, 0.95), (0.85, 0.15, 0.12)
BOWL_SIZE = (0.12, 0.12, 0.05)


def _det(colour, pos, half=(0.06, 0.06, 0.025), shape="cylinder", bottom=0.0, low=0.0):
    return Detection(position=np.array(pos, float), yaw=0.0, half_extents=np.array(half, float), shape=shape,
                     colour_rgb=np.array(colour), colour_lab=srgb_to_lab(np.array([colour]))[0], points=300,
                     cameras=2, position_std_m=0.002, yaw_std_rad=0.05, view_agreement=1.0, bottom_m=bottom,
                     low_m=low)


def _bowl(name, where=None):
    return ObjectDescriptor(name, cls="bowl", shape="cylinder", colour_rgb=BLACK, size_m=BOWL_SIZE, where=where)


def _landmark(name, pos, half=(0.04, 0.04, 0.02), shape="cylinder", bottom=0.0):
    return Landmark(name, np.array(pos, float), np.array(half, float), 0.0, shape, bottom)


CFG = PerceptionConfig.default()


# -- the declared reference -------------------------------------------------------------------------------


def test_a_reference_is_validated_and_round_trips():
    ref = SpatialReference.from_value({"relation": "between", "of": ["plate_1", "ramekin_1"]})
    assert ref.of == ("plate_1", "ramekin_1") and ref.to_dict() == {"relation": "between",
                                                                      "of": ["plate_1", "ramekin_1"]}
    assert SpatialReference.from_value({"relation": "table_center"}).of == ()
    d = ObjectDescriptor.from_dict({"name": "bowl_1", "class": "bowl", "where": {"relation": "in", "of": ["cab_1"],
                                                                                 "part": "top drawer"}})
    assert d.where == SpatialReference("in", ("cab_1",), "top drawer")
    with pytest.raises(PerceptionError, match="is not one of"):
        SpatialReference("left_of", ("plate_1",))
    with pytest.raises(PerceptionError, match="takes 2 landmark"):
        SpatialReference("between", ("plate_1",))
    with pytest.raises(PerceptionError, match="unknown key"):
        SpatialReference.from_value({"relation": "on", "of": ["plate_1"], "init": "region"})
    with pytest.raises(PerceptionError, match="itself"):
        ObjectDescriptor("bowl_1", where={"relation": "next_to", "of": ["bowl_1"]})


# -- resolve_reference --------------------------------------------------------------------------------------


@pytest.mark.parametrize("order", [0, 1])
def test_next_to_picks_the_detection_nearest_the_landmark_in_either_order(order):
    near, far = _det(BLACK, (0.55, 0.10, 0.03)), _det(BLACK, (0.40, -0.20, 0.03))
    dets = [near, far] if order == 0 else [far, near]
    desc = _bowl("bowl_1", {"relation": "next_to", "of": ["ramekin_1"]})
    res = resolve_reference(desc, [0, 1], dets, {"ramekin_1": _landmark("ramekin_1", (0.60, 0.18, 0.02))}, CFG,
                            look_alikes=2)
    assert res.detection is not None and dets[res.detection] is near


@pytest.mark.parametrize("order", [0, 1])
def test_between_picks_the_detection_nearest_the_segment_not_the_nearest_landmark(order):
    # the other bowl stands right beside the plate but outside the plate-ramekin segment
    mid, beside = _det(BLACK, (0.50, 0.02, 0.03)), _det(BLACK, (0.50, -0.26, 0.03))
    dets = [mid, beside] if order == 0 else [beside, mid]
    desc = _bowl("bowl_1", {"relation": "between", "of": ["plate_1", "ramekin_1"]})
    marks = {"plate_1": _landmark("plate_1", (0.50, -0.15, 0.01)), "ramekin_1": _landmark("ramekin_1", (0.50, 0.2, 0.02))}
    res = resolve_reference(desc, [0, 1], dets, marks, CFG, look_alikes=2)
    assert dets[res.detection] is mid


@pytest.mark.parametrize("order", [0, 1])
def test_on_a_perceived_landmark_needs_the_footprint_and_height(order):
    up = _det(BLACK, (0.45, 0.10, 0.12), bottom=0.09, low=0.09)
    down = _det(BLACK, (0.60, -0.1, 0.03))
    dets = [up, down] if order == 0 else [down, up]
    desc = _bowl("bowl_1", {"relation": "on", "of": ["cookies_1"]})
    box = _landmark("cookies_1", (0.45, 0.11, 0.045), half=(0.08, 0.05, 0.045), shape="box")
    res = resolve_reference(desc, [0, 1], dets, {"cookies_1": box}, CFG, look_alikes=2)
    assert dets[res.detection] is up
    # over the footprint but standing on the table (beside a flat thing): not "on" it
    flat = _det(BLACK, (0.45, 0.10, 0.03))
    res = resolve_reference(desc, [0, 1], [flat, down], {"cookies_1": box}, CFG, look_alikes=2)
    assert res.detection is None and "0 candidates" in res.reason


@pytest.mark.parametrize("order", [0, 1])
def test_on_an_unperceived_fixture_picks_the_one_look_alike_off_the_table(order):
    raised = _det(BLACK, (0.30, 0.30, 0.05), bottom=0.02, low=0.025)
    table = _det(BLACK, (0.55, -0.05, 0.03))
    dets = [raised, table] if order == 0 else [table, raised]
    desc = _bowl("bowl_1", {"relation": "on", "of": ["flat_stove_1"]})
    res = resolve_reference(desc, [0, 1], dets, {}, CFG, look_alikes=2)
    assert dets[res.detection] is raised and "not perceived" in res.reason
    # both on the table: which is on the stove cannot be seen
    res = resolve_reference(desc, [0, 1], [table, _det(BLACK, (0.3, 0.3, 0.03))], {}, CFG, look_alikes=2)
    assert res.detection is None


@pytest.mark.parametrize("order", [0, 1])
def test_a_bowl_on_a_perceived_cabinet_is_not_taken_for_the_bowl_on_an_unperceived_stove(order):
    """libero_spatial task 7 ("the black bowl on the stove"): the stove under its bowl is not
    perceived (one segment with it) and that bowl looks as if it rested on the table; the other
    bowl, on the cabinet's top (seen since the crop is raised over a perceived fixture), is off
    the table -- but it rests on the cabinet, so it is not the bowl on the stove: unresolved."""
    on_cabinet = _det(BLACK, (0.03, -0.27, 1.153), half=(0.056, 0.05, 0.026), bottom=0.227, low=0.23)
    on_stove = _det(BLACK, (-0.26, -0.13, 0.94), half=(0.056, 0.056, 0.04))
    cabinet = Landmark("wooden_cabinet_1", np.array([0.02, -0.25, 1.014]), np.array([0.128, 0.11, 0.1136]), 0.0,
                       "box", 0.0)
    dets = [on_cabinet, on_stove] if order == 0 else [on_stove, on_cabinet]
    desc = _bowl("bowl_1", {"relation": "on", "of": ["flat_stove_1"]})
    res = resolve_reference(desc, [0, 1], dets, {"wooden_cabinet_1": cabinet}, CFG, look_alikes=2)
    assert res.detection is None and "besides those on wooden_cabinet_1" in res.reason
    # "the black bowl on the wooden cabinet": the perceived cabinet is the landmark
    desc = _bowl("bowl_1", {"relation": "on", "of": ["wooden_cabinet_1"]})
    res = resolve_reference(desc, [0, 1], dets, {"wooden_cabinet_1": cabinet}, CFG, look_alikes=2)
    assert dets[res.detection] is on_cabinet and "over wooden_cabinet_1's footprint" in res.reason


@pytest.mark.parametrize("order", [0, 1])
def test_in_the_top_drawer_is_the_look_alike_inside_that_open_drawer_not_the_one_on_the_cabinet(order):
    """libero_spatial task 4 ("the black bowl in the top drawer of the wooden cabinet"): the
    other bowl stands on the cabinet's top, over its footprint too; the drawer's inside (the
    perceiver's landmark for an open drawer) tells them apart, and a drawer not seen open
    decides nothing."""
    on_top = _det(BLACK, (0.02, -0.28, 1.153), half=(0.056, 0.05, 0.026), bottom=0.227, low=0.23)
    in_drawer = _det(BLACK, (0.09, -0.15, 1.089), half=(0.052, 0.052, 0.025), bottom=0.164, low=0.165)
    cabinet = Landmark("wooden_cabinet_1", np.array([0.02, -0.275, 1.014]), np.array([0.128, 0.11, 0.1136]), -0.45,
                       "box", 0.0)
    inside = Landmark("wooden_cabinet_1_top_drawer", np.array([0.10, -0.14, 0.982]), np.array([0.09, 0.06, 0.082]),
                      -0.45, "box", 0.0)
    dets = [on_top, in_drawer] if order == 0 else [in_drawer, on_top]
    desc = _bowl("bowl_1", {"relation": "in", "of": ["wooden_cabinet_1"], "part": "top drawer"})
    marks = {"wooden_cabinet_1": cabinet, "wooden_cabinet_1_top_drawer": inside}
    res = resolve_reference(desc, [0, 1], dets, marks, CFG, look_alikes=2)
    assert dets[res.detection] is in_drawer and "inside wooden_cabinet_1_top_drawer" in res.reason
    res = resolve_reference(desc, [0, 1], dets, {"wooden_cabinet_1": cabinet}, CFG, look_alikes=2)
    assert res.detection is None and "top drawer of wooden_cabinet_1 is not seen open" in res.reason
    # a bowl on the table under the open drawer is not in it
    under = _det(BLACK, (0.10, -0.14, 0.93), half=(0.052, 0.052, 0.025))
    res = resolve_reference(desc, [0, 1], [under, on_top], marks, CFG, look_alikes=2)
    assert res.detection is None and "0 candidates inside" in res.reason
    # a level read as no drawer is never widened to the whole cabinet (whose one raised bowl is on its top)
    shelf = _bowl("bowl_1", {"relation": "in", "of": ["wooden_cabinet_1"], "part": "top shelf"})
    res = resolve_reference(shelf, [0, 1], dets, marks, CFG, look_alikes=2)
    assert res.detection is None and "top shelf of wooden_cabinet_1 is not a part perception reads" in res.reason


def test_only_a_drawer_part_narrows_a_reference():
    assert part_landmark("wooden_cabinet_1", "top drawer") == "wooden_cabinet_1_top_drawer"
    assert part_landmark("wooden_cabinet_1", "bottom drawer") == "wooden_cabinet_1_bottom_drawer"
    assert part_landmark("wooden_cabinet_1", None) is None
    assert part_landmark("wooden_cabinet_1", "top") is None
    assert part_landmark("microwave_1", "door") is None

def test_table_center_uses_the_perceived_table_centre():
    dets = [_det(BLACK, (0.20, 0.25, 0.03)), _det(BLACK, (0.02, -0.01, 0.03))]
    desc = _bowl("bowl_1", {"relation": "table_center"})
    res = resolve_reference(desc, [0, 1], dets, {}, CFG, look_alikes=2, table_centre_xy=np.array([0.0, 0.0]))
    assert res.detection == 1
    res = resolve_reference(desc, [0, 1], dets, {}, CFG, look_alikes=2, table_centre_xy=np.array([0.25, 0.3]))
    assert res.detection == 0
    res = resolve_reference(desc, [0, 1], dets, {}, CFG, look_alikes=2, table_centre_xy=None)
    assert res.detection is None and "centre is not perceived" in res.reason


@pytest.mark.parametrize("order", [(0, 1), (1, 0)])
def test_left_and_right_are_the_viewers_as_the_scene_camera_shows_the_table(order):
    # LIBERO's agentview stands across the table from the robot: its image right is world +y
    dets = [_det(BLACK, (0.10, -0.20, 0.03)), _det(BLACK, (-0.05, 0.15, 0.03))]
    dets = [dets[i] for i in order]
    left, right = order.index(0), order.index(1)
    facing_robot = np.array([0.0, 1.0])
    for side, want in (("left", left), ("right", right)):
        res = resolve_reference(_bowl("bowl_1", {"relation": side}), [0, 1], dets, {}, CFG, look_alikes=2,
                                viewer_right_xy=facing_robot)
        assert res.detection == want, res.reason
    # the same table seen from behind the robot: the sides swap
    res = resolve_reference(_bowl("bowl_1", {"relation": "left"}), [0, 1], dets, {}, CFG, look_alikes=2,
                            viewer_right_xy=-facing_robot)
    assert res.detection == right


def test_a_side_is_not_picked_when_the_twins_stand_level_or_no_camera_is_known():
    dets = [_det(BLACK, (0.10, 0.01, 0.03)), _det(BLACK, (-0.20, 0.02, 0.03))]  # 1 cm apart across the view
    desc = _bowl("bowl_1", {"relation": "right"})
    res = resolve_reference(desc, [0, 1], dets, {}, CFG, look_alikes=2, viewer_right_xy=np.array([0.0, 1.0]))
    assert res.detection is None and "within" in res.reason
    res = resolve_reference(desc, [0, 1], dets, {}, CFG, look_alikes=2, viewer_right_xy=None)
    assert res.detection is None and "left and right" in res.reason
    # the look-alike not seen may be the one meant
    res = resolve_reference(desc, [0], dets, {}, CFG, look_alikes=2, viewer_right_xy=np.array([0.0, 1.0]))
    assert res.detection is None and "look-alikes seen" in res.reason


def test_the_viewers_right_is_the_named_cameras_image_x_axis_on_the_table():
    def frame(sensor, R):
        T = np.eye(4)
        T[:3, :3] = R
        return CameraFrame(sensor=sensor, frame_id=f"{sensor}_optical", stamp_s=0.0,
                           intrinsics=CameraIntrinsics(width=4, height=4, fx=2.0, fy=2.0, cx=2.0, cy=2.0),
                           T_world_camera=T, rgb=np.zeros((4, 4, 3), np.uint8), depth_m=None)

    # optical frame: x right, y down, z forward; looking along world -x, tilted down
    tilt = np.radians(30.0)
    z = np.array([-np.cos(tilt), 0.0, -np.sin(tilt)])
    x = np.array([0.0, 1.0, 0.0])
    across = frame("agentview", np.column_stack([x, np.cross(z, x), z]))
    down = frame("wrist", np.column_stack([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))  # x straight up
    assert viewer_right([across, down]) == pytest.approx([0.0, 1.0])
    assert viewer_right([down, across]) is None  # the first camera's x axis is vertical
    assert viewer_right([down, across], "agentview") == pytest.approx([0.0, 1.0])
    assert viewer_right([across], "overview") is None


def test_table_centre_is_the_middle_of_the_perceived_table_top():
    rng = np.random.default_rng(0)
    top = np.column_stack([rng.uniform(-0.3, 0.5, 4000), rng.uniform(-0.4, 0.2, 4000), np.full(4000, 0.9)])
    things = np.column_stack([rng.uniform(0.4, 0.9, 500), rng.uniform(0.1, 0.6, 500), rng.uniform(0.92, 1.1, 500)])
    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.9, 4000, True)
    centre = table_centre(np.vstack([top, things]), plane, CFG)
    assert centre == pytest.approx([0.1, -0.1], abs=0.02)
    assert table_centre(top[:10], plane, CFG) is None


def test_an_unresolvable_relation_picks_nothing():
    a, b = _det(BLACK, (0.50, 0.00, 0.03)), _det(BLACK, (0.50, 0.30, 0.03))
    desc = _bowl("bowl_1", {"relation": "next_to", "of": ["plate_1"]})
    # the landmark is not perceived
    assert resolve_reference(desc, [0, 1], [a, b], {}, CFG, look_alikes=2).detection is None
    # both equally near: within the margin, no pick
    plate = _landmark("plate_1", (0.50, 0.15, 0.01))
    res = resolve_reference(desc, [0, 1], [a, b], {"plate_1": plate}, CFG, look_alikes=2)
    assert res.detection is None and "within" in res.reason
    # only one of the two look-alikes seen: it may be the other one
    res = resolve_reference(desc, [0], [a, b], {"plate_1": _landmark("plate_1", (0.5, -0.1, 0.01))}, CFG,
                            look_alikes=2)
    assert res.detection is None and "look-alikes seen" in res.reason
    assert resolve_reference(desc, [], [a, b], {"plate_1": plate}, CFG, look_alikes=2).detection is None


def test_forbid_except_leaves_one_admissible_pair():
    C = np.array([[0.1, 0.2], [0.3, 0.1]])
    out = forbid_except(C, 0, 1)
    assert out[1, 0] == 0.3 and out[0, 0] > CFG.association.gate_cost and (out[:, 1] == C[:, 1]).all()
    assert (forbid_except(C, 1, None)[:, 1] > CFG.association.gate_cost).all()


# -- the perceiver's association --------------------------------------------------------------------------


def _perceiver(where):
    declared = [_bowl("bowl_1", where), _bowl("bowl_2"),
                ObjectDescriptor("ramekin_1", cls="ramekin", shape="cylinder", colour_rgb=WHITE, size_m=(0.08, 0.08, 0.04)),
                ObjectDescriptor("plate_1", cls="plate", shape="cylinder", colour_rgb=RED, size_m=(0.2, 0.2, 0.02))]
    return Perceiver(CFG, declared)


def _assign(p: Perceiver, dets):
    names = [d.name for d in p.declared]
    track_pos = [p.tracks[n].position if n in p.tracks else None for n in names]
    C = p._resolve_references(cost_matrix(dets, p.declared, CFG, track_pos), dets, 0.0)
    a = associate(C, CFG)
    return {names[j]: i for i, (j, _, _) in a.matches.items()}


@pytest.mark.parametrize("order", [0, 1])
def test_the_perceiver_gives_the_relation_its_bowl_and_the_twin_the_other(order):
    near = _det(BLACK, (0.52, 0.12, 0.03))
    far = _det(BLACK, (0.40, -0.25, 0.03))
    ramekin = _det(WHITE, (0.60, 0.20, 0.02), half=(0.04, 0.04, 0.02))
    plate = _det(RED, (0.45, -0.05, 0.01), half=(0.1, 0.1, 0.01))
    bowls = [near, far] if order == 0 else [far, near]
    dets = [bowls[0], ramekin, bowls[1], plate]
    p = _perceiver({"relation": "next_to", "of": ["ramekin_1"]})
    got = _assign(p, dets)
    assert dets[got["bowl_1"]] is near and dets[got["bowl_2"]] is far
    assert got["ramekin_1"] == 1 and got["plate_1"] == 3
    assert p.last_references["bowl_1"].detection == got["bowl_1"]


def test_the_perceiver_leaves_both_bowls_unseen_when_the_landmark_is_not_seen():
    dets = [_det(BLACK, (0.52, 0.12, 0.03)), _det(BLACK, (0.40, -0.25, 0.03)),
            _det(RED, (0.45, -0.05, 0.01), half=(0.1, 0.1, 0.01))]
    p = _perceiver({"relation": "next_to", "of": ["ramekin_1"]})
    got = _assign(p, dets)
    assert "bowl_1" not in got and "bowl_2" not in got  # the twin is not given either one by index
    assert got == {"plate_1": 2}
    assert p.last_references["bowl_1"].detection is None


def test_a_landmark_named_only_weakly_picks_out_nothing():
    """A brown thing of the ramekin's size where the ramekin should be is the ramekin's best
    match, at confidence 0.25: "the bowl next to the ramekin" is not read off it (on the
    development split a cookie box under the other bowl passed for the ramekin at 0.21, and
    the wrong bowl was picked)."""
    near = _det(BLACK, (0.52, 0.12, 0.03))
    far = _det(BLACK, (0.40, -0.25, 0.03))
    not_a_ramekin = _det((0.55, 0.35, 0.2), (0.60, 0.20, 0.02), half=(0.04, 0.04, 0.02))
    plate = _det(RED, (0.45, -0.05, 0.01), half=(0.1, 0.1, 0.01))
    dets = [near, not_a_ramekin, far, plate]
    p = _perceiver({"relation": "next_to", "of": ["ramekin_1"]})
    got = _assign(p, dets)
    assert "bowl_1" not in got and "bowl_2" not in got
    assert p.last_references["bowl_1"].detection is None
    # the same layout with the ramekin's own look: resolved
    dets[1] = _det(WHITE, (0.60, 0.20, 0.02), half=(0.04, 0.04, 0.02))
    p = _perceiver({"relation": "next_to", "of": ["ramekin_1"]})
    assert dets[_assign(p, dets)["bowl_1"]] is near


def test_a_weak_track_of_the_landmark_picks_out_nothing_either():
    """The ramekin named weakly at a reset (a track at 0.21, where the cookie box is) and not
    seen now: its track is no landmark, so "the bowl next to the ramekin" stays unresolved (on
    the development split this track picked out the wrong bowl at the pick's observation)."""
    from phyagentos.perception.tracks import Track

    near = _det(BLACK, (0.52, 0.12, 0.03))
    far = _det(BLACK, (0.40, -0.25, 0.03))
    plate = _det(RED, (0.45, -0.05, 0.01), half=(0.1, 0.1, 0.01))
    dets = [near, far, plate]
    for conf, resolved in ((0.21, False), (0.9, True)):
        p = _perceiver({"relation": "next_to", "of": ["ramekin_1"]})
        p.tracks["ramekin_1"] = Track.start("ramekin_1", _det(WHITE, (0.60, 0.20, 0.02), half=(0.04, 0.04, 0.02)),
                                            conf, 0.0, ("front",))
        got = _assign(p, dets)
        assert (p.last_references["bowl_1"].detection is not None) == resolved, (conf, p.last_references)
        assert resolved == ("bowl_1" in got and dets[got["bowl_1"]] is near)


def test_with_one_lookalike_in_view_neither_bowl_is_named():
    """The landmark is seen but only one black bowl: it may be the one meant or the other, so
    neither name is given to it."""
    dets = [_det(BLACK, (0.52, 0.12, 0.03)), _det(WHITE, (0.60, 0.20, 0.02), half=(0.04, 0.04, 0.02)),
            _det(RED, (0.45, -0.05, 0.01), half=(0.1, 0.1, 0.01))]
    p = _perceiver({"relation": "next_to", "of": ["ramekin_1"]})
    got = _assign(p, dets)
    assert got == {"ramekin_1": 1, "plate_1": 2}
    assert "look-alikes seen" in p.last_references["bowl_1"].reason


def test_a_tracked_bowl_keeps_its_identity_without_the_relation():
    """Once associated, the track decides: the bowl set down on the plate is still bowl_1,
    though 'next to the ramekin' now fits the other one better."""
    p = _perceiver({"relation": "next_to", "of": ["ramekin_1"]})
    ramekin = _det(WHITE, (0.60, 0.20, 0.02), half=(0.04, 0.04, 0.02))
    plate = _det(RED, (0.45, -0.05, 0.01), half=(0.1, 0.1, 0.01))
    first = [_det(BLACK, (0.52, 0.12, 0.03)), _det(BLACK, (0.40, -0.25, 0.03)), ramekin, plate]
    snap_names = _assign(p, first)
    from phyagentos.perception.tracks import Track

    for name, i in snap_names.items():
        p.tracks[name] = Track.start(name, first[i], 0.9, 0.0, ("front",))
    # the hand set bowl_1 down on the plate (its track is where it was let go); the ramekin is
    # now beside bowl_2: "next to the ramekin" would pick bowl_2's detection
    p.tracks["bowl_1"].position = np.array([0.45, -0.05, 0.04])
    ramekin = _det(WHITE, (0.40, -0.33, 0.02), half=(0.04, 0.04, 0.02))
    later = [_det(BLACK, (0.41, -0.24, 0.03)), _det(BLACK, (0.45, -0.05, 0.04), bottom=0.02), ramekin, plate]
    again = resolve_reference(p.declared[0], [0, 1], later, {"ramekin_1": _landmark("ramekin_1", (0.40, -0.33, 0.02))},
                              CFG, look_alikes=2)
    assert again.detection == 0
    got = _assign(p, later)
    assert got["bowl_1"] == 1 and got["bowl_2"] == 0
    assert p.last_references == {}  # no reference left to resolve


def _tracked(name, pos, *, held=False):
    from phyagentos.perception.tracks import Track

    return Track(name, np.array(pos, float), 1e-6, 0.0, 1.0, np.array([0.056, 0.056, 0.025]), "cylinder",
                 np.array(BLACK), 300, 0.99, 0.0, 0.0, held=held)


def _hand_at(xyz):
    from phyagentos.perception.frames import Proprioception

    tcp = np.eye(4)
    tcp[:3, 3] = xyz
    return Proprioception(0.0, ("j1",), np.zeros(1), np.zeros(1), np.zeros(1), 0.0, 0.0, None, None, tcp)


def test_a_held_bowl_with_a_reference_leaves_its_twin_on_the_table_its_name():
    """"The black bowl between the plate and the ramekin" in the hand: its track ties
    association where the hand is, so the one bowl seen on the table is its twin, named. With no
    position for the held bowl (the behaviour before, kept for a held object that has no
    look-alike), both bowls matched that sighting alike and it was left unknown."""
    p = _perceiver({"relation": "between", "of": ["plate_1", "ramekin_1"]})
    p.tracks["bowl_1"] = _tracked("bowl_1", (0.50, 0.10, 0.15), held=True)
    p.tracks["bowl_2"] = _tracked("bowl_2", (0.40, -0.25, 0.03))
    hand = _hand_at((0.50, 0.10, 0.18))
    dets = [_det(BLACK, (0.40, -0.25, 0.03))]
    pos = p.track_positions(hand)
    assert np.allclose(pos[0], (0.50, 0.10, 0.18)) and np.allclose(pos[1], (0.40, -0.25, 0.03))
    assert pos[2] is None and pos[3] is None  # untracked
    names = [d.name for d in p.declared]
    C = cost_matrix(dets, p.declared, CFG) + track_costs(dets, len(names), CFG, pos)
    a = associate(C, CFG)
    assert {names[j] for j, _, _ in a.matches.values()} == {"bowl_2"}
    before = [None, pos[1], None, None]
    C = cost_matrix(dets, p.declared, CFG) + track_costs(dets, len(names), CFG, before)
    assert not associate(C, CFG).matches


def test_a_held_object_with_no_look_alike_ties_nothing():
    p = _perceiver(None)
    p.tracks["plate_1"] = _tracked("plate_1", (0.50, 0.10, 0.15), held=True)
    assert p.track_positions(_hand_at((0.5, 0.1, 0.2)))[3] is None


@pytest.mark.parametrize("order", [(0, 1, 2), (2, 0, 1), (1, 2, 0)])
def test_front_back_and_middle_are_read_across_the_table_as_the_scene_camera_sees_it(order):
    # LIBERO-90's KITCHEN_SCENE2 (its regions, generated placements): the black bowl "at the front"
    # stands nearest the agentview camera (+x, across the table from the robot), the one "at the back"
    # nearest the robot, and "the middle black bowl" between them
    front, middle, back = (0.10, 0.15, 0.9), (-0.05, 0.20, 0.9), (-0.15, 0.05, 0.9)
    dets = [_det(BLACK, p) for p in (front, middle, back)]
    dets = [dets[i] for i in order]
    want = {"front": order.index(0), "middle": order.index(1), "back": order.index(2)}
    facing_robot = np.array([0.0, 1.0])  # the agentview camera's right: world +y
    for side, idx in want.items():
        res = resolve_reference(_bowl("bowl_1", {"relation": side}), [0, 1, 2], dets, {}, CFG, look_alikes=3,
                                viewer_right_xy=facing_robot)
        assert res.detection == idx, (side, res.reason)
    # seen from behind the robot, the front and the back swap; the middle one stays the middle one
    for side, idx in (("front", want["back"]), ("back", want["front"]), ("middle", want["middle"])):
        res = resolve_reference(_bowl("bowl_1", {"relation": side}), [0, 1, 2], dets, {}, CFG, look_alikes=3,
                                viewer_right_xy=-facing_robot)
        assert res.detection == idx, (side, res.reason)


def test_a_middle_one_is_one_of_three_seen_and_clearly_between_the_others():
    row = [_det(BLACK, (x, 0.0, 0.9)) for x in (-0.2, 0.0, 0.2)]
    desc = _bowl("bowl_1", {"relation": "middle"})
    res = resolve_reference(desc, [0, 1, 2], row, {}, CFG, look_alikes=3)
    assert res.detection == 1 and "middle" in res.reason
    # two seen of three: the middle one cannot be told (the third may stand anywhere)
    res = resolve_reference(desc, [0, 2], row, {}, CFG, look_alikes=2)
    assert res.detection is None and "one of at least three" in res.reason
    # four in a row: two stand between the others, 2 cm apart in how central they are -> unresolved
    four = [_det(BLACK, (x, 0.0, 0.9)) for x in (-0.3, -0.1, 0.12, 0.3)]
    res = resolve_reference(desc, [0, 1, 2, 3], four, {}, CFG, look_alikes=4)
    assert res.detection is None and "within" in res.reason
    # front and back need the camera's view of the table, as left and right do
    res = resolve_reference(_bowl("bowl_1", {"relation": "front"}), [0, 1, 2], row, {}, CFG, look_alikes=3)
    assert res.detection is None and "front and back" in res.reason
