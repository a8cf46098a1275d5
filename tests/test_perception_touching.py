"""Objects that touch are told apart (issue 28): a segment larger than every declared object is
split at a height step or around a taller part when the parts match declared looks, and stays
one unknown segment when that is ambiguous.

Scenes: the tabletop Franka with static primitives (:mod:`phyagentos.perception.synthetic`),
built so that the objects touch; rendered with seeded camera noise; clustered as in LIBERO's
scenes (by position: a colour difference counts for little), so only geometry and the
declared looks can separate them. The truth is read by the test only.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.perception import ObjectDescriptor, PerceptionConfig, Perceiver
from phyagentos.perception.synthetic import DEFAULT_CAMERAS, CameraNoise, SyntheticObject, SyntheticScene

pytestmark = pytest.mark.sim

GREY, BROWN, WHITE = (0.25, 0.25, 0.27, 1), (0.45, 0.27, 0.12, 1), (0.85, 0.85, 0.88, 1)

#: LIBERO's clustering (phyagentos.targets.libero.sensing): position first, colour barely counts.
CFG = PerceptionConfig.model_validate({"clustering": {"chromaticity_scale": 2.0, "lightness_scale": 10.0,
                                                      "eps_m": 0.015}})
NO_SPLIT = PerceptionConfig.model_validate({"clustering": {"chromaticity_scale": 2.0, "lightness_scale": 10.0,
                                                           "eps_m": 0.015, "split_max_cost": 0.0}})


@pytest.fixture(scope="module")
def scene():
    s = SyntheticScene([], cameras=DEFAULT_CAMERAS, pool_per_shape=3)
    yield s
    s.close()


def _desc(o: SyntheticObject, **kw):
    return ObjectDescriptor(o.name, shape=o.shape, colour_rgb=o.rgba[:3],
                            size_m=tuple(round(2 * h, 3) for h in o.half_extents), **kw)


def _observe(scene, objects, declared, config=CFG, seed=1):
    scene.place(objects)
    frames = [scene.capture(c, noise=CameraNoise(), rng=np.random.default_rng(seed)) for c in ("front", "side")]
    snap = Perceiver(config, declared).observe(frames, scene.proprioception())
    return {e["name"]: e for e in snap["entities"]}, snap


def _xy_error(e, o):
    return float(np.linalg.norm(np.subtract(e["position"][:2], o.position)))


BOWL = SyntheticObject("bowl_1", "cylinder", (0.055, 0.055, 0.025), (0.50, 0.0), rgba=GREY)


def test_a_tall_object_standing_against_a_flat_one_is_split_around_the_taller_part(scene):
    """A 5 cm 'bowl' against a 1.9 cm 'plate' (its rim over the plate's edge, as a bowl's
    does): one segment before, the plate not perceived; now each named with its own centre."""
    plate = SyntheticObject("plate_1", "cylinder", (0.07, 0.07, 0.0095), (0.50, 0.11), rgba=GREY)
    objects, declared = [BOWL, plate], [_desc(BOWL), _desc(plate)]
    merged, _ = _observe(scene, objects, declared, NO_SPLIT)
    assert "plate_1" not in merged  # unsplit: one segment, named after its top (the bowl); no plate
    ents, snap = _observe(scene, objects, declared)
    for o in objects:
        e = ents[o.name]
        assert e["kind"] == "object" and e["attributes"]["confidence"] > 0.5, e
        assert _xy_error(e, o) < 0.015, (o.name, e["position"], o.position)
        assert abs(2 * e["size"][2] - 2 * o.half_extents[2]) < 0.01, (o.name, e["size"])
    assert snap["unseen"] == []


def test_an_object_resting_on_a_box_is_split_at_the_height_step_and_rests_on_it(scene):
    """A 5 cm cylinder (7 cm across) resting on a 2.1 cm box: one segment before, named after
    its top, no box; now split where the height steps, the upper part resting on the box."""
    box = SyntheticObject("box_1", "box", (0.06, 0.045, 0.0105), (0.52, -0.05), yaw=0.3, rgba=BROWN)
    bowl = SyntheticObject("bowl_1", "cylinder", (0.035, 0.035, 0.025), (0.52, -0.05), rgba=GREY, z_base_m=0.021)
    objects, declared = [box, bowl], [_desc(box), _desc(bowl)]
    merged, _ = _observe(scene, objects, declared, NO_SPLIT)
    assert "box_1" not in merged  # unsplit: one segment, named after its top (the bowl); no box
    ents, snap = _observe(scene, objects, declared)
    e = ents["bowl_1"]
    assert e["kind"] == "object" and _xy_error(e, bowl) < 0.015, e
    assert abs(e["position"][2] - bowl.centre[2]) < 0.01, (e["position"], bowl.centre)
    assert ents["box_1"]["kind"] == "object" and _xy_error(ents["box_1"], box) < 0.02, ents["box_1"]
    assert any(r["subject"] == "bowl_1" and r["relation"] == "on" and r["object"] == "box_1"
               for r in snap["relations"]), snap["relations"]


def test_three_objects_touching_a_bowl_on_a_plate_against_a_ramekin_are_all_named(scene):
    """A bowl set on a plate whose rim touches a ramekin beside it: one segment of three, each
    named at its centre and the bowl on the plate. (In this synthetic scene the plate is named
    without a second cut of the bowl-on-plate part; in LIBERO's world it takes one:
    tests/test_libero_touching.py.)"""
    plate = SyntheticObject("plate_1", "cylinder", (0.08, 0.08, 0.0095), (0.50, 0.02), rgba=WHITE)
    bowl = SyntheticObject("bowl_1", "cylinder", (0.055, 0.055, 0.025), (0.50, 0.02), rgba=GREY, z_base_m=0.019)
    ramekin = SyntheticObject("ramekin_1", "cylinder", (0.045, 0.045, 0.02), (0.50, 0.146), rgba=BROWN)
    objects = [plate, bowl, ramekin]
    ents, snap = _observe(scene, objects, [_desc(o) for o in objects])
    for o in objects:
        e = ents.get(o.name)
        assert e is not None and e["kind"] == "object" and e["attributes"]["confidence"] > 0.5, (o.name, e)
        assert _xy_error(e, o) < 0.015, (o.name, e["position"], o.position)
    assert any(r["subject"] == "bowl_1" and r["relation"] == "on" and r["object"] == "plate_1"
               for r in snap["relations"]), snap["relations"]


def test_two_alike_objects_touching_at_the_same_height_stay_one_unknown_segment(scene):
    """Nothing tells the two apart (same colour, same height: no step, no taller part):
    the merged segment stays unknown and neither object is named."""
    a = SyntheticObject("box_a", "box", (0.03, 0.03, 0.02), (0.50, 0.0), rgba=GREY)
    b = SyntheticObject("box_b", "box", (0.03, 0.03, 0.02), (0.50, 0.06), rgba=GREY)
    ents, snap = _observe(scene, [a, b], [_desc(a), _desc(b)])
    assert "box_a" not in ents and "box_b" not in ents
    assert sorted(snap["unseen"]) == ["box_a", "box_b"]
    assert sum(e["kind"] == "unknown" for e in ents.values()) == 1


def test_a_segment_that_fits_a_declared_object_is_never_split(scene):
    """The bowl alone is not larger than its declared size: one detection, as before."""
    plate = SyntheticObject("plate_1", "cylinder", (0.07, 0.07, 0.0095), (0.50, 0.30), rgba=WHITE)
    ents, snap = _observe(scene, [BOWL, plate], [_desc(BOWL), _desc(plate)])
    assert _xy_error(ents["bowl_1"], BOWL) < 0.01 and _xy_error(ents["plate_1"], plate) < 0.01
    assert not [e for e in ents.values() if e["kind"] == "unknown"]


def test_two_objects_of_different_colours_touching_at_the_same_height_are_split_by_colour(scene):
    """Same height, no step: only the colour tells them apart (CIELAB k-means)."""
    a = SyntheticObject("box_a", "box", (0.03, 0.03, 0.02), (0.50, 0.0), rgba=BROWN)
    b = SyntheticObject("box_b", "box", (0.03, 0.03, 0.02), (0.50, 0.06), rgba=WHITE)
    merged, _ = _observe(scene, [a, b], [_desc(a), _desc(b)], NO_SPLIT)
    assert "box_a" not in merged and "box_b" not in merged
    ents, snap = _observe(scene, [a, b], [_desc(a), _desc(b)])
    for o in (a, b):
        assert ents[o.name]["kind"] == "object" and _xy_error(ents[o.name], o) < 0.01, ents.get(o.name)
    assert snap["unseen"] == []


def _slab(half_x: float, half_y: float, height: float, step: float = 0.003):
    """Points (world m) of a box's top face and sides standing on the plane z = 0, grey."""
    from phyagentos.perception.cloud import Cloud

    xs, ys = np.arange(-half_x, half_x + 1e-9, step), np.arange(-half_y, half_y + 1e-9, step)
    zs = np.arange(step, height, step)
    top = [(x, y, height) for x in xs for y in ys]
    sides = [(x, y, z) for z in zs for x in xs for y in (-half_y, half_y)] + \
            [(x, y, z) for z in zs for y in ys for x in (-half_x, half_x)]
    p = np.array(top + sides, dtype=np.float32)
    n = p.shape[0]
    return Cloud(p, np.full((n, 3), 90, np.uint8), np.full(n, 0.8, np.float32), np.zeros(n, np.int16))


