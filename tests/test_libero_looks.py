"""A LIBERO look from its sightings (``looks_from_samples``): pooled over worlds, with how it
varies with the view; no simulator needed."""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.perception import ObjectDescriptor
from phyagentos.targets.libero.descriptors import SIZE_PERCENTILES, looks_from_samples


def _seen(shape: str, size, colour=(0.4, 0.15, 0.1)) -> dict:
    return {"shape": shape, "colour": list(colour), "size_m": list(size)}


def test_a_looks_shape_fractions_and_size_range_pool_every_worlds_sightings():
    # world A sees the carton face-on (3 cm deep) and always as a box; world B at an angle, its
    # gable top read as a cylinder twice in five
    world_a = [_seen("box", (0.055, 0.030 + 0.001 * k, 0.135)) for k in range(5)]
    world_b = [_seen("cylinder" if k < 2 else "box", (0.055, 0.050 + 0.001 * k, 0.134)) for k in range(5)]
    looks = looks_from_samples({"milk": world_a + world_b})
    milk = looks["milk"]
    assert milk["shapes"] == {"box": 0.8, "cylinder": 0.2} and milk["shape"] == "box"
    lo, hi = milk["size_range_m"]
    assert lo[1] < 0.032 and hi[1] > 0.052  # both views' depths are in the range
    assert lo[1] <= milk["size_m"][1] <= hi[1]
    assert ObjectDescriptor.from_dict({"name": "milk_1", **milk}).size_range_m is not None  # a valid look


def test_a_sighting_cut_short_by_a_neighbour_does_not_widen_the_range():
    whole = [_seen("cylinder", (0.068, 0.068, 0.080)) for _ in range(9)]
    cut = [_seen("cylinder", (0.024, 0.024, 0.039))]  # a can seen 4 cm tall of its 8
    lo, hi = looks_from_samples({"alphabet_soup": whole + cut})["alphabet_soup"]["size_range_m"]
    assert np.allclose(lo, [0.068, 0.068, 0.080]) and np.allclose(hi, lo)
    assert SIZE_PERCENTILES == (10.0, 90.0)


def test_a_category_sighted_once_has_no_look_and_a_split_shape_vote_declares_none():
    looks = looks_from_samples({"plate": [_seen("cylinder", (0.2, 0.2, 0.02))],
                                "caddy": [_seen(s, (0.2, 0.1, 0.08)) for s in ("box", "cylinder") * 3]})
    assert "plate" not in looks
    assert "shape" not in looks["caddy"] and looks["caddy"]["shapes"] == {"box": 0.5, "cylinder": 0.5}


def test_each_world_is_sighted_once_per_workspace_and_shared_by_its_perturbed_suites(tmp_path, monkeypatch):
    """The bench pools each category's sightings over the run's worlds; a world (its scene,
    objects and fixtures) is measured once and LIBERO-PRO's swapped suite reuses it."""
    import phyagentos.targets.libero as libero
    import phyagentos.targets.libero.descriptors as descriptors
    from phyagentos.bench.libero import _descriptors

    built: list[tuple[str, int]] = []

    class World:
        def __init__(self, name, scene, seed):
            built.append((scene.suite, scene.task))
            self.cats = libero.parse_bddl(libero.resolve_task(scene.suite, scene.task).bddl_path).objects

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    def sightings(target):
        return {c: [_seen("box", (0.05, 0.03 + 0.002 * k, 0.1)) for k in range(4)] for c in set(target.cats.values())}

    monkeypatch.setattr(libero, "LiberoTarget", World)
    monkeypatch.setattr(descriptors, "descriptor_samples", sightings)
    # measured here, not taken from the shipped looks (tests/test_shipped_looks.py)
    looks = _descriptors(tmp_path, "libero_object", [0, 1], measure=True)
    assert built == [("libero_object", 0), ("libero_object", 1)] and "milk" in looks
    _descriptors(tmp_path, "libero_object", [0, 1, 2], measure=True)
    assert built[2:] == [("libero_object", 2)]  # only the new world
    swapped = _descriptors(tmp_path, "libero_object_swap", [0, 2], measure=True)
    assert len(built) == 3 and set(swapped) <= set(looks) | set(_descriptors(tmp_path, "libero_object", [2]))


