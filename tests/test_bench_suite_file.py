"""A bench suite file (``phyagentos bench SUITE.yaml``, LIBERO's generated suites included) is
refused with ``file:line`` -- the line of the offending key or item -- before anything is
built, like every other deploy-time file (issue 33); a nested field of ``fleet.yaml`` is
reported at its own line."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from hostile_tally import counted

from phyagentos.bench.suite import available_suites, load_suite
from phyagentos.errors import BenchError, FleetError
from phyagentos.fleet.config import load_fleet_config
from phyagentos.yamlsource import line_at, load_yaml

TASK = "  - id: pick\n    goal_graph: pick_and_place.yaml\n"

#: (suite text, the 1-based line the error must name, what it must say)
BAD_SUITES = [
    ("version: 1\nname: s\ncolour: red\ntasks:\n" + TASK, 3, "unknown key(s) 'colour'"),
    ("version: 2\nname: s\ntasks:\n" + TASK, 1, "unsupported version 2"),
    ("version: 1\nname: 'not an id'\ntasks:\n" + TASK, 2, "name must be an identifier"),
    ("version: 1\nname: s\nepisodes: 0\ntasks:\n" + TASK, 3, "episodes must be an integer >= 1"),
    ("version: 1\nname: s\nepisodes: true\ntasks:\n" + TASK, 3, "episodes must be an integer >= 1"),
    ("version: 1\nname: s\nheldout_seed_offset: .inf\ntasks:\n" + TASK, 3, "heldout_seed_offset must be"),
    ("version: 1\nname: s\nperturbations:\n  rate: 0.5\n  kinds:\n    - heavy_object\n    - gremlins\ntasks:\n" + TASK,
     7, "unknown perturbation 'gremlins'"),
    ("version: 1\nname: s\nperturbations:\n  rate: .nan\n  kinds: [heavy_object]\ntasks:\n" + TASK, 4,
     "perturbations.rate must be a number in [0, 1]"),
    ("version: 1\nname: s\nperturbations:\n  rate: 0.5\n  gremlins: 1\ntasks:\n" + TASK, 5,
     "perturbations must be a mapping"),
    ("version: 1\nname: s\ntasks: []\n", 3, "tasks must be a non-empty list"),
    ("version: 1\nname: s\ntasks:\n  - 7\n", 4, "tasks[0] must be a mapping"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    bogus: 1\n", 6, "tasks[0]: unknown key(s) 'bogus'"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    safety: [1]\n", 6, "tasks[0].safety must be a mapping"),
    ("version: 1\nname: s\ntasks:\n" + TASK + TASK, 6, "duplicate task id 'pick'"),
    ("version: 1\nname: s\ntasks:\n  - id: pick\n    goal_graph: nowhere.yaml\n", 5, "goal graph 'nowhere.yaml' not found"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    target: [a]\n", 6, "tasks[0].target must be a target name"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    randomize:\n      - names: [cube]\n        yaw: abc\n", 8,
     "yaw must be a finite number >= 0"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    randomize:\n      - names: [cube]\n        yaw: .inf\n", 8,
     "yaw must be a finite number >= 0"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    randomize:\n      - names: [cube]\n        xy: [.nan, 0.1]\n", 8,
     "xy must be two finite numbers"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    randomize:\n      - names: [cube]\n        xy: [-0.1, 0.1]\n", 8,
     "xy must be >= 0"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    randomize:\n      - names: cube\n", 7, "names must be a non-empty list"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    randomize:\n      - {xy: [0.1, 0.1]}\n", 7,
     "randomize[0] must be a mapping with 'names'"),
    ("version: 1\nname: s\ntasks:\n" + TASK + "    random_world: {colour: red}\n", 6, "random_world must be true"),
    # LIBERO's suites write the episode's seed into the scene (``seed_to_scene: init``)
    ("version: 1\nname: s\ntasks:\n" + TASK + "    seed_to_scene: not a key\n", 6, "seed_to_scene must be a scene key"),
    ("version: 1\nname: s\nsafety: [1, 2]\ntasks:\n" + TASK, 3, "safety must be a mapping"),
    ("version: 1\nname: s\ntasks: [\n", 4, "YAML syntax error"),
    ("- just\n- a list\n", 1, "top level must be a mapping"),
]


@pytest.mark.parametrize("text,line,expect", BAD_SUITES, ids=[f"line{c[1]}-{c[2][:30]}" for c in BAD_SUITES])
@counted("bench/LIBERO suite YAML")
def test_a_bad_suite_key_is_reported_with_its_file_and_line(tmp_path, text, line, expect):
    path = tmp_path / "suite.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(BenchError) as info:
        load_suite(path)
    message = str(info.value)
    assert message.startswith(f"{path}:{line}: "), message  # file:line, named once
    assert message.count(str(path)) == 1, message
    assert expect in message, message
    assert "Traceback" not in message
    assert path.read_text(encoding="utf-8") == text  # reported, never rewritten


def test_a_suite_loaded_with_lines_still_gives_plain_data(tmp_path):
    # The checks read line-carrying containers; what the suite keeps (and the bench dumps
    # into every episode) is plain YAML data again.
    for name in available_suites():
        suite = load_suite(name)
        yaml.safe_dump(suite.to_dict())
        yaml.safe_dump(dict(suite.safety))
        for task in suite.tasks:
            if task.random_world is not None:
                assert type(task.random_world) is dict
                yaml.safe_dump(task.random_world)
    path = tmp_path / "s.yaml"
    path.write_text("version: 1\nname: s\nsafety:\n  workspace_box: {min: [-1, -1, 0], max: [1, 1, 2]}\ntasks:\n"
                    + TASK + "    random_world: {distractors: [0, 2]}\n", encoding="utf-8")
    suite = load_suite(path)
    assert type(suite.raw) is dict and type(suite.safety["workspace_box"]["min"]) is list
    assert suite.tasks[0].random_world == {"distractors": [0, 2]}
    assert yaml.safe_load(yaml.safe_dump(suite.to_dict()))["tasks"][0]["id"] == "pick"


@pytest.mark.parametrize("text,line", [
    ("# an edge\nname: arm1\nauth:\n  user: 'a b'\n  password_file: pw\n", 4),
    ("name: arm1\ntls:\n  root_ca: ca.pem\n  cert: me.pem\n  key: me.key\n  colour: red\n", 6),
    ("name: arm1\nconnect:\n  - tcp/10.0.0.2:7447\n  - http://x\n", 2),
])
@counted("fleet.yaml: nested fields")
def test_a_nested_fleet_field_is_reported_at_its_own_line(tmp_path, text, line):
    path = tmp_path / "fleet.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(FleetError) as info:
        load_fleet_config(path)
    assert re.match(rf"{re.escape(str(path))}:{line}: ", str(info.value)), str(info.value)
    assert info.value.line == line


def test_line_at_follows_keys_and_items_to_the_deepest_known_line():
    data = load_yaml("a:\n  b:\n    - x\n    - {c: 1,\n       d: 2}\ne: 3\n", error=ValueError)
    assert line_at(data, ("a", "b", 1, "d")) == 5
    assert line_at(data, ("a", "b", 0)) == 3
    assert line_at(data, ("a", "b", "missing")) == 2  # stops at the nearest known line: the key b
    assert line_at(data, ("a", "missing", 0)) == 1
    assert line_at(data, ("e",)) == 6
    assert line_at(data, ()) == 1
    assert line_at(Path("not yaml"), ("x",)) is None
