"""Objects cut by the image border: told by their pixels at the border, matched with their seen
size as a lower bound, a round one completed from its look, and never allowed to move a track
they do not look like (phyagentos.perception.truncation and the perceiver's use of it)."""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.perception import ObjectDescriptor, PerceptionConfig, Perceiver
from phyagentos.perception import perceiver as perceiver_module
from phyagentos.perception.association import cost_matrix
from phyagentos.perception.cloud import Cloud
from phyagentos.perception.colour import srgb_to_lab
from phyagentos.perception.detect import Detection
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics
from phyagentos.perception.truncation import complete_box, complete_round, cut_direction

PINK = (0.85, 0.6, 0.6, 1.0)


def _camera(width=64, height=48):
    """A pinhole camera at the origin looking along world +z (its optical frame is the world's)."""
    intr = CameraIntrinsics(width=width, height=height, fx=50.0, fy=50.0, cx=(width - 1) / 2, cy=(height - 1) / 2)
    return CameraFrame(sensor="cam", frame_id="cam_optical", stamp_s=0.0, intrinsics=intr, T_world_camera=np.eye(4),
                       rgb=np.zeros((height, width, 3), np.uint8), depth_m=np.ones((height, width), np.float32))


def _cloud_at_pixels(frame, us, vs, depth=1.0):
    k = frame.intrinsics
    us, vs = np.asarray(us, float), np.asarray(vs, float)
    pts = np.stack([(us - k.cx) / k.fx * depth, (vs - k.cy) / k.fy * depth, np.full(us.shape, depth)], axis=1)
    n = len(pts)
    return Cloud(pts, np.zeros((n, 3), np.uint8), np.full(n, depth), np.zeros(n, np.int16))


def test_a_segment_reaching_the_image_border_is_cut_towards_that_border():
    cam = _camera()
    uu, vv = np.meshgrid(np.arange(0, 12), np.arange(20, 28))
    cloud = _cloud_at_pixels(cam, uu.ravel(), vv.ravel())
    d = cut_direction(cloud, np.arange(len(cloud)), [cam], [1])
    assert d is not None and d[0] < -0.99  # the left border: image -u is world -x here
    inside = _cloud_at_pixels(cam, uu.ravel() + 20, vv.ravel())
    assert cut_direction(inside, np.arange(len(inside)), [cam], [1]) is None


def test_a_segment_one_camera_sees_whole_is_not_cut():
    cam = _camera()
    uu, vv = np.meshgrid(np.arange(0, 12), np.arange(20, 28))
    at_border = _cloud_at_pixels(cam, uu.ravel(), vv.ravel())
    whole = _cloud_at_pixels(cam, uu.ravel() + 20, vv.ravel())
    both = Cloud(np.vstack([at_border.points, whole.points]), np.zeros((2 * len(whole), 3), np.uint8),
                 np.ones(2 * len(whole)), np.r_[np.zeros(len(whole), np.int16), np.ones(len(whole), np.int16)])
    # the second camera's points are the same segment seen whole (a second view of it)
    assert cut_direction(both, np.arange(len(both)), [cam, cam], [1, 1]) is None
    assert cut_direction(both, np.arange(len(whole)), [cam, cam], [1, 1]) is not None


@pytest.mark.parametrize("visible_from", [-0.05, 0.0, 0.03])
def test_a_round_object_seen_in_part_is_completed_from_its_far_edge_and_radius(visible_from):
    rng = np.random.default_rng(0)
    r = 0.07
    pts = rng.uniform(-r, r, size=(4000, 2))
    pts = pts[(np.hypot(pts[:, 0], pts[:, 1]) <= r) & (pts[:, 0] <= -visible_from)] + [0.3, -0.2]
    # out of view on the +x side beyond x = -visible_from
    centre = complete_round(pts, np.array([1.0, 0.0]), r)
    assert np.linalg.norm(centre - [0.3, -0.2]) < 0.004, centre


def _box_part(centre, half, yaw, keep, rng):
    """(N, 2) points over a box's footprint (``centre`` (2,), ``half`` (2,) m, ``yaw`` rad) where
    ``keep(points)`` holds (the part in view)."""
    c, s = np.cos(yaw), np.sin(yaw)
    local = rng.uniform(-1.0, 1.0, size=(6000, 2)) * half
    pts = local @ np.array([[c, s], [-s, c]]) + centre
    return pts[keep(pts)]