def test_two_admissible_splits_that_cut_differently_leave_the_segment_whole(monkeypatch):
    """A 12 x 12 cm slab declared as two 12 x 6 cm bars: cut along x or along y, both explain
    it equally -- ambiguous, so nothing is split; with only one such cut it is split."""
    from phyagentos.perception import split
    from phyagentos.perception.cloud import Plane

    cloud = _slab(0.06, 0.06, 0.04)
    heights = cloud.points[:, 2].astype(np.float64)
    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 1000, True)
    bars = [ObjectDescriptor(f"bar_{k}", shape="box", colour_rgb=(0.35, 0.35, 0.35), size_m=(0.12, 0.06, 0.04))
            for k in (1, 2)]
    p = cloud.points
    along_x = (p[:, 1] > 0).astype(np.int64)  # two bars lying along x
    along_y = (p[:, 0] > 0).astype(np.int64)  # two bars lying along y
    focal = np.array([400.0])
    monkeypatch.setattr(split, "_partitions", lambda c, h, cfg: iter([("step", 0.01, along_x), ("columns", 0.01, along_y)]))
    assert split.split_cluster(cloud, heights, plane, CFG, focal, bars) is None
    monkeypatch.setattr(split, "_partitions", lambda c, h, cfg: iter([("step", 0.01, along_x)]))
    parts = split.split_cluster(cloud, heights, plane, CFG, focal, bars)
    assert parts is not None and len(parts) == 2
    assert sorted(round(float(d.position[1]), 2) for d, _ in parts) == [-0.03, 0.03]


