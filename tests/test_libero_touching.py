"""Objects that touch in LIBERO's libero_spatial world, told apart (issue 28): generated scenes
(:func:`~phyagentos.targets.libero.descriptors.place_objects`, then
:func:`~phyagentos.targets.libero.descriptors.set_touching`: never an init state) where a black
bowl rests on the cookie box or on the ramekin (seeds from bench/libero_touching.py); the perceiver is given the objects in
view by name, category and look; the truth is read here, by the test, only."""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.targets.libero import LiberoScene, LiberoTarget
from phyagentos.targets.libero.descriptors import _observe, object_boxes, place_objects, set_touching

pytestmark = pytest.mark.sim

BOWL = "akita_black_bowl_1"
#: The categories' looks as measured on generated cluttered scenes (measure_descriptors, seeds
#: from 12345, libero_spatial task 0; the bench's cached looks), as a user would declare them.
LOOKS = {
    "akita_black_bowl": {"colour": [0.49, 0.506, 0.498], "shape": "cylinder", "size_m": [0.1124, 0.1124, 0.0504]},
    "cookies": {"colour": [0.424, 0.255, 0.129], "shape": "box", "size_m": [0.085, 0.0644, 0.0208]},
    "glazed_rim_porcelain_ramekin": {"colour": [0.6, 0.6, 0.62], "shape": "cylinder",
                                     "size_m": [0.0904, 0.0904, 0.0426]},
    "plate": {"colour": [0.62, 0.463, 0.435], "shape": "cylinder", "size_m": [0.1384, 0.1384, 0.0186]},
}


@pytest.fixture(scope="module")
def world():
    t = LiberoTarget("libero", LiberoScene(suite="libero_spatial", task=0), seed=0)
    yield t, t.perception_config()  # at the reset (its support prior: the table under the objects)
    t.close()


def _touching(world, landmark: str, how: str, seed: int, config=None):
    """Only the bowl and the landmark in view (the twin bowl would make any bowl ambiguous)."""
    target, cfg = world
    placed = place_objects(target, seed, names=[BOWL, landmark])
    assert set(placed) == {BOWL, landmark}
    assert set_touching(target, BOWL, landmark, how, seed)
    cats = target._problem.objects
    declared = [{"name": n, "class": cats[n], **LOOKS[cats[n]]} for n in (BOWL, landmark)]
    snap = _observe(target, config or cfg, declared)
    return {e["name"]: e for e in snap["entities"]}, snap, object_boxes(target)


def _centre_error(e, box) -> float:
    lo, hi = box
    return float(np.linalg.norm(np.asarray(e["position"][:2]) - 0.5 * (lo + hi)[:2]))


def _no_split(world):
    cfg = world[1]
    return cfg.model_validate({**cfg.model_dump(), "clustering": {**cfg.clustering.model_dump(), "split_max_cost": 0.0}})


def test_a_bowl_resting_on_the_cookie_box_is_split_at_the_height_step_and_rests_on_it(world):
    _on(world, "cookies_1", 60001)


def test_a_bowl_resting_on_the_ramekin_is_split_from_it_and_rests_on_it(world):
    _on(world, "glazed_rim_porcelain_ramekin_1", 60002)


def _on(world, landmark: str, seed: int):
    """Unsplit (``split_max_cost`` 0: the old behaviour), bowl and landmark are one segment,
    named after its top, the landmark not perceived; split, both are named at their centres
    and the bowl rests on the landmark."""
    before, _, _ = _touching(world, landmark, "on", seed, _no_split(world))
    assert landmark not in before or before[landmark]["kind"] != "object"
    ents, snap, boxes = _touching(world, landmark, "on", seed)
    for name in (BOWL, landmark):
        e = ents[name]
        assert e["kind"] == "object", e
        assert _centre_error(e, boxes[name]) < 0.015, (name, e["position"], boxes[name])
    assert any(r["subject"] == BOWL and r["relation"] == "on" and r["object"] == landmark
               for r in snap["relations"]), snap["relations"]


def test_a_bowl_rim_to_rim_with_the_ramekin_is_cut_at_the_neck_of_their_footprint(world, monkeypatch):
    """Beside it, one height and both grey: unsplit by any height or colour, the footprint's
    neck cut names both at their centres; with neither the neck cut (``split_max_neck_ratio``
    0) nor the disc cut (the behaviour before both), neither is named. The seed is the bench's
    first ``beside`` scene of the ramekin."""
    import phyagentos.perception.split as split

    off = world[1].model_validate({**world[1].model_dump(), "clustering": {
        **world[1].clustering.model_dump(), "split_max_neck_ratio": 0.0}})
    names = (BOWL, "glazed_rim_porcelain_ramekin_1")
    with monkeypatch.context() as mp:
        mp.setattr(split, "_disc_partitions", lambda *a, **k: iter(()))
        before, _, _ = _touching(world, names[1], "beside", 60000, off)
        assert BOWL not in before and names[1] not in before
        ents, _, boxes = _touching(world, names[1], "beside", 60000)
        for name in names:
            assert ents[name]["kind"] == "object", ents.get(name)
            assert _centre_error(ents[name], boxes[name]) < 0.015, (name, ents[name]["position"], boxes[name])