def _fit(pts, yaw):
    """Centre (2,) and half extents (2,) of ``pts`` along the axes of ``yaw``: the part's own box."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    local = pts @ R
    lo, hi = local.min(axis=0), local.max(axis=0)
    return R @ (0.5 * (lo + hi)), 0.5 * (hi - lo)


@pytest.mark.parametrize("yaw", [0.0, 0.3, np.pi / 2, np.pi / 4])
def test_a_box_seen_in_part_is_completed_from_its_far_edge_and_its_looks_length(yaw):
    """LIBERO's basket (17.4 by 16.2 cm by its look) at the scene camera's right border was seen
    short by 2-3 cm and centred 1-2 cm towards the image's middle; its far edge and its look's
    length put its centre back."""
    rng = np.random.default_rng(1)
    centre, half = np.array([0.0, 0.26]), np.array([0.087, 0.081])
    pts = _box_part(centre, half, yaw, lambda p: p[:, 1] <= 0.29, rng)  # out of view beyond y = 0.29
    seen_c, seen_h = _fit(pts, yaw)
    out = complete_box(pts, np.array([0.0, 1.0]), seen_c, yaw, seen_h, (0.162, 0.174))
    if max(abs(np.sin(yaw)), abs(np.cos(yaw))) > 0.866:  # the cut runs along one of the box's axes
        assert np.linalg.norm(seen_c - centre) > 0.01  # the part alone is well short
        assert out is not None
        assert np.linalg.norm(out[0] - centre) < 0.004, out
        assert np.allclose(np.sort(out[1]), np.sort(half), atol=0.004)
    else:  # across a corner: left as seen
        assert out is None


def test_a_box_part_longer_than_its_look_or_not_short_of_it_is_left_as_seen():
    rng = np.random.default_rng(2)
    pts = _box_part(np.array([0.0, 0.0]), np.array([0.05, 0.03]), 0.0, lambda p: p[:, 0] <= 0.04, rng)
    c, h = _fit(pts, 0.0)
    assert complete_box(pts, np.array([1.0, 0.0]), c, 0.0, h, (0.06, 0.06)) is None  # seen longer than the look
    whole = _box_part(np.array([0.0, 0.0]), np.array([0.05, 0.03]), 0.0, lambda p: p[:, 0] <= 1.0, rng)
    c, h = _fit(whole, 0.0)
    out = complete_box(whole, np.array([1.0, 0.0]), c, 0.0, h, (0.1, 0.06))
    assert out is None or np.linalg.norm(out[0] - c) < 0.002  # all of it seen: nowhere to go


def _det(half, shape="box", cut=(1.0, 0.0)):
    rgb = np.array(PINK[:3])
    return Detection(position=np.array([0.5, 0.3, 0.44]), yaw=0.0, half_extents=np.array(half, float), shape=shape,
                     colour_rgb=rgb, colour_lab=srgb_to_lab(rgb[None])[0], points=300, cameras=1,
                     position_std_m=0.002, yaw_std_rad=0.1, view_agreement=1.0, bottom_m=0.0,
                     cut_direction=None if cut is None else np.array(cut))


def test_a_cut_detection_is_matched_with_its_size_as_a_lower_bound_and_no_shape():
    plate = ObjectDescriptor("plate_1", shape="cylinder", colour_rgb=PINK[:3], size_m=(0.138, 0.138, 0.03))
    cfg = PerceptionConfig.default()
    half_seen = cost_matrix([_det((0.069, 0.03, 0.015))], [plate], cfg)[0, 0]
    whole_view = cost_matrix([_det((0.069, 0.03, 0.015), cut=None)], [plate], cfg)[0, 0]
    too_big = cost_matrix([_det((0.12, 0.03, 0.015))], [plate], cfg)[0, 0]
    assert half_seen < 0.3 < whole_view  # half a plate, box-shaped, at the border: a plate
    assert too_big > half_seen + 1.0  # bigger than the look: no plate, cut or not


# ------------------------------------------------------------------ rendered (MuJoCo)


@pytest.fixture(scope="module")
def scene():
    from phyagentos.perception.synthetic import DEFAULT_CAMERAS, SyntheticScene

    s = SyntheticScene([], cameras=DEFAULT_CAMERAS, pool_per_shape=3)
    yield s
    s.close()


def _observe(scene, perceiver, stamp_s=0.0, cameras=("front",)):
    from phyagentos.perception.synthetic import CameraNoise

    frames = [scene.capture(c, noise=CameraNoise(), rng=np.random.default_rng(0), stamp_s=stamp_s) for c in cameras]
    snap = perceiver.observe(frames, scene.proprioception(stamp_s=stamp_s))
    return {e["name"]: e for e in snap["entities"]}, snap


PLATE = ObjectDescriptor("plate", shape="cylinder", colour_rgb=PINK[:3], size_m=(0.14, 0.14, 0.024))


@pytest.mark.sim
@pytest.mark.parametrize("y", [0.36, 0.40])
def test_a_plate_half_out_of_the_frame_is_named_with_its_true_centre(scene, monkeypatch, y):
    from phyagentos.perception.synthetic import SyntheticObject

    scene.place([SyntheticObject("plate", "cylinder", (0.07, 0.07, 0.012), (0.55, y), rgba=PINK)])
    ents, _ = _observe(scene, Perceiver(PerceptionConfig.default(), [PLATE]))
    e = ents["plate"]
    assert e["kind"] == "object" and e["attributes"]["confidence"] > 0.8
    assert np.hypot(e["position"][0] - 0.55, e["position"][1] - y) < 0.007
    # without the border's cut: the part seen is no plate (or one centred 1-3 cm short)
    monkeypatch.setattr(perceiver_module, "cut_direction", lambda *a, **k: None)
    old, _ = _observe(scene, Perceiver(PerceptionConfig.default(), [PLATE]))
    assert "plate" not in old or old["plate"]["attributes"]["confidence"] < 0.5


@pytest.mark.sim
def test_a_basket_cut_by_the_frame_is_named_with_its_true_centre_and_size(scene, monkeypatch):
    """A box-shaped open container half out of the scene camera's frame (LIBERO-10's basket at
    the agentview's right border: seen 1-2 cm short of its centre, so a place into it aimed
    there)."""
    from phyagentos.perception.synthetic import SyntheticObject

    tan = (0.6, 0.58, 0.5)
    basket = ObjectDescriptor("basket_1", shape="box", colour_rgb=tan, size_m=(0.16, 0.16, 0.14))
    scene.place([SyntheticObject("basket", "box", (0.08, 0.08, 0.07), (0.55, 0.40), rgba=(*tan, 1))])
    ents, _ = _observe(scene, Perceiver(PerceptionConfig.default(), [basket]))
    e = ents["basket_1"]
    assert np.hypot(e["position"][0] - 0.55, e["position"][1] - 0.40) < 0.006, e["position"]
    assert np.allclose(e["size"][:2], [0.08, 0.08], atol=0.006)
    monkeypatch.setattr(perceiver_module, "complete_box", lambda *a, **k: None)  # as seen: short of it
    old, _ = _observe(scene, Perceiver(PerceptionConfig.default(), [basket]))
    assert np.hypot(old["basket_1"]["position"][0] - 0.55, old["basket_1"]["position"][1] - 0.40) > 0.01


@pytest.mark.sim
def test_a_sliver_at_the_border_alone_names_nothing_but_confirms_a_tracked_object(scene):
    from phyagentos.perception.synthetic import SyntheticObject

    scene.place([SyntheticObject("plate", "cylinder", (0.07, 0.07, 0.012), (0.55, 0.45), rgba=PINK)])
    p = Perceiver(PerceptionConfig.default(), [PLATE])
    ents, snap = _observe(scene, p)
    assert "plate" not in ents and "plate" in snap["unseen"]  # 2 cm of it: could be anything pink
    assert any(e["kind"] == "unknown" for e in ents.values())
    # seen whole by a second camera first, the sliver keeps it where it is
    p = Perceiver(PerceptionConfig.default(), [PLATE])
    _observe(scene, p, cameras=("front", "side"))
    ents, _ = _observe(scene, p, stamp_s=1.0)
    assert ents["plate"]["attributes"]["confidence"] > 0.5
    assert np.hypot(ents["plate"]["position"][0] - 0.55, ents["plate"]["position"][1] - 0.45) < 0.01


@pytest.mark.sim
def test_a_part_at_the_border_completed_off_a_confident_track_never_moves_it(scene):
    """The wrist camera saw the plate whole; the scene camera, with half of it out of the frame,
    completes it 2 cm away (LIBERO-10 task 4: a mug on the left plate): the part confirms the
    plate where it was and does not restart its track there."""
    from phyagentos.perception.synthetic import SyntheticObject

    scene.place([SyntheticObject("plate", "cylinder", (0.07, 0.07, 0.012), (0.55, 0.40), rgba=PINK)])
    p = Perceiver(PerceptionConfig.default(), [PLATE])
    _observe(scene, p, cameras=("front", "side"))
    t = p.tracks["plate"]
    t.position[:2] = (0.55, 0.38)  # where the whole sighting put it, 2 cm from where the part completes it
    t.var_xy = 0.002 ** 2
    ents, _ = _observe(scene, p, stamp_s=0.5)
    assert ents["plate"]["attributes"]["confidence"] > 0.5
    assert np.allclose(p.tracks["plate"].position[:2], (0.55, 0.38), atol=1e-9)


@pytest.mark.sim
def test_the_right_plate_is_told_from_the_left_one_it_took(scene):
    from phyagentos.perception.synthetic import SyntheticObject

    scene.place([SyntheticObject("a", "cylinder", (0.07, 0.07, 0.012), (0.55, -0.18), rgba=PINK),
                 SyntheticObject("b", "cylinder", (0.07, 0.07, 0.012), (0.55, 0.18), rgba=PINK)])
    looks = [ObjectDescriptor(n, shape="cylinder", colour_rgb=PINK[:3], size_m=(0.14, 0.14, 0.024),
                              where={"relation": side}) for n, side in (("plate_1", "left"), ("plate_2", "right"))]
    ents, snap = _observe(scene, Perceiver(PerceptionConfig.default(), looks))
    assert snap["references"]["plate_1"]["resolved"] and snap["references"]["plate_2"]["resolved"], snap["references"]
    # the front camera looks along world -x: its image's right is world +y
    assert ents["plate_2"]["position"][1] > 0.1 > -0.1 > ents["plate_1"]["position"][1]


@pytest.mark.sim
def test_a_weak_look_elsewhere_never_moves_a_confident_track(scene):
    from phyagentos.perception.synthetic import SyntheticObject

    p = Perceiver(PerceptionConfig.default(), [PLATE])
    scene.place([SyntheticObject("plate", "cylinder", (0.07, 0.07, 0.012), (0.50, -0.10), rgba=PINK)])
    first, _ = _observe(scene, p, cameras=("front", "side"))
    assert first["plate"]["attributes"]["confidence"] > 0.8
    # the plate gone; a smaller, browner disc 25 cm away looks only a little like it
    scene.place([SyntheticObject("plate", "cylinder", (0.05, 0.05, 0.012), (0.55, 0.15), rgba=(0.7, 0.45, 0.35, 1))])
    second, _ = _observe(scene, p, stamp_s=1.0, cameras=("front", "side"))
    assert "plate" not in second or np.hypot(second["plate"]["position"][0] - 0.55,
                                             second["plate"]["position"][1] - 0.15) > 0.1
    assert p.tracks["plate"].confidence > 0.8 and np.allclose(p.tracks["plate"].position[:2], (0.50, -0.10), atol=0.01)


def test_a_weak_sighting_where_a_confident_track_stands_keeps_the_remembered_confidence():
    from phyagentos.perception.tracks import REMEMBERED_CONFIDENCE, Track

    cfg = PerceptionConfig.default()
    det = _det((0.069, 0.03, 0.015), cut=(0.0, 1.0))

    def track():
        return Track.start("plate_1", det, 0.95, 0.0, ("agentview",))

    # part of the plate seen where it stands, weakly: the rest hidden or out of the frame
    kept = track()
    kept.update(det, 0.1, 1.0, ("agentview",), cfg, weak_below=0.5)
    assert kept.confidence == pytest.approx(0.95 * REMEMBERED_CONFIDENCE)
    plain = track()
    plain.update(det, 0.1, 1.0, ("agentview",), cfg)  # without: agreeing sightings only fuse
    assert plain.confidence < 0.6
    # elsewhere, the weak sighting restarts the track at its own confidence
    far = track()
    moved = Detection(**{**det.__dict__, "position": det.position + [0.3, 0.0, 0.0]})
    far.update(moved, 0.1, 1.0, ("agentview",), cfg, weak_below=0.5)
    assert far.confidence == pytest.approx(0.1)


def test_weak_sightings_in_a_row_never_wear_a_confident_track_below_the_remembered_confidence():
    # a mug at the back of LIBERO's microwave, seen whole from its mouth (0.74), then only weakly
    # by the scene camera frame after frame: each frame must not take the remembered share again
    from phyagentos.perception.tracks import REMEMBERED_CONFIDENCE, Track

    cfg = PerceptionConfig.default()
    det = _det((0.069, 0.03, 0.015), cut=(0.0, 1.0))
    t = Track.start("mug_1", det, 0.74, 0.0, ("robot0_eye_in_hand",))
    for k in range(1, 8):
        t.update(det, 0.33, 0.1 * k, ("agentview",), cfg, weak_below=0.5)
        assert t.confidence == pytest.approx(0.74 * REMEMBERED_CONFIDENCE)
    t.update(det, 0.9, 1.0, ("agentview",), cfg, weak_below=0.5)  # a confident sighting fuses as ever
    assert t.confidence > 0.9 and t.confident_before is None
    t.update(det, 0.2, 1.1, ("agentview",), cfg, weak_below=0.5)  # the next weak run starts from there
    assert t.confidence == pytest.approx(t.confident_before * REMEMBERED_CONFIDENCE) and t.confident_before > 0.9


def test_a_part_at_the_border_never_makes_a_whole_sighting_ambiguous():
    can = ObjectDescriptor("soup_1", shape="cylinder", colour_rgb=PINK[:3], size_m=(0.066, 0.066, 0.1))
    whole = Detection(**{**_det((0.033, 0.033, 0.05), shape="cylinder", cut=None).__dict__})
    part = _det((0.03, 0.012, 0.05))  # its look's colour, cut by the border elsewhere
    p = Perceiver(PerceptionConfig.default(), [can])
    C = cost_matrix([whole, part], [can], p.config)
    assert C[1, 0] < p.config.association.gate_cost  # the part alone would do
    assoc = p._associate_parts_weighed(C, [whole, part])
    assert assoc.matches.keys() == {0} and assoc.ambiguous == ()
    alone = p._associate_parts_weighed(C[1:], [part])
    assert alone.matches.keys() == {0}  # with no whole sighting, the part names it


def test_an_objects_height_known_when_it_was_let_go_survives_a_restarted_track():
    from phyagentos.perception.tracks import Track

    cfg = PerceptionConfig.default()
    det = _det((0.048, 0.048, 0.062), shape="cylinder", cut=None)
    t = Track.start("mug_1", det, 0.9, 0.0, ("agentview",))
    t.known_height_m = 0.1232
    moved = Detection(**{**det.__dict__, "position": det.position + [0.2, 0.0, 0.0]})
    assert t.update(moved, 0.9, 1.0, ("agentview",), cfg) is False  # seen elsewhere: restarted
    assert t.known_height_m == 0.1232 and np.allclose(t.position, moved.position)


@pytest.mark.sim
def test_an_object_let_go_seen_short_on_a_piece_stands_its_known_height_below_its_top(scene):
    """LIBERO-10 task 6: the mug just set on the plate was seen 9.2 cm tall of its 12.3, stacked on
    a piece split off below it (its handle's foot and the plate's rim), so "not on the plate".
    Its height known from the hand, its bottom is its top less that height."""
    from phyagentos.perception.synthetic import SyntheticObject

    mug = ObjectDescriptor("mug", shape="cylinder", colour_rgb=(0.15, 0.35, 0.85), size_m=(0.08, 0.08, 0.12))
    scene.place([SyntheticObject("piece", "box", (0.05, 0.05, 0.015), (0.55, 0.05), rgba=PINK),
                 SyntheticObject("mug", "cylinder", (0.04, 0.04, 0.045), (0.55, 0.05), rgba=(0.15, 0.35, 0.85, 1),
                                 z_base_m=0.03)])
    p = Perceiver(PerceptionConfig.default(), [mug])
    seen, _ = _observe(scene, p, cameras=("front", "side"))
    assert seen["mug"]["position"][2] == pytest.approx(0.03 + 0.045, abs=0.006)  # as seen: on the piece
    p.tracks["mug"].known_height_m = 0.12  # let go by the hand, 12 cm tall
    again, _ = _observe(scene, p, stamp_s=1.0, cameras=("front", "side"))
    top = 0.03 + 0.09
    assert again["mug"]["position"][2] == pytest.approx(top - 0.06, abs=0.006)
    assert again["mug"]["size"][2] == pytest.approx(0.06, abs=1e-6)


def test_a_weak_look_far_from_where_the_hand_let_an_object_go_is_not_that_object():
    """LIBERO-10 task 1: the cream cheese let go into the basket, hidden by its walls, was matched
    at confidence 0.23 to a segment 39 cm away; the look for it inside the basket never ran. A
    weak match beyond RELEASE_REACH_M of the release point is refused; a near one, or a
    confident one anywhere (a can that rolled off), is taken."""
    from phyagentos.perception.tracks import Track

    p = Perceiver(PerceptionConfig.default(), [ObjectDescriptor("cream_cheese_1", shape="box")])
    det = _det((0.042, 0.022, 0.015), cut=None)
    p.tracks["cream_cheese_1"] = t = Track.start("cream_cheese_1", det, 0.95, 0.0, ("agentview",))
    t.held = True
    placed = det.position[:2] + [0.0, 0.39]
    reach = perceiver_module.RELEASE_REACH_M
    assert p._weak_elsewhere("cream_cheese_1", det, 0.23, 1.0, placed)
    near = Detection(**{**det.__dict__, "position": det.position + [0.0, 0.39 - 0.8 * reach, 0.0]})
    assert not p._weak_elsewhere("cream_cheese_1", near, 0.23, 1.0, placed)
    assert not p._weak_elsewhere("cream_cheese_1", det, 0.9, 1.0, placed)


def test_a_match_far_from_where_an_object_was_let_go_is_not_it_when_it_shows_in_the_container_there(monkeypatch):
    """LIBERO-10 task 1: the butter let go into the basket, its top seen between the walls, was
    matched at confidence 0.53 to a small segment 38 cm away at the table's edge, so the look
    inside the basket never ran. Such a match is refused when the object shows inside a
    container where the hand let it go (looked for there, not where its track last stood); it
    stands when nothing shows there (a can that rolled off), and a near match is never probed."""
    from phyagentos.perception.tracks import Track

    p = Perceiver(PerceptionConfig.default(), [ObjectDescriptor("butter_1", shape="box")])
    det = _det((0.04, 0.02, 0.009), cut=None)
    p.tracks["butter_1"] = t = Track.start("butter_1", det, 0.99, 0.0, ("agentview",))
    t.held = True  # being let go now: no release recorded on the track yet
    placed = det.position[:2] + [0.0, -0.38]
    probed = []

    def shows(found):
        def probe(track, cloud, heights, dets, indices, sensors, others=()):
            probed.append(np.round(track.position[:2], 4).tolist())
            return (0, np.array([*placed, 0.46]), 0.96, 200, ("wrist",), 0.03) if found else None
        return probe

    args = (None, np.zeros(0), [det], [], ["agentview"])
    monkeypatch.setattr(perceiver_module, "_released_inside", shows(True))
    assert p._inside_where_let_go("butter_1", det, placed, *args)
    assert probed == [np.round(placed, 4).tolist()]  # looked for where the hand let it go
    assert np.allclose(t.position[:2], det.position[:2])  # the track itself untouched
    monkeypatch.setattr(perceiver_module, "_released_inside", shows(False))
    assert not p._inside_where_let_go("butter_1", det, placed, *args)  # rolled off: the match stands
    probed.clear()
    near = Detection(**{**det.__dict__, "position": np.array([*placed, 0.44]) + [0.05, 0.0, 0.0]})
    assert not p._inside_where_let_go("butter_1", near, placed, *args) and not probed
    assert not p._inside_where_let_go("butter_1", det, None, *args)  # never let go


@pytest.mark.sim
def test_an_object_seen_resting_in_a_container_is_not_found_higher_up_its_walls(scene, monkeypatch):
    """LIBERO-10 task 1: the butter seen on the basket's floor from the wrist camera was then
    "found" 4.4 cm higher from the ready pose, where the basket's far wall shows over the near
    one, at 0.51; the next look found nothing and it left the snapshot (a false failure). A find
    more than CONTENT_RISE_M above where an object rested inside a container, seen there at 0.5
    or more and not moved since, is not it: the track is kept (and reported remembered where
    something hides it); a find at its height moves it, and so does any find of a track only
    weakly seen where it rested."""
    from phyagentos.perception.synthetic import SyntheticObject
    from phyagentos.perception.tracks import Track

    scene.place([SyntheticObject("crate", "box", (0.08, 0.08, 0.07), (0.55, 0.05), rgba=(0.6, 0.58, 0.5, 1))])
    butter = ObjectDescriptor("butter_1", shape="box", colour_rgb=(0.8, 0.7, 0.3), size_m=(0.08, 0.04, 0.018))
    p = Perceiver(PerceptionConfig.default(), [butter])
    p.tracks["butter_1"] = t = Track.start("butter_1", _det((0.04, 0.02, 0.009), cut=None), 0.96, 0.0, ("wrist",))
    t.released_s, t.inside_of = 0.5, "basket_1"
    at = {"z": 0.0}

    def found(track, cloud, heights, dets, indices, sensors, others=(), *, tracked_top_m=None):
        return 0, np.array([0.55, 0.05, at["z"]]), 0.8, 120, ("front",), 0.03

    monkeypatch.setattr(perceiver_module, "_released_inside", found)
    _observe(scene, p, stamp_s=1.0)  # just let go: found where it rests, wherever that is
    rested, where = t.bottom_m, t.position.copy()
    t.released_s = None  # seen inside since, not moved by the hand
    at["z"] = float(where[2]) + perceiver_module.CONTENT_RISE_M + 0.024
    _observe(scene, p, stamp_s=2.0)
    assert t.bottom_m == rested and np.array_equal(t.position, where) and t.last_seen_s == 1.0
    at["z"] = float(where[2]) + 0.5 * perceiver_module.CONTENT_RISE_M
    _observe(scene, p, stamp_s=3.0)
    assert t.bottom_m == pytest.approx(rested + 0.5 * perceiver_module.CONTENT_RISE_M) and t.last_seen_s == 3.0
    # a weak find is no rest (the sauce can found weakly on the floor, then standing on the soup)
    t.confidence, risen = 0.44, t.bottom_m + perceiver_module.CONTENT_RISE_M + 0.024
    at["z"] += perceiver_module.CONTENT_RISE_M + 0.024
    _observe(scene, p, stamp_s=4.0)
    assert t.bottom_m == pytest.approx(risen) and t.last_seen_s == 4.0


@pytest.mark.sim
def test_an_object_let_go_is_as_tall_as_its_look_whatever_its_track_made_of_it(scene):
    """libero_spatial task 5: a bowl picked off a ramekin was tracked 5.7 cm tall for its look's
    5.05; set on a plate whose floor its body hid, it stood no higher than that, so it was taken
    to rest on the table and the verifier could not say it was on the plate. Its look's height
    (``size_range_m``) bounds the tracked one: it stands on something hidden, 1 cm up."""
    from phyagentos.perception.synthetic import SyntheticObject

    bowl = ObjectDescriptor("bowl", shape="cylinder", colour_rgb=(0.15, 0.35, 0.85), size_m=(0.1, 0.1, 0.05),
                            size_range_m=((0.099, 0.099, 0.049), (0.101, 0.101, 0.051)))
    p = Perceiver(PerceptionConfig.default(), [bowl])
    scene.place([SyntheticObject("bowl", "cylinder", (0.05, 0.05, 0.025), (0.55, 0.05), rgba=(0.15, 0.35, 0.85, 1))])
    _observe(scene, p, cameras=("front", "side"))
    t = p.tracks["bowl"]
    t.half_extents[2], t.released_s = 0.0287, 0.5  # tracked too tall, then let go
    scene.place([SyntheticObject("bowl", "cylinder", (0.05, 0.05, 0.025), (0.55, 0.05), rgba=(0.15, 0.35, 0.85, 1),
                                 z_base_m=0.01)])
    again, _ = _observe(scene, p, stamp_s=1.0, cameras=("front", "side"))
    bottom = again["bowl"]["position"][2] - again["bowl"]["size"][2]
    assert bottom == pytest.approx(0.01, abs=0.003), bottom
    assert p.tracks["bowl"].known_height_m == pytest.approx(0.051)


def test_a_can_let_go_onto_something_hidden_in_a_basket_is_matched_with_its_height_as_an_upper_bound():
    """LIBERO-10 task 0 (development run): the tomato sauce can let go into the basket stood on the
    alphabet soup lying in it; seen from the rim up and fitted down to the table it was 18 cm tall
    for its look's 9.1, and it named nothing (a false failure of the place). Where the hand let it
    go (and at its next looks, its height known from the hand), its measured height is an upper
    bound; a tall segment 9 cm away (the basket's wall), an object never let go and one still in
    the hand keep the height error."""
    from phyagentos.perception.tracks import Track

    red = (0.23, 0.12, 0.05)
    sauce = ObjectDescriptor("tomato_sauce_1", shape="cylinder", colour_rgb=red, size_m=(0.0674, 0.0674, 0.0914),
                             size_range_m=((0.0672, 0.0658, 0.0912), (0.0683, 0.0683, 0.0914)))
    cfg = PerceptionConfig.default()
    p = Perceiver(cfg, [sauce])

    def seen(dx, height=0.184):
        rgb = np.array(red)
        return Detection(position=np.array([0.5 + dx, 0.3, 0.43 + height / 2]), yaw=0.0,
                         half_extents=np.array([0.034, 0.034, height / 2]), shape="cylinder", colour_rgb=rgb,
                         colour_lab=srgb_to_lab(rgb[None])[0], points=800, cameras=1, position_std_m=0.002,
                         yaw_std_rad=np.pi, view_agreement=1.0, bottom_m=0.0)

    dets = [seen(0.002), seen(0.09, height=0.152)]
    raw = cost_matrix(dets, [sauce], cfg)
    assert raw[0, 0] > cfg.association.gate_cost  # as tall as 18 cm: no sauce can
    upright = seen(0.0, height=0.0914)
    p.tracks["tomato_sauce_1"] = t = Track.start("tomato_sauce_1", upright, 0.95, 0.0, ("agentview",))
    assert t.known_height_m is None
    for state in ("never let go", "held"):
        t.held = state == "held"
        assert np.array_equal(p._hidden_base_where_let_go(raw, dets), raw), state
    t.held, t.released_s = False, 1.0  # let go where it stands
    got = p._hidden_base_where_let_go(raw, dets)
    assert got[0, 0] < 0.5 and got[1, 0] == raw[1, 0]
    assert got[0, 0] == pytest.approx(cost_matrix([upright], [sauce], cfg)[0, 0], abs=0.05)
    t.released_s, t.known_height_m = None, 0.0914  # matched so since: its height known from the hand
    assert np.array_equal(p._hidden_base_where_let_go(raw, dets), got)
    short = [seen(0.002, height=0.06)]  # seen shorter than its look: that still counts
    assert p._hidden_base_where_let_go(cost_matrix(short, [sauce], cfg), short)[0, 0] > 0.5


@pytest.mark.sim
@pytest.mark.parametrize("known_container", [None, "basket_1"])
def test_an_object_found_let_go_in_a_segment_named_nothing_is_looked_for_there_again(scene, monkeypatch,
                                                                                    known_container):
    """LIBERO-10 task 0 (development run): the sauce let go into the basket was found standing
    in the basket's segment, but that segment was named nothing (ambiguous); it was then neither
    let go nor inside anything, so no later look searched the basket for it again and it was
    absent from the terminal snapshot (a false failure). Found in an unnamed segment, it stays
    let go; found in a container it is known to be inside, it is inside it."""
    from phyagentos.perception.synthetic import SyntheticObject
    from phyagentos.perception.tracks import Track

    scene.place([SyntheticObject("crate", "box", (0.08, 0.08, 0.07), (0.55, 0.05), rgba=(0.6, 0.58, 0.5, 1))])
    sauce = ObjectDescriptor("tomato_sauce_1", shape="cylinder", colour_rgb=(0.23, 0.12, 0.05), size_m=(0.067, 0.067, 0.091))
    p = Perceiver(PerceptionConfig.default(), [sauce])
    p.tracks["tomato_sauce_1"] = t = Track.start(
        "tomato_sauce_1", _det((0.034, 0.034, 0.046), shape="cylinder", cut=None), 0.9, 0.0, ("front",))
    t.released_s, t.inside_of = 0.5, known_container
    calls = []

    def found(track, cloud, heights, dets, indices, sensors, others=(), *, tracked_top_m=None):
        calls.append(track.name)
        return 0, np.array([0.55, 0.05, 0.1]), 0.8, 120, ("front",), 0.03

    monkeypatch.setattr(perceiver_module, "_released_inside", found)
    ents, _ = _observe(scene, p, stamp_s=1.0)
    assert ents["tomato_sauce_1"]["attributes"]["source"] == "perceived" and calls == ["tomato_sauce_1"]
    if known_container is None:  # the crate is named nothing: look there again next time
        assert t.released_s == 0.5 and t.inside_of is None
        ents, _ = _observe(scene, p, stamp_s=2.0)
        assert calls == ["tomato_sauce_1"] * 2 and ents["tomato_sauce_1"]["attributes"]["source"] == "perceived"
    else:
        assert t.released_s is None and t.inside_of == known_container


def _can(x, y, bottom, height, rgb=(0.18, 0.18, 0.18), *, truncated=False):
    rgb = np.array(rgb)
    return Detection(position=np.array([x, y, 0.43 + bottom + height / 2]), yaw=0.0,
                     half_extents=np.array([0.034, 0.034, height / 2]), shape="cylinder", colour_rgb=rgb,
                     colour_lab=srgb_to_lab(rgb[None])[0], points=300, cameras=1, position_std_m=0.002,
                     yaw_std_rad=np.pi, view_agreement=1.0, bottom_m=bottom,
                     cut_direction=np.array([0.0, 1.0]) if truncated else None)


def _two_cans():
    from phyagentos.perception.tracks import Track

    grey, red = (0.18, 0.18, 0.18), (0.23, 0.13, 0.05)
    soup = ObjectDescriptor("alphabet_soup_1", shape="cylinder", colour_rgb=grey, size_m=(0.0679, 0.0679, 0.0916))
    sauce = ObjectDescriptor("tomato_sauce_1", shape="cylinder", colour_rgb=red, size_m=(0.0676, 0.0674, 0.0914))
    p = Perceiver(PerceptionConfig.default(), [soup, sauce])
    # the soup standing in the basket, its bottom on the basket's floor (7 mm up), seen there
    p.tracks["alphabet_soup_1"] = Track.start("alphabet_soup_1", _can(0.0, 0.26, 0.007, 0.0916), 0.9, 0.0, ("agentview",))
    p.tracks["tomato_sauce_1"] = Track.start("tomato_sauce_1", _can(-0.12, 0.05, 0.0, 0.0914, red), 0.9, 0.0,
                                             ("agentview",))
    return p


def _only_the_first_refused_the_soup(p, dets):
    """``_not_on_itself`` forbids the first of ``dets`` the soup (track 0) and changes nothing
    else; returns the cost matrix before it."""
    raw = cost_matrix(dets, p.declared, p.config)
    got = p._not_on_itself(raw, dets)
    assert got[0, 0] >= perceiver_module.FORBIDDEN_COST and got[0, 1] == raw[0, 1]
    assert np.array_equal(got[1:], raw[1:])
    return raw


def test_a_segment_resting_on_a_tracked_objects_top_is_not_that_object():
    """LIBERO-10 task 0 (generated scenes, seeds 95000-95019): the tomato sauce let go onto the
    alphabet soup standing in the basket shows the wrist camera, straight above, only its lid, grey
    like the soup's look; the upper part split off the stack (resting 12.5 cm up, the soup's top 9.9
    cm up) went to the soup, and the soup was lost at the next look. What rests on an object's top,
    over its footprint, is not that object; lower, beside it, or for an object let go or held since,
    it may be."""
    p = _two_cans()
    lid = _can(0.003, 0.262, 0.125, 0.058)  # on the soup's top
    low = _can(0.003, 0.262, 0.05, 0.05)  # resting half way down the soup: not on its top
    aside = _can(0.09, 0.262, 0.125, 0.058)  # resting on something else 9 cm away
    dets = [lid, low, aside]
    raw = _only_the_first_refused_the_soup(p, dets)
    soup = p.tracks["alphabet_soup_1"]
    for held, released in ((True, None), (False, 3.0)):  # taken or let go since: it may stand anywhere
        soup.held, soup.released_s = held, released
        assert np.array_equal(p._not_on_itself(raw, dets), raw)


def test_a_stack_standing_on_the_table_half_an_object_taller_than_a_tracked_object_is_not_it():
    """LIBERO-10 task 0, the bench's own development episodes (seeds 501 and 504): the soup with the
    sauce standing on it came out as one segment from the table up, 18.4 cm tall where the soup's top
    is 9.9 cm up, and went to the soup as a can whose base the basket's walls hide; the soup's track
    climbed onto the sauce. A sighting's top wanders by millimetres: a little taller, it is the soup;
    cut by the image border (its top unknown) or over an open container (whose contents stand above
    its rim), the rise says nothing."""
    p = _two_cans()
    whole = _can(0.003, 0.262, 0.0, 0.184)  # the stack seen from the table up
    taller = _can(0.003, 0.262, 0.0, 0.099 + 0.02)  # the soup and the basket's floor, 2 cm taller
    cut = _can(0.003, 0.262, 0.0, 0.184, truncated=True)
    dets = [whole, taller, cut]
    raw = _only_the_first_refused_the_soup(p, dets)
    soup = p.tracks["alphabet_soup_1"]
    soup.known_height_m = 0.20  # as tall as the stack when the hand last let it go: nothing is on it
    assert np.array_equal(p._not_on_itself(raw, dets), raw)
    soup.known_height_m = None
    soup.open_depth_m = 0.05  # an open container: what it holds may stand above its rim
    assert np.array_equal(p._not_on_itself(raw, dets), raw)


def test_a_part_at_the_border_is_an_object_the_hand_lets_go_now_only_where_the_hand_let_it_go():
    """LIBERO-10 task 0 (generated scenes): at the look straight down after the sauce's release, a
    sliver of the table's far edge 31 cm away, cut by the wrist camera's border, took the sauce's
    name (0.54: no track to hold it, the sauce still counted in the hand) and the sauce's track
    jumped there; at the next look the can in the basket was too tall for it without its track."""
    from phyagentos.perception.frames import Proprioception

    p = _two_cans()
    sauce = p.tracks["tomato_sauce_1"]
    tcp = np.eye(4)
    tcp[:3, :3] = np.diag([1.0, -1.0, -1.0])
    tcp[:3, 3] = (0.0, 0.26, 0.71)
    sauce.held = True
    sauce.grasp_offset = np.linalg.inv(tcp) @ perceiver_module._pose(np.array([0.0, 0.26, 0.56]), 0.0)
    opened = Proprioception(stamp_s=6.0, joint_names=("j1",), joint_positions=np.zeros(1), joint_velocities=np.zeros(1),
                            joint_efforts=np.zeros(1), gripper_opening_m=0.04, gripper_effort_n=0.0,
                            wrist_force_n=None, wrist_torque_nm=None, tcp_pose=tcp)
    red = (0.23, 0.13, 0.05)
    sliver = _can(0.30, 0.50, 0.0, 0.015, red, truncated=True)
    there = _can(0.005, 0.262, 0.1, 0.08, red, truncated=True)
    dets = [sliver, there]
    raw = cost_matrix(dets, p.declared, p.config)
    assert np.array_equal(p._truncated_where_tracked(raw, dets)[:, 1], raw[:, 1])  # no proprioception: the hand's rules
    got = p._truncated_where_tracked(raw, dets, opened)
    assert got[0, 1] >= perceiver_module.FORBIDDEN_COST and got[1, 1] == raw[1, 1]
    from dataclasses import replace

    still = replace(opened, gripper_opening_m=0.034, gripper_effort_n=19.0)
    assert got[0, 1] != p._truncated_where_tracked(raw, dets, still)[0, 1]  # still held: found by the hand's rules


def test_parts_at_the_border_rivalling_only_for_a_tracked_object_confirm_it_where_it_was():
    """LIBERO-10 task 1 (generated scenes): the arm lifting the butter in front of the basket,
    which reaches the scene camera's border, cut its view in two; each part alone would name
    it, so the two were each other's rivals and the basket went unseen. Pieces of the one
    object tracked there confirm it; without a confident track there they stay unknown."""
    from phyagentos.perception.tracks import Track

    basket = ObjectDescriptor("basket_1", shape="box", colour_rgb=PINK[:3], size_m=(0.16, 0.148, 0.152))
    whole = Detection(**{**_det((0.08, 0.074, 0.076), cut=None).__dict__})
    strip = Detection(**{**_det((0.078, 0.04, 0.076), cut=(0.0, 1.0)).__dict__,
                         "position": whole.position + [0.03, -0.05, 0.0]})
    corner = Detection(**{**_det((0.037, 0.037, 0.076), cut=(0.0, 1.0)).__dict__,
                          "position": whole.position + [-0.065, 0.01, 0.0]})
    parts = [strip, corner]

    def pieces(p, dets):
        C = p._truncated_where_tracked(cost_matrix(dets, [basket], p.config), dets)
        assoc = p._associate_parts_weighed(C, dets)
        return assoc, p._pieces_where_tracked(C, dets, assoc, {})

    p = Perceiver(PerceptionConfig.default(), [basket])
    assoc, _ = pieces(p, parts)
    assert assoc.matches == {} and set(assoc.ambiguous) == {0, 1}  # each other's rivals
    assert pieces(p, parts)[1] == {}  # never seen whole: nothing to confirm
    p.tracks["basket_1"] = Track.start("basket_1", whole, 0.99, 0.0, ("agentview",))
    assert pieces(p, parts)[1] == {"basket_1": [0, 1]}
    # tracked elsewhere (moved since): the parts are not admissible for it and confirm nothing
    p.tracks["basket_1"].position[:2] += 0.4
    assert pieces(p, parts)[1] == {}
    p.tracks["basket_1"].position[:2] -= 0.4
    # in the hand: found by the hand's rules; a whole sighting among the parts names it itself
    p.tracks["basket_1"].held = True
    assert pieces(p, parts)[1] == {}
    p.tracks["basket_1"].held = False
    far_whole = Detection(**{**whole.__dict__, "position": whole.position + [0.0, 0.02, 0.0]})
    assert pieces(p, parts + [far_whole])[1] == {}


@pytest.mark.sim
def test_a_sighting_that_restarts_a_track_inside_a_container_tests_that_container_again(scene, monkeypatch):
    """LIBERO-10 task 0 init 1: the sauce let go onto the soup in the basket was found inside the
    basket from the wrist camera; the scene camera's next sighting, merged with the basket's wall,
    disagreed with its track (a restart), and the restart forgot the basket: the look that judged
    the place had the sauce inside nothing, a false failure where LIBERO counts it in. A restarted
    track keeps the container it was inside for the test the new sighting gets (which a can taken
    out of it fails as before)."""
    from phyagentos.perception.synthetic import SyntheticObject
    from phyagentos.perception.tracks import Track

    scene.place([SyntheticObject("can", "cylinder", (0.034, 0.034, 0.046), (0.55, 0.05),
                                 rgba=(0.23, 0.12, 0.05, 1))])
    sauce = ObjectDescriptor("tomato_sauce_1", shape="cylinder", colour_rgb=(0.23, 0.12, 0.05), size_m=(0.068, 0.068, 0.092))
    p = Perceiver(PerceptionConfig.default(), [sauce])
    # tracked as a box once (one sighting): a cylinder now disagrees with it and restarts it
    p.tracks["tomato_sauce_1"] = t = Track.start("tomato_sauce_1", _det((0.034, 0.03, 0.046), cut=None), 0.9, 0.0,
                                                 ("front",))
    t.position[:2] = (0.55, 0.05)
    t.inside_of = "basket_1"
    tested = []

    def still_inside(container, det, dets, matched, *, height_m=None):
        tested.append(container)
        return container

    monkeypatch.setattr(perceiver_module, "_still_inside", still_inside)
    ents, _ = _observe(scene, p, stamp_s=1.0)
    assert p.tracks["tomato_sauce_1"].shape == "cylinder" and p.tracks["tomato_sauce_1"].observations == 1  # restarted
    assert tested == ["basket_1"] and p.tracks["tomato_sauce_1"].inside_of == "basket_1"
    assert ents["tomato_sauce_1"]["attributes"]["inside_of"] == "basket_1"


def test_a_can_resting_tilted_on_a_tracked_object_off_its_centre_is_not_that_object():
    """LIBERO-10 task 0 (development seed 509): the tomato sauce let go onto the alphabet soup in
    the basket stood tilted on it, the segment of its upper part resting at the basket's rim with
    its centre 3.5 cm off the soup's, beyond the soup's half width; it went ambiguous between the
    soup and the sauce and named nothing. Resting on the soup's top with the footprints
    overlapping, it is not the soup; resting as high 7.5 cm away (no overlap), it may be."""
    p = _two_cans()
    tilted = _can(0.035, 0.26, 0.115, 0.068)  # the soup's top 9.9 cm up, its centre at (0, 0.26)
    clear = _can(0.075, 0.26, 0.115, 0.068)
    raw = _only_the_first_refused_the_soup(p, [tilted, clear])
    assert raw[0, 0] < perceiver_module.FORBIDDEN_COST


@pytest.mark.sim
def test_a_container_cut_by_the_image_border_is_looked_into_where_its_track_puts_it(scene, monkeypatch):
    """LIBERO-10 task 0 (development seed 509): once the arm left, the scene camera saw the basket
    cut by its border, the soup and the sauce standing in it merged with it; the look for the
    sauce inside it took the segment's own footprint, 6.6 cm wide, for the basket's and passed it
    by (narrower than any container), and the sauce was lost. A container matched while cut by
    the border is looked into where its track puts it; what was seen inside it before is looked
    for at the height where it was seen."""
    from phyagentos.perception.synthetic import SyntheticObject
    from phyagentos.perception.tracks import Track

    tan = (0.6, 0.58, 0.5)
    basket = ObjectDescriptor("basket_1", shape="box", colour_rgb=tan, size_m=(0.16, 0.16, 0.14))
    sauce = ObjectDescriptor("tomato_sauce_1", shape="cylinder", colour_rgb=(0.23, 0.12, 0.05), size_m=(0.067, 0.067, 0.091))
    p = Perceiver(PerceptionConfig.default(), [basket, sauce])
    scene.place([SyntheticObject("basket", "box", (0.08, 0.08, 0.07), (0.55, 0.40), rgba=(*tan, 1))])
    ents, snap = _observe(scene, p)
    seen = ents["basket_1"]
    assert seen["attributes"]["source"] == "perceived"
    dets_seen = []

    def found(track, cloud, heights, dets, indices, sensors, others=(), *, tracked_top_m=None):
        dets_seen.append(([d.half_extents.copy() for d in dets], [bool(d.truncated) for d in dets], tracked_top_m))
        return None

    full = np.array([0.08, 0.08, 0.07])
    p.tracks["basket_1"].position[:2] = (0.55, 0.40)
    p.tracks["basket_1"].half_extents = full.copy()
    p.tracks["tomato_sauce_1"] = t = Track.start(
        "tomato_sauce_1", _det((0.034, 0.034, 0.046), shape="cylinder", cut=None), 0.9, 0.0, ("front",))
    t.position[:2] = (0.55, 0.40)
    t.inside_of, t.bottom_m = "basket_1", 0.09
    monkeypatch.setattr(perceiver_module, "_released_inside", found)
    _observe(scene, p, stamp_s=1.0)
    (halves, cut, top), = dets_seen
    assert any(cut), "the basket is not cut by the border here: the test's scene is wrong"
    k = cut.index(True)
    # the track's footprint, not the part seen: the basket's whole, refined by this look's part
    # completed by its look's size (complete_box) to within 2 mm of the whole
    assert np.allclose(halves[k][:2], p.tracks["basket_1"].half_extents[:2])
    assert np.allclose(halves[k][:2], full[:2], atol=0.002)
    assert top == pytest.approx(0.09 + 0.092)  # where it was seen: its bottom plus its height