def test_a_bowl_against_a_ramekin_of_its_height_and_colour_is_cut_at_the_neck_of_their_footprint(scene):
    """Side by side, the same height and grey: no step, no taller part, no colour -- only the
    pinch of the footprint where the two rims touch tells them apart."""
    ramekin = SyntheticObject("ramekin_1", "cylinder", (0.045, 0.045, 0.025), (0.50, 0.101), rgba=GREY)
    objects, declared = [BOWL, ramekin], [_desc(BOWL), _desc(ramekin)]
    merged, _ = _observe(scene, objects, declared, NO_SPLIT)
    assert "bowl_1" not in merged and "ramekin_1" not in merged
    ents, snap = _observe(scene, objects, declared)
    for o in objects:
        assert ents[o.name]["kind"] == "object" and _xy_error(ents[o.name], o) < 0.01, ents.get(o.name)
    assert snap["unseen"] == []


def test_the_footprint_cut_finds_the_contact_of_two_disks_and_no_neck_between_two_boxes():
    from phyagentos.perception.split import footprint_cut

    rng = np.random.default_rng(0)

    def disk(c, r, n):
        a, d = rng.uniform(0, 2 * np.pi, n), r * np.sqrt(rng.uniform(0, 1, n))
        return np.c_[c[0] + d * np.cos(a), c[1] + d * np.sin(a)]

    # an 11 cm bowl and a 9 cm ramekin touching at x = 0.055
    xy = np.r_[disk((0.0, 0.0), 0.055, 4000), disk((0.1, 0.0), 0.045, 2700)]
    ratio, labels = footprint_cut(xy)
    assert ratio < 0.45  # the 5 mm slice at the contact: two chords of about 3.3 cm against 9 cm
    bowl_side = labels[0]
    assert np.mean(labels[:4000] == bowl_side) > 0.98 and np.mean(labels[4000:] != bowl_side) > 0.98
    # two 6 cm boxes face to face: a 12 x 6 cm rectangle, no neck
    boxes = np.c_[rng.uniform(0.0, 0.12, 5000), rng.uniform(0.0, 0.06, 5000)]
    assert footprint_cut(boxes)[0] > CFG.clustering.split_max_neck_ratio


def test_a_mug_with_its_handle_set_on_a_plate_splits_from_the_plate_and_rests_on_it(scene):
    """A mug (a 9 cm body, its handle reaching 2.7 cm past it: its points' rectangle 30 % longer than its fitted
    body, which is how its look was measured) set on a plate: one segment, named after the mug
    and no plate, while a part was judged oversized by its points; as fitted, it splits and the
    mug rests on the plate (LIBERO-10 task 6's white mug, generated scenes)."""
    plate = SyntheticObject("plate_1", "cylinder", (0.07, 0.07, 0.008), (0.50, 0.0), rgba=WHITE)
    body = SyntheticObject("mug_1", "cylinder", (0.045, 0.045, 0.05), (0.50, 0.0), rgba=GREY, z_base_m=0.016)
    handle = SyntheticObject("handle", "box", (0.006, 0.016, 0.03), (0.50, 0.056), rgba=GREY, z_base_m=0.036)
    declared = [_desc(plate), _desc(body)]
    ents, snap = _observe(scene, [plate, body, handle], declared)
    for o in (plate, body):
        e = ents[o.name]
        assert e["kind"] == "object" and e["attributes"]["confidence"] > 0.5, e
        assert _xy_error(e, o) < 0.02, (o.name, e["position"], o.position)
    assert abs(ents["mug_1"]["position"][2] - body.centre[2]) < 0.012, ents["mug_1"]["position"]
    assert any(r["subject"] == "mug_1" and r["relation"] == "on" and r["object"] == "plate_1"
               for r in snap["relations"]), snap["relations"]


def _spherical(centre_z: float, r: float, z_lo: float, z_hi: float, step: float = 0.004):
    """Points (world m) of a sphere of radius ``r`` centred ``centre_z`` above the plane z = 0,
    from ``z_lo`` up to ``z_hi``, grey."""
    from phyagentos.perception.cloud import Cloud

    pts = []
    for z in np.arange(z_lo, z_hi + 1e-9, step):
        ring = math.sqrt(max(r * r - (z - centre_z) ** 2, 0.0))
        n = max(int(2 * math.pi * ring / step), 6)
        pts += [(ring * math.cos(2 * math.pi * k / n), ring * math.sin(2 * math.pi * k / n), z) for k in range(n)]
    p = np.array(pts, dtype=np.float32)
    n = p.shape[0]
    return Cloud(p, np.full((n, 3), 90, np.uint8), np.full(n, 0.8, np.float32), np.zeros(n, np.int16))