def test_a_bowl_rim_to_rim_with_the_ramekin_is_cut_by_its_disc_where_no_neck_cut_is_taken(world):
    """The same scene with the neck cut off: the bowl's disc, found on the footprint's edge,
    cuts it from the ramekin, both named within 1.5 cm of their centres (1.3 mm when measured)."""
    off = world[1].model_validate({**world[1].model_dump(), "clustering": {
        **world[1].clustering.model_dump(), "split_max_neck_ratio": 0.0}})
    ents, _, boxes = _touching(world, "glazed_rim_porcelain_ramekin_1", "beside", 60000, off)
    for name in (BOWL, "glazed_rim_porcelain_ramekin_1"):
        assert ents[name]["kind"] == "object", ents.get(name)
        assert _centre_error(ents[name], boxes[name]) < 0.015, (name, ents[name]["position"], boxes[name])


def test_generated_scenes_set_no_object_down_on_a_fixture(world):
    """The look generator's scenes keep every object off the cabinet and the stove: an object
    set down in a fixture is segmented with it, and its look is then the fixture's (libero_goal's
    bowl measured as an 11 x 9 cm grey box before)."""
    from phyagentos.targets.libero.descriptors import fixture_boxes

    target, _ = world
    fixtures = list(fixture_boxes(target).values())
    assert len(fixtures) >= 2  # libero_spatial's wooden cabinet and flat stove
    for seed in range(12345, 12351):
        for name in place_objects(target, seed):
            lo, hi = object_boxes(target)[name]
            for flo, fhi in fixtures:
                overlap = np.minimum(hi[:2], fhi[:2]) - np.maximum(lo[:2], flo[:2])
                assert np.any(overlap <= 0.0), (seed, name, lo, hi, flo, fhi)


def test_a_bowl_set_on_the_plate_beside_the_other_bowl_leaves_the_plate_named(world):
    """Three touching: the other bowl rim to rim with the plate, the bowl set on the plate. The
    segment is cut in two at the footprint's neck, then the bowl-on-plate part again at its
    height step; before, that part was named after its top and the plate was not seen (the
    place of libero_spatial task 2 could not be judged on the development split)."""
    target, cfg = world
    twin, plate = "akita_black_bowl_2", "plate_1"
    assert set(place_objects(target, 60022, names=[BOWL, twin, plate])) == {BOWL, twin, plate}
    assert set_touching(target, twin, plate, "beside", 60022)
    assert set_touching(target, BOWL, plate, "on", 60022)
    cats = target._problem.objects
    declared = [{"name": n, "class": cats[n], **LOOKS[cats[n]]} for n in (BOWL, plate)]
    ents = {e["name"]: e for e in _observe(target, cfg, declared)["entities"]}
    boxes = object_boxes(target)
    e = ents.get(plate)
    assert e is not None and e["kind"] == "object" and e["attributes"]["confidence"] > 0.5, e
    assert _centre_error(e, boxes[plate]) < 0.015, (e["position"], boxes[plate])


def _lean_on_the_box(target, seed: int, over_m: float = 0.012) -> float:
    """The plate set with its rim ``over_m`` over the cookie box's edge (a random side, seeded),
    1 cm above the box's top, settled 1.5 s: it comes to rest with its rim on the box, tilted, as
    LIBERO-PRO's ``libero_spatial_swap`` task 1 sets it. Returns the plate's tilt, degrees (a
    scene generator: the true boxes are read here, by the test)."""
    import mujoco

    from phyagentos.targets.libero.descriptors import _free_adr

    rng = np.random.default_rng(seed)
    lo, hi = object_boxes(target)["cookies_1"]
    u = np.array([math.cos(a := rng.uniform(0.0, 2.0 * math.pi)), math.sin(a)])
    half = 0.5 * (hi - lo)[:2]
    edge = min(half[0] / max(abs(u[0]), 1e-9), half[1] / max(abs(u[1]), 1e-9))
    m, d = target.model, target.data
    qa, _ = _free_adr(m, target._obj_body["plate_1"])
    xy = 0.5 * (lo + hi)[:2] + u * (edge + 0.5 * LOOKS["plate"]["size_m"][0] - over_m)
    d.qpos[qa:qa + 7] = [xy[0], xy[1], float(hi[2]) + 0.01, 1.0, 0.0, 0.0, 0.0]
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=1.5)
    q = d.xquat[target._obj_body["plate_1"]]
    return math.degrees(2.0 * math.acos(min(1.0, math.hypot(q[0], q[3]))))


def test_a_plate_resting_tilted_on_the_cookie_box_is_named_with_it(world):
    """Its rim on the box, the plate lies about 3.4 degrees tilted: the band within 6 mm of its
    top is its raised side, a crescent. Its top taken from its own slope (and cut from the box by
    its disc), both are named where they are (bench/libero_touching's seeds; seed 60007 of ten,
    3 of the 6 tilted named; before both changes the plate was unknown at 0.02 and the box unseen
    here). The mechanism without the slope is pinned on synthetic points
    (``tests/test_perception_plate_touching.py``): here the settled tilt, and with it the
    sighting without the slope (0.43 or 0.62), depends on what the world simulated before."""
    target, cfg = world
    names = ["plate_1", "cookies_1"]
    cats = target._problem.objects
    declared = [{"name": n, "class": cats[n], **LOOKS[cats[n]]} for n in names]

    def observe():
        assert set(place_objects(target, 60007, names=names)) == set(names)
        tilt = _lean_on_the_box(target, 60007)
        return tilt, {e["name"]: e for e in _observe(target, cfg, declared)["entities"]}, object_boxes(target)

    tilt, ents, boxes = observe()
    assert tilt > 2.5, tilt
    for name in names:
        e = ents.get(name)
        assert e is not None and e["kind"] == "object" and e["attributes"]["confidence"] >= 0.5, (name, e)
        assert _centre_error(e, boxes[name]) < 0.01, (name, e["position"], boxes[name])