def test_the_bench_builds_each_world_once_for_its_descriptors_and_its_fixture_looks(tmp_path, monkeypatch):
    """A suite's preparation measures a task's object sightings and fixture looks on one
    LiberoTarget (closed before the next world is built, and at the end); a second preparation
    in the same workspace builds none."""
    import phyagentos.targets.libero as libero
    import phyagentos.targets.libero.descriptors as descriptors
    from phyagentos.bench.libero import prepare_libero_suite

    events: list[tuple[str, int, str]] = []

    class World:
        def __init__(self, name, scene, seed):
            self.key = (scene.suite, scene.task)
            self.cats = libero.parse_bddl(libero.resolve_task(scene.suite, scene.task).bddl_path).objects
            events.append((*self.key, "built"))

        def close(self):
            events.append((*self.key, "closed"))

    def sightings(target):
        events.append((*target.key, "descriptors"))
        return {c: [_seen("box", (0.05, 0.03 + 0.002 * k, 0.1)) for k in range(4)] for c in set(target.cats.values())}

    def fixture_looks(target):
        events.append((*target.key, "fixture looks"))
        return {}

    monkeypatch.setattr(libero, "LiberoTarget", World)
    monkeypatch.setattr(descriptors, "descriptor_samples", sightings)
    monkeypatch.setattr(descriptors, "measure_fixture_looks", fixture_looks)
    prepare_libero_suite("libero_object", tmp_path / "ws", tasks=("0", "1"), seeds=(0,), measure_looks=True)
    # libero_object's tasks share one fixture world (the floor scene and its basket's region)
    # and differ in their objects: task 1's world is built for its sightings alone
    assert events == [("libero_object", 0, "built"), ("libero_object", 0, "descriptors"),
                      ("libero_object", 0, "fixture looks"), ("libero_object", 0, "closed"),
                      ("libero_object", 1, "built"), ("libero_object", 1, "descriptors"),
                      ("libero_object", 1, "closed")]
    prepare_libero_suite("libero_object", tmp_path / "ws", tasks=("0", "1"), seeds=(0,), measure_looks=True)
    assert len(events) == 7  # both measured in this workspace: nothing built


def test_a_category_that_shows_a_handle_gets_its_model_origin_along_it_and_one_that_seldom_does_not():
    mug = [{**_seen("cylinder", (0.11, 0.10, 0.12)), "handle_origin_m": 0.016 + 0.001 * (k % 3)} for k in range(6)]
    mug += [_seen("box", (0.11, 0.09, 0.12)) for _ in range(2)]  # the handle hidden twice in eight
    bowl = [_seen("cylinder", (0.11, 0.11, 0.05)) for _ in range(7)] + [{**_seen("cylinder", (0.12, 0.11, 0.05)),
                                                                         "handle_origin_m": 0.03}]
    looks = looks_from_samples({"white_yellow_mug": mug, "akita_black_bowl": bowl})
    assert looks["white_yellow_mug"]["handle_origin_m"] == pytest.approx(0.017)
    assert "handle_origin_m" not in looks["akita_black_bowl"]
    desc = ObjectDescriptor.from_dict({"name": "white_yellow_mug_1", **looks["white_yellow_mug"]})
    assert desc.handle_origin_m == pytest.approx(0.017)


@pytest.mark.parametrize("bad", [-0.01, 0.5, "near", float("nan")])
def test_a_handle_origin_out_of_range_is_a_clear_error(bad):
    from phyagentos.perception import PerceptionError

    with pytest.raises(PerceptionError, match="handle_origin_m"):
        ObjectDescriptor.from_dict({"name": "mug_1", "handle_origin_m": bad})