def test_a_round_part_resting_on_something_is_a_sphere_only_if_as_tall_as_it_is_wide():
    """A dome 5 cm tall and 10 cm across, raised 6 cm on something, is as tall as a 10 cm ball
    measured from the table and was fitted as one; measured from where it rests (a step's cut)
    it is a cap. A ball resting on a plate 2.5 cm up stays a ball."""
    from phyagentos.perception.cloud import Plane
    from phyagentos.perception.detect import fit_cluster

    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 1000, True)
    focal = np.array([400.0])
    dome = _spherical(0.06, 0.05, 0.06, 0.11)  # the upper half of a sphere, standing on a cut 6 cm up
    h = dome.points[:, 2].astype(np.float64)
    assert fit_cluster(dome, h, plane, CFG, focal).shape == "sphere"  # from the table: as tall as a ball
    det = fit_cluster(dome, h, plane, CFG, focal, rests_at_m=0.06)
    assert det is not None and det.shape != "sphere", det.shape
    ball = _spherical(0.065, 0.04, 0.065 - 0.7 * 0.04, 0.065 + 0.04)
    det = fit_cluster(ball, ball.points[:, 2].astype(np.float64), plane, CFG, focal, rests_at_m=0.025)
    assert det is not None and det.shape == "sphere", det.shape


def test_a_bowl_whose_surface_is_a_sphere_seen_from_within_is_no_ball():
    """A bowl's wall, raised 4.5 cm on a ramekin, is the lower half of a sphere 10 cm across up
    to its rim: as tall as a 10 cm ball from the table, and its points fit one, but its centre
    stands above them, half a radius over their median (a ball seen from above has them round
    or above its centre). Not a sphere, from the table or from the cut; a ball's upper half
    standing on the table is one."""
    from phyagentos.perception.cloud import Plane
    from phyagentos.perception.detect import fit_cluster

    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 1000, True)
    focal = np.array([400.0])
    cap = _spherical(0.095, 0.05, 0.045, 0.095)
    h = cap.points[:, 2].astype(np.float64)
    for rests_at in (None, 0.045):
        det = fit_cluster(cap, h, plane, CFG, focal, rests_at_m=rests_at)
        assert det is not None and det.shape != "sphere", (rests_at, det.shape)
    up = _spherical(0.05, 0.05, 0.05, 0.10)  # a ball's upper half, resting on the table
    det = fit_cluster(up, up.points[:, 2].astype(np.float64), plane, CFG, focal)
    assert det is not None and det.shape == "sphere", det.shape


def _det(xy, half, bottom=0.0, *, covered=False, colour=(0.3, 0.3, 0.3), shape="cylinder"):
    from phyagentos.perception.colour import srgb_to_lab
    from phyagentos.perception.detect import Detection

    half = np.asarray(half, float)
    pos = np.array([xy[0], xy[1], bottom + half[2]])
    rgb = np.asarray(colour, float)
    return Detection(pos, 0.0, half, shape, rgb, srgb_to_lab(np.array([rgb]))[0], 500, 2, 0.002, np.pi, 1.0, bottom,
                     low_m=bottom, covered=covered)


def test_the_upper_part_of_a_step_rests_at_the_cut_and_only_what_it_overhangs_is_covered():
    """A bowl 11 cm across cut at 4.3 cm over a 9 cm ramekin's crescent: the bowl rests at the
    cut, the ramekin is covered. A bottle's 1.8 cm body cut over its own 4 cm base covers nothing
    (narrower than what shows below it); nor does an upper part beside a lower one."""
    from phyagentos.perception.cloud import Plane
    from phyagentos.perception.split import _rested

    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 1000, True)
    bowl, ramekin = _det((0.0, 0.0), (0.056, 0.056, 0.047)), _det((0.0, -0.015), (0.046, 0.031, 0.0215))
    rested = _rested([bowl, ramekin], [True, False], 0.043, plane)
    assert rested[0].bottom_m == pytest.approx(0.043) and rested[0].top_m == pytest.approx(bowl.top_m)
    assert rested[0].position[2] == pytest.approx(0.5 * (0.043 + bowl.top_m))
    assert rested[1].covered and not rested[0].covered
    neck, base = _det((0.0, 0.0), (0.009, 0.009, 0.079)), _det((0.0, 0.0), (0.021, 0.009, 0.0095))
    assert not _rested([neck, base], [True, False], 0.019, plane)[1].covered
    far = _det((0.2, 0.0), (0.056, 0.056, 0.047))
    assert not _rested([far, ramekin], [True, False], 0.043, plane)[1].covered


