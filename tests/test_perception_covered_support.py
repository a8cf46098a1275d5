"""A support seen only round what now rests on it stays where it was seen whole.

LIBERO-10 task 4: the white mug let go on the left plate hides most of it; the plate's part
showing round the mug was split off under it (``Detection.covered``), its centre 3.5 cm off the
plate's, and the plate's track moved there: the mug, resting 0.9 cm from the plate's centre by
LIBERO's ground truth, was then judged 3.3 cm off it. A covered sighting whose points all lie
within where the object was seen whole confirms it there and never moves it
(``Perceiver._covered_within_track``); one reaching outside it is fused as any sighting.

The scene is the tabletop Franka with a static plate (:mod:`phyagentos.perception.synthetic`);
the second look's detection of the plate is replaced by the covered crescent a mug on it would
leave, so only the perceiver's handling of it is under test.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from phyagentos.perception import ObjectDescriptor, PerceptionConfig, Perceiver
from phyagentos.perception import perceiver as perceiver_module
from phyagentos.perception.synthetic import DEFAULT_CAMERAS, CameraNoise, SyntheticObject, SyntheticScene

pytestmark = pytest.mark.sim

CFG = PerceptionConfig.model_validate({"clustering": {"chromaticity_scale": 2.0, "lightness_scale": 10.0,
                                                      "eps_m": 0.015}})
PLATE = SyntheticObject("plate_1", "cylinder", (0.07, 0.07, 0.0075), (0.50, 0.10), rgba=(0.85, 0.85, 0.88, 1))


@pytest.fixture(scope="module")
def scene():
    s = SyntheticScene([PLATE], cameras=DEFAULT_CAMERAS, pool_per_shape=1)
    yield s
    s.close()


def _look(scene, perceiver, seed):
    frames = [scene.capture(c, noise=CameraNoise(), rng=np.random.default_rng(seed)) for c in ("front", "side")]
    snap = perceiver.observe(frames, scene.proprioception())
    return {e["name"]: e for e in snap["entities"]}


def _second_look(scene, monkeypatch, *, kept_rule: bool, side_m: float) -> np.ndarray:
    """The plate's perceived centre (2,) world m after a first look at it whole and a second
    whose detection of it is the covered part beyond ``side_m`` of its centre along world y,
    fitted there (centre and radius of what shows); ``kept_rule`` False: the perceiver's rule
    for it switched off."""
    declared = [ObjectDescriptor("plate_1", shape="cylinder", colour_rgb=PLATE.rgba[:3], size_m=(0.14, 0.14, 0.015))]
    perceiver = Perceiver(CFG, declared)
    first = _look(scene, perceiver, seed=1)["plate_1"]
    assert first["kind"] == "object" and np.linalg.norm(np.subtract(first["position"][:2], PLATE.position)) < 0.005
    split = perceiver_module.split_clusters

    def crescent(clusters, cloud, *args, **kwargs):
        out = []
        for det, idx in split(clusters, cloud, *args, **kwargs):
            part = idx[cloud.points[idx, 1] > PLATE.position[1] + side_m]
            xy = cloud.points[part, :2]
            centre = np.array([*xy.mean(axis=0), det.position[2]])
            half = np.array([0.5 * float(np.ptp(xy[:, 1])), 0.5 * float(np.ptp(xy[:, 1])), det.half_extents[2]])
            out.append((replace(det, position=centre, half_extents=half, covered=True), part))
        return out

    monkeypatch.setattr(perceiver_module, "split_clusters", crescent)
    if not kept_rule:
        monkeypatch.setattr(Perceiver, "_covered_within_track", staticmethod(lambda t, xy: False))
    second = _look(scene, perceiver, seed=2)["plate_1"]
    monkeypatch.undo()
    return np.asarray(second["position"][:2])


def test_a_plate_seen_only_round_what_rests_on_it_is_kept_where_it_was_seen_whole(scene, monkeypatch):
    kept = _second_look(scene, monkeypatch, kept_rule=True, side_m=-0.02)
    assert np.linalg.norm(kept - PLATE.position) < 0.005, kept
    # fused as any sighting, the crescent pulls the plate towards what shows of it
    moved = _second_look(scene, monkeypatch, kept_rule=False, side_m=-0.02)
    assert np.linalg.norm(moved - PLATE.position) > 0.01, moved


def _moved_and_covered(scene, monkeypatch, moved: SyntheticObject):
    """``(perceiver, entities by name)`` after a first look at the plate whole and a second at it
    moved to ``moved``, every detection there reported covered (a support's part showing round
    what rests on it)."""
    scene.place([PLATE])
    declared = [ObjectDescriptor("plate_1", shape="cylinder", colour_rgb=PLATE.rgba[:3], size_m=(0.14, 0.14, 0.015))]
    perceiver = Perceiver(CFG, declared)
    _look(scene, perceiver, seed=1)
    scene.place([moved])
    split = perceiver_module.split_clusters

    def covered(clusters, cloud, *args, **kwargs):
        return [(replace(det, covered=True), idx) for det, idx in split(clusters, cloud, *args, **kwargs)]

    monkeypatch.setattr(perceiver_module, "split_clusters", covered)
    try:
        return perceiver, _look(scene, perceiver, seed=2)
    finally:
        monkeypatch.undo()
        scene.place([PLATE])


def test_a_covered_part_reaching_outside_where_it_was_seen_is_fused_as_any_sighting(scene, monkeypatch):
    # the plate's part beyond its centre, shifted 4 cm on: it reaches past the track's footprint
    shifted = SyntheticObject("plate_1", "cylinder", PLATE.half_extents, (0.50, 0.14), rgba=PLATE.rgba)
    _, seen = _moved_and_covered(scene, monkeypatch, shifted)
    assert np.linalg.norm(np.subtract(seen["plate_1"]["position"][:2], shifted.position)) < 0.01, seen["plate_1"]


def test_a_covered_part_nowhere_near_where_the_object_was_seen_names_nothing(scene, monkeypatch):
    """LIBERO-10 task 4 init 3: the left plate hidden behind the held mug, the base of a red mug
    39 cm away, split off as a support under it (covered), was named the plate at 0.16; the
    plate's track restarted there and the mug was let go on the bare table. A covered sighting
    with no point within the confident track's footprint, outside its gate, is left unknown
    (``Perceiver._covered_elsewhere``); the track stays where it was seen."""
    far = SyntheticObject("plate_1", "cylinder", PLATE.half_extents, (0.50, -0.20), rgba=PLATE.rgba)
    perceiver, seen = _moved_and_covered(scene, monkeypatch, far)
    assert "plate_1" not in seen or seen["plate_1"]["attributes"]["source"] == "remembered"
    assert np.linalg.norm(perceiver.tracks["plate_1"].position[:2] - PLATE.position) < 0.005
    unknown = [e for e in seen.values() if e["kind"] == "unknown"]
    assert any(np.linalg.norm(np.subtract(e["position"][:2], far.position)) < 0.01 for e in unknown), seen


PLATE_RIGHT = SyntheticObject("plate_2", "cylinder", (0.07, 0.07, 0.0075), (0.50, 0.12), rgba=PLATE.rgba)
PLATE_LEFT = SyntheticObject("plate_1", "cylinder", (0.07, 0.07, 0.0075), (0.50, -0.16), rgba=PLATE.rgba)


@pytest.fixture(scope="module")
def two_plates():
    s = SyntheticScene([PLATE_RIGHT, PLATE_LEFT], cameras=DEFAULT_CAMERAS, pool_per_shape=2)
    yield s
    s.close()


@pytest.mark.parametrize("rule", [True, False])
def test_a_covered_part_is_no_rival_for_a_look_alike_tracked_elsewhere(two_plates, monkeypatch, rule):
    """LIBERO-10 task 4 (development seed 502): the yellow and white mug let go on the right
    plate, the plate's rim split off under it (covered) was matched to the right plate and, at
    a track cost capped at 1, to the left plate 62 cm away: within the ambiguity margin, so
    neither was named and the mug's place was judged on the right plate as remembered. A
    covered sighting is weighed only against the objects that may stand there
    (``Perceiver._covered_where_tracked``): the right plate is seen there, kept where it was."""
    look = dict(shape="cylinder", colour_rgb=PLATE.rgba[:3], size_m=(0.14, 0.14, 0.015))
    declared = [ObjectDescriptor("plate_1", **look, where={"relation": "left"}),
                ObjectDescriptor("plate_2", **look, where={"relation": "right"})]
    perceiver = Perceiver(CFG, declared)
    two_plates.place([PLATE_RIGHT, PLATE_LEFT])
    try:
        first = _look(two_plates, perceiver, seed=1)
        for plate in (PLATE_RIGHT, PLATE_LEFT):
            assert np.linalg.norm(np.subtract(first[plate.name]["position"][:2], plate.position)) < 0.005, first
        two_plates.place([PLATE_RIGHT])  # the left plate out of view: remembered, tracked where it was
        split = perceiver_module.split_clusters

        def crescent(clusters, cloud, *args, **kwargs):  # the half of the right plate beyond its centre
            out = []
            for det, idx in split(clusters, cloud, *args, **kwargs):
                part = idx[cloud.points[idx, 1] > PLATE_RIGHT.position[1]]
                xy = cloud.points[part, :2]
                half = 0.5 * float(np.ptp(xy[:, 1]))
                out.append((replace(det, position=np.array([*xy.mean(axis=0), det.position[2]]),
                                    half_extents=np.array([half, half, det.half_extents[2]]), covered=True), part))
            return out

        monkeypatch.setattr(perceiver_module, "split_clusters", crescent)
        if not rule:
            monkeypatch.setattr(Perceiver, "_covered_where_tracked", lambda self, C, *args: C)
        second = _look(two_plates, perceiver, seed=2)
    finally:
        monkeypatch.undo()
        two_plates.place([PLATE_RIGHT, PLATE_LEFT])
    if rule:
        seen = second["plate_2"]
        assert seen["attributes"]["source"] == "perceived", seen
        assert np.linalg.norm(np.subtract(seen["position"][:2], PLATE_RIGHT.position)) < 0.005, seen
        assert "plate_1" not in second or second["plate_1"]["attributes"]["source"] == "remembered"
    else:  # the rivalry leaves the crescent unknown and the right plate unseen
        assert "plate_2" not in second or second["plate_2"]["attributes"]["source"] == "remembered", second
        assert any(e["kind"] == "unknown" for e in second.values()), second