def test_a_covered_part_counts_its_footprint_as_a_lower_bound_down_to_half_its_look():
    from phyagentos.perception.association import COVERED_MIN_SHOWN, cost_matrix

    ramekin = ObjectDescriptor("ramekin_1", shape="cylinder", colour_rgb=(0.3, 0.3, 0.3), size_m=(0.09, 0.09, 0.043))
    crescent = dict(xy=(0.0, 0.0), half=(0.046, 0.031, 0.0215))
    seen = cost_matrix([_det(**crescent, shape="box")], [ramekin], CFG)[0, 0]
    covered = cost_matrix([_det(**crescent, shape="box", covered=True)], [ramekin], CFG)[0, 0]
    # neither the short side nor the shape count: only the 2 mm its long side shows beyond the look's
    assert covered < seen and covered == pytest.approx(0.002 / 3.0 / CFG.association.size_scale_m, abs=1e-6)
    # less than half of a side showing costs what is missing of that half; the height counts as ever
    sliver = cost_matrix([_det((0.0, 0.0), (0.046, 0.015, 0.0215), covered=True)], [ramekin], CFG)[0, 0]
    missing = (COVERED_MIN_SHOWN * 0.09 - 0.03 + 0.002) / 3.0 / CFG.association.size_scale_m
    assert sliver == pytest.approx(missing, abs=1e-6)
    short = cost_matrix([_det((0.0, 0.0), (0.046, 0.031, 0.01), covered=True)], [ramekin], CFG)[0, 0]
    assert short == pytest.approx((0.043 - 0.02 + 0.002) / 3.0 / CFG.association.size_scale_m, abs=1e-6)


def test_one_object_cut_in_two_that_match_one_look_is_no_stack():
    """A bowl's rim over its narrower body matches the bowl's look twice: no split of it."""
    from phyagentos.perception.association import cost_matrix
    from phyagentos.perception.split import _covered_alike

    bowls = [ObjectDescriptor(f"bowl_{k}", shape="cylinder", colour_rgb=(0.3, 0.3, 0.3), size_m=(0.112, 0.112, 0.05))
             for k in (1, 2)]
    box = ObjectDescriptor("box_1", shape="box", colour_rgb=(0.45, 0.27, 0.12), size_m=(0.085, 0.064, 0.021))
    rim, body = _det((0.0, 0.0), (0.056, 0.056, 0.016), 0.034), _det((0.0, 0.0), (0.04, 0.04, 0.017), covered=True)
    looks = [*bowls, box]
    assert _covered_alike([rim, body], cost_matrix([rim, body], looks, CFG), looks)
    under = _det((0.0, 0.0), (0.042, 0.031, 0.0105), covered=True, colour=(0.45, 0.27, 0.12), shape="box")
    assert not _covered_alike([rim, under], cost_matrix([rim, under], looks, CFG), looks)


def test_what_a_stack_taller_than_one_bowl_covers_is_the_other_look_that_explains_it():
    """A black bowl on a ramekin, the ramekin's side darkened in the bowl's shadow: the covered
    part matches the bowl's look best, but the two stand 10 cm where one bowl stands 5, and the
    ramekin's look explains it within the covered limit: a stack, not one bowl cut in two, the
    part under it scored as the ramekin. The
    same covered part under a bowl's rim at one bowl's height stays one bowl cut in two, and so
    does the taller stack when no other look explains what is under it."""
    from phyagentos.perception.association import cost_matrix
    from phyagentos.perception.split import COVERED_COST_FRACTION, _covered_alike, _part_costs

    bowls = [ObjectDescriptor(f"bowl_{k}", shape="cylinder", colour_rgb=(0.3, 0.3, 0.3), size_m=(0.112, 0.112, 0.05))
             for k in (1, 2)]
    ramekin = ObjectDescriptor("ramekin_1", shape="cylinder", colour_rgb=(0.36, 0.36, 0.36), size_m=(0.09, 0.09, 0.05))
    looks = [*bowls, ramekin]
    bowl_on_top = _det((0.0, 0.0), (0.056, 0.056, 0.025), 0.052)
    shadowed_side = _det((0.0, 0.0), (0.028, 0.028, 0.026), covered=True)
    costs = cost_matrix([bowl_on_top, shadowed_side], looks, CFG)
    limit = COVERED_COST_FRACTION * CFG.clustering.split_max_cost
    assert int(np.argmin(costs[1])) in (0, 1) and costs[1, 2] <= limit  # the bowl's look best, the ramekin's within
    assert _covered_alike([bowl_on_top, shadowed_side], costs, looks)  # without the heights: one bowl cut in two
    assert not _covered_alike([bowl_on_top, shadowed_side], costs, looks, CFG)
    # and what is under it is scored as the ramekin it is taken for, not as the bowl it looks like best
    assert _part_costs([bowl_on_top, shadowed_side], costs, looks, CFG).tolist() == [costs[0].min(), costs[1, 2]]
    # a bowl's rim over its own body: the two stand one bowl's height
    rim = _det((0.0, 0.0), (0.056, 0.056, 0.012), 0.026)
    at_one_height = cost_matrix([rim, shadowed_side], looks, CFG)
    assert _covered_alike([rim, shadowed_side], at_one_height, looks, CFG)
    # nothing but the bowls' look explains what is under it: still no stack
    assert _covered_alike([bowl_on_top, shadowed_side], costs[:, :2], bowls, CFG)


def test_a_stack_is_scored_as_a_stack_where_the_plain_fits_cut_it_ambiguously(monkeypatch):
    """Where the admissible partitions as fitted cut the segment differently at alike costs,
    the steps are scored again as stacks, beside them: a stack that beats them all by the
    ambiguity margin is taken, one that another cut scores alike is not; a covered part is
    taken for another object than the look it matches best only where no stack is admissible
    without that; where the plain fits decide, the stacks are never scored."""
    from phyagentos.perception import split
    from phyagentos.perception.cloud import Plane

    cloud = _slab(0.06, 0.06, 0.1)
    heights = cloud.points[:, 2].astype(np.float64)
    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 1000, True)
    looks = [ObjectDescriptor("bowl_1", shape="cylinder", colour_rgb=(0.3, 0.3, 0.3), size_m=(0.112, 0.112, 0.05))]
    idx = np.arange(len(cloud))
    side_a = [_det((0.0, 0.0), (0.05, 0.05, 0.05)), _det((0.02, 0.026), (0.038, 0.038, 0.025))]
    side_b = [_det((0.0, 0.0), (0.05, 0.05, 0.05)), _det((0.0, -0.03), (0.038, 0.038, 0.03))]
    stack = [_det((0.0, 0.0), (0.056, 0.056, 0.025), 0.05), _det((0.0, 0.0), (0.028, 0.028, 0.025), covered=True)]
    plain = [(2.68, "step", 0.05, side_a, [idx, idx], np.array([1.35, 1.33])),
             (2.97, "step", 0.06, side_b, [idx, idx], np.array([1.5, 1.47]))]
    calls = []

    strict: list = []  # the stacks admissible with nothing covered taken for another object

    def admissible(partitions, *a, stacks, other_under=False, **k):
        calls.append(stacks)
        if not stacks:
            return list(plain)
        return strict if not other_under else [(0.34, "step", 0.05, stack, [idx, idx], np.array([0.14, 0.2]))]

    monkeypatch.setattr(split, "_partitions", lambda c, h, cfg: iter([]))
    monkeypatch.setattr(split, "_admissible", admissible)
    parts = split.split_cluster(cloud, heights, plane, CFG, np.array([400.0]), looks)
    assert calls == [False, True, True] and parts is not None  # no stack strictly: the covered part another object
    assert [d.covered for d, _ in parts] == [False, True]
    calls.clear()
    strict.append((0.4, "step", 0.047, stack, [idx, idx], np.array([0.2, 0.2])))
    parts = split.split_cluster(cloud, heights, plane, CFG, np.array([400.0]), looks)
    assert calls == [False, True] and parts is not None  # a strict stack: the other tier is never scored
    strict.clear()
    calls.clear()
    # two side-by-side cuts, alike as fitted and within the margin of the stack: no cut is taken
    along_x = [_det((0.0, 0.03), (0.056, 0.03, 0.05)), _det((0.0, -0.03), (0.056, 0.03, 0.05))]
    along_y = [_det((0.03, 0.0), (0.03, 0.056, 0.05)), _det((-0.03, 0.0), (0.03, 0.056, 0.05))]
    plain = [(0.5, "columns", 0.05, along_x, [idx, idx], np.array([0.25, 0.25])),
             (0.6, "footprint", 0.0, along_y, [idx, idx], np.array([0.3, 0.3]))]
    assert split.split_cluster(cloud, heights, plane, CFG, np.array([400.0]), looks) is None
    assert calls == [False, True, True]
    calls.clear()
    plain = plain[:1]  # one admissible cut as fitted: taken, no stacks scored
    parts = split.split_cluster(cloud, heights, plane, CFG, np.array([400.0]), looks)
    assert calls == [False] and [round(float(d.position[1]), 2) for d, _ in parts] == [0.03, -0.03]


def test_cuts_of_one_step_that_differ_only_below_it_cut_alike():
    """What shows below a step moves, breaks up and is covered or not as the cut above it
    moves; the parts resting on others decide whether two cuts of a step cut alike."""
    from phyagentos.perception.split import _alike

    bowl = _det((0.0, 0.0), (0.056, 0.056, 0.02), 0.03)
    one = [bowl, _det((0.005, -0.01), (0.03, 0.03, 0.015), covered=True)]
    two = [bowl, _det((0.04, 0.0), (0.017, 0.017, 0.005), covered=True), _det((-0.04, 0.0), (0.017, 0.017, 0.005),
                                                                              covered=True)]
    assert _alike(one, two) and _alike(two, one)
    moved = [_det((0.05, 0.0), (0.056, 0.056, 0.02), 0.03), one[1]]
    assert not _alike(one, moved)  # the part seen whole is elsewhere
    # the plate under it seen whole at one cut, as its near crescent at another
    assert _alike(one, [bowl, _det((0.0, 0.0), (0.069, 0.069, 0.009))])
    below = _det((0.2, 0.0), (0.03, 0.03, 0.015))
    assert not _alike(one, [bowl, below])  # what is below is elsewhere
    assert not _alike(one, [_det((0.0, 0.0), (0.056, 0.056, 0.02)), one[1]])  # no step in the other


def _two_tone_plate_and_box(rng):
    """Points (4 mm grid) of a plate 13.8 cm across (a white well 10 cm across in a red rim) and 8.5
    by 3 cm of a dark box touching its edge (14 % of the points): the tones of LIBERO's plate and
    cream cheese as its cameras see them (L* about 74 / 50 / 28, shading +-10 in each channel)."""
    from phyagentos.perception.cloud import Cloud

    g = np.arange(-0.16, 0.16, 0.004)
    xy = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    r = np.hypot(*xy.T)
    well, rim = r <= 0.05, (r > 0.05) & (r <= 0.069)
    box = (np.abs(xy[:, 0] - 0.069 - 0.0425) <= 0.0425) & (np.abs(xy[:, 1]) <= 0.015)
    keep = well | rim | box
    tone = np.where(well, 0, np.where(rim, 1, 2))[keep]
    rgb = np.array([(185, 182, 176), (140, 110, 104), (60, 66, 92)])[tone] + rng.integers(-10, 11, (int(keep.sum()), 3))
    points = np.column_stack([xy[keep], np.where(tone == 2, 0.918, 0.91)])
    n = len(points)
    cloud = Cloud(points=points, rgb=np.clip(rgb, 0, 255).astype(np.uint8), range_m=np.full(n, 1.0),
                  camera=np.zeros(n, dtype=int))
    return cloud, tone


def test_a_dark_box_against_a_two_tone_plate_is_cut_off_by_colour_and_the_plate_kept_whole():
    """The plate's well and rim lie 17 apart in CIELAB (L* halved), under the 20 a colour cut needs;
    the 2-means' best cut here is the well against the rim and the box (centres 17.9 apart:
    refused), and before the third group the box was never cut off: plate and box stayed one
    unknown segment (libero_goal task 5's dragged plate against the cream cheese, development
    scenes 507, 512 and 514)."""
    from phyagentos.perception.split import _colour_cuts

    cloud, tone = _two_tone_plate_and_box(np.random.default_rng(0))
    cuts = _colour_cuts(cloud)
    box = tone == 2
    agree = [max(np.mean((c == 1) == box), np.mean((c == 0) == box)) for c in cuts]
    assert cuts and max(agree) >= 0.97  # one cut is the box against the plate
    for c in cuts:  # no cut parts the well from the rim
        well, rim = c[tone == 0], c[tone == 1]
        assert round(well.mean()) == round(rim.mean())


@pytest.mark.parametrize("again_costs, cut_again", [((1.34, 1.31), False), ((0.3, 0.2), True)])
def test_a_part_is_cut_again_only_where_its_parts_explain_it_better_than_it_whole(monkeypatch, again_costs, cut_again):
    """LIBERO-10 task 6: a mug let go on a plate is cut from the plate (the mug at 0.84, the plate
    at 0.04); cut again at a height step into parts at 1.34 and 1.31, it came out too short for
    its look and unnamed. A part of a split is split again only where its parts' mean cost is
    below its own (a bowl cut from a plate and a ramekin at 0.3 and 0.2 is)."""
    from phyagentos.perception import split
    from phyagentos.perception.cloud import Plane

    cloud = _slab(0.06, 0.06, 0.12)
    heights = cloud.points[:, 2].astype(np.float64)
    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 1000, True)
    looks = [ObjectDescriptor("mug_1", shape="cylinder", colour_rgb=(0.3, 0.3, 0.3), size_m=(0.096, 0.096, 0.12)),
             ObjectDescriptor("plate_1", shape="cylinder", colour_rgb=(0.3, 0.3, 0.3), size_m=(0.14, 0.14, 0.015))]
    n = len(cloud)
    upper, lower = np.arange(n // 2), np.arange(n // 2, n)
    mug, plate = _det((0.0, 0.0), (0.048, 0.048, 0.05), 0.02), _det((0.0, 0.0), (0.07, 0.07, 0.0075), covered=True)
    high, low = _det((0.0, 0.0), (0.048, 0.048, 0.03), 0.07), _det((0.0, 0.0), (0.048, 0.048, 0.025), 0.02)
    half = np.arange(len(upper) // 2)

    def admissible(partitions, part_cloud, *a, stacks, **k):
        if stacks:
            return []
        if len(part_cloud) == n:  # the segment: the mug cut from the plate
            return [(0.88, "step", 0.02, [mug, plate], [upper, lower], np.array([0.84, 0.04]))]
        if len(part_cloud) == len(upper):  # the mug part, cut again at a step
            return [(sum(again_costs), "step", 0.07, [high, low], [half, np.arange(len(half), len(upper))],
                     np.array(again_costs))]
        return []

    monkeypatch.setattr(split, "oversized", lambda *a, **k: True)
    monkeypatch.setattr(split, "_partitions", lambda c, h, cfg: iter([]))
    monkeypatch.setattr(split, "_admissible", admissible)
    clusters = [(_det((0.0, 0.0), (0.07, 0.07, 0.06)), np.arange(n))]
    out = split.split_clusters(clusters, cloud, heights, plane, CFG, np.array([400.0]), looks)
    assert len(out) == (3 if cut_again else 2)
    assert (out[0][0] is high) == cut_again and (out[0][0] is mug) != cut_again


def test_two_cans_touching_within_a_larger_looks_size_are_still_split_when_no_look_names_them(scene):
    """LIBERO-10 task 7, init 4: the alphabet soup and the tomato sauce stand touching, one
    segment 14.4 by 6.8 cm, 9.2 cm tall; the basket's look (16 by 14.6 by 15 cm) is larger
    in every dimension, so the segment was not oversized, never split, and named by nothing
    (both cans unseen, the pick of one refused). A segment no look names is split when its
    parts explain it better."""
    a = SyntheticObject("soup_1", "cylinder", (0.034, 0.034, 0.046), (0.50, 0.0), rgba=BROWN)
    b = SyntheticObject("sauce_1", "cylinder", (0.034, 0.034, 0.046), (0.50, 0.0685), rgba=WHITE)
    basket = ObjectDescriptor("basket_1", shape="box", colour_rgb=GREY[:3], size_m=(0.16, 0.146, 0.15))
    declared = [_desc(a), _desc(b), basket]
    merged, _ = _observe(scene, [a, b], declared, NO_SPLIT)
    assert "soup_1" not in merged and "sauce_1" not in merged and "basket_1" not in merged
    ents, snap = _observe(scene, [a, b], declared)
    for o in (a, b):
        assert ents[o.name]["kind"] == "object" and _xy_error(ents[o.name], o) < 0.01, ents.get(o.name)
    assert snap["unseen"] == ["basket_1"]


def test_a_flat_box_against_a_tall_carton_is_split_from_the_carton_that_names_their_segment(scene, monkeypatch):
    """LIBERO-10 task 1 (development seed 500): the orange juice carton, fallen from where the
    scene put it, stands against the cream cheese box. Their one segment (14.1 by 7.2 cm of
    points) is fitted by the carton's top and named as the carton; within the basket's look it
    is not larger than every look, so it was never split and the box went unseen (its pick
    refused). A segment larger than every look that names it is split as an oversized one."""
    from phyagentos.perception import split

    carton = SyntheticObject("carton_1", "box", (0.028, 0.0235, 0.074), (0.50, -0.05), rgba=(0.9, 0.5, 0.1, 1))
    box = SyntheticObject("cheese_1", "box", (0.042, 0.022, 0.0155), (0.50, -0.004), rgba=(0.25, 0.27, 0.42, 1))
    basket = ObjectDescriptor("basket_1", shape="box", colour_rgb=GREY[:3], size_m=(0.174, 0.162, 0.152))
    declared = [_desc(carton), _desc(box), basket]
    with monkeypatch.context() as m:  # the rule before: only a segment larger than every look, or named by none
        m.setattr(split, "outgrows_names", lambda *a, **k: False)
        before, _ = _observe(scene, [carton, box], declared)
    assert "carton_1" in before and "cheese_1" not in before
    ents, snap = _observe(scene, [carton, box], declared)
    for o in (carton, box):
        e = ents[o.name]
        assert e["kind"] == "object" and e["attributes"]["confidence"] > 0.5, e
        assert _xy_error(e, o) < 0.01, (o.name, e["position"], o.position)
    assert snap["unseen"] == ["basket_1"]


def test_the_parts_of_one_body_that_overlap_where_they_stand_are_no_two_objects():
    """What the split of a segment outgrowing its names keeps: parts on one level stand apart
    (LIBERO-10 task 7, development seed 518: a ketchup bottle with a strip of low points at its
    foot, cut by colour into two bottles 8 mm apart, is one body); a box beside a carton and a
    bowl resting on a box are two objects."""
    from phyagentos.perception.cloud import Plane
    from phyagentos.perception.split import stand_apart

    plane = Plane(np.array([0.0, 0.0, 1.0]), 0.0, 0, False)
    label = _det((0.0, 0.0), (0.019, 0.019, 0.06))
    bottle = _det((0.008, 0.0), (0.018, 0.018, 0.079))
    assert not stand_apart([label, bottle], plane, CFG)
    carton = _det((0.0, -0.05), (0.028, 0.0235, 0.074), shape="box")
    cheese = _det((0.0, -0.004), (0.042, 0.022, 0.0155), shape="box")
    assert stand_apart([carton, cheese], plane, CFG)
    base = _det((0.0, 0.0), (0.05, 0.03, 0.0105), shape="box")
    bowl = _det((0.005, 0.0), (0.035, 0.035, 0.025), bottom=0.021)
    assert stand_apart([base, bowl], plane, CFG)


def test_only_a_segment_with_enough_points_beyond_its_fitted_top_is_split_for_outgrowing_its_names():
    """The points beyond the footprint a segment was fitted to are counted past a 1 cm margin: a
    carton's own face points are not, the box beside it is (LIBERO-10 task 1, 24-32 % of the
    segment), a bottle's few stray foot points (5-11 %) are under the 15 % that a split asks."""
    from phyagentos.perception.split import BEYOND_FIT_FRACTION, beyond_fit

    carton = _det((0.0, 0.0), (0.028, 0.0235, 0.074), shape="box")
    rng = np.random.default_rng(3)
    own = np.column_stack([rng.uniform(-0.037, 0.037, 600), rng.uniform(-0.033, 0.033, 600), rng.uniform(0, 0.148, 600)])
    box = np.column_stack([rng.uniform(-0.042, 0.042, 300), rng.uniform(0.045, 0.09, 300), rng.uniform(0, 0.031, 300)])
    foot = np.column_stack([rng.uniform(0.04, 0.05, 40), rng.uniform(-0.01, 0.01, 40), rng.uniform(0, 0.02, 40)])
    assert beyond_fit(own, carton) == 0
    assert beyond_fit(np.vstack([own, box]), carton) == 300 >= BEYOND_FIT_FRACTION * 900
    assert beyond_fit(np.vstack([own, foot]), carton) == 40 < BEYOND_FIT_FRACTION * 640
