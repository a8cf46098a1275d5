"""LIBERO's catalogue: suites, tasks, init states and BDDL, resolved without building a world."""

from __future__ import annotations

import sys
import time

import pytest

from phyagentos.errors import TargetError
from phyagentos.targets.libero import catalog
from phyagentos.targets.libero.catalog import (
    SUITES,
    STANDARD_SUITES,
    check_init_index,
    load_init_states,
    parse_bddl,
    resolve_task,
    suite_tasks,
)
from phyagentos.targets.libero.target import LiberoScene


def test_the_four_evaluation_suites_have_ten_tasks_in_liberos_fixed_order_with_fifty_init_states():
    for suite in STANDARD_SUITES:
        tasks = suite_tasks(suite)
        assert [t.index for t in tasks] == list(range(10))
        for t in tasks:
            assert t.bddl_path.is_file() and t.init_states_path.is_file()
            assert load_init_states(t).shape[0] == 50
    assert len(suite_tasks("libero_90")) == 90
    # LIBERO's own names and order (task order index 0)
    assert resolve_task("libero_object", 0).language == "pick up the alphabet soup and place it in the basket"
    assert resolve_task("libero_10", 0).language == "put both the alphabet soup and the tomato sauce in the basket"
    assert resolve_task("libero_goal", 0).name == "open_the_middle_drawer_of_the_cabinet"


def test_an_unknown_suite_task_or_init_state_is_refused_with_the_valid_choices():
    with pytest.raises(TargetError, match="unknown LIBERO suite 'libero_objects'; valid suites: 'libero_10'"):
        suite_tasks("libero_objects")
    with pytest.raises(TargetError, match=r"has no task 10; valid tasks: 0-9 \(0: pick up the alphabet soup"):
        resolve_task("libero_object", 10)
    with pytest.raises(TargetError, match="has no task -1"):
        resolve_task("libero_spatial", -1)
    with pytest.raises(TargetError, match="has no init state 50; valid init states: 0-49"):
        check_init_index(resolve_task("libero_goal", 3), 50)
    assert check_init_index(resolve_task("libero_goal", 3), 49) == 49


def test_a_bad_scene_is_refused_before_robosuite_is_imported():
    # the checks read LIBERO's files only: nothing is built, no simulator is loaded
    loaded_before = "robosuite" in sys.modules
    started = time.perf_counter()
    for raw, expect in ((dict(suite="libero_100"), "valid suites"),
                        (dict(suite="libero_object", task=11), "valid tasks: 0-9"),
                        (dict(suite="libero_object", task=0, init=77), "valid init states: 0-49"),
                        (dict(suite="libero_object", colour="red"), "unknown key"),
                        (dict(suite="libero_object", objects=[{"name": "ketchup_1"}]), "is not in the task"),
                        (dict(suite="libero_object", objects=[{"name": "basket_1", "class": "plate"}]),
                         "is a 'basket', declared 'plate'")):
        with pytest.raises(TargetError, match=expect):
            LiberoScene.from_dict(raw)
    assert time.perf_counter() - started < 5.0
    assert ("robosuite" in sys.modules) == loaded_before


def test_bddl_splits_into_a_declared_half_and_a_privileged_half():
    problem = parse_bddl(resolve_task("libero_10", 0).bddl_path)
    declared = problem.declared()
    assert {"name": "basket_1", "class": "basket"} in declared["objects"]
    assert {"name": "living_room_table", "class": "living_room_table"} in declared["fixtures"]
    # the declared half names things and their categories, never where they are or what is wanted
    flat = repr(declared)
    assert "region" not in flat and "In" not in flat and "goal" not in flat
    secret = problem.privileged()
    assert secret["goal"] == ["And", ["In", "alphabet_soup_1", "basket_1_contain_region"],
                              ["In", "tomato_sauce_1", "basket_1_contain_region"]]
    assert set(secret["obj_of_interest"]) == {"alphabet_soup_1", "tomato_sauce_1", "basket_1"}
    assert ["On", "basket_1", "living_room_table_basket_init_region"] in secret["init"]
    assert secret["regions"]["basket_init_region"]["target"] == "living_room_table"
    assert secret["regions"]["contain_region"]["target"] == "basket_1"


def test_every_task_of_every_suite_parses_with_objects_and_a_goal():
    for suite in SUITES:
        for task in suite_tasks(suite):
            problem = parse_bddl(task.bddl_path)
            assert problem.objects and problem.goal, (suite, task.name)
            assert set(problem.obj_of_interest) <= set(problem.objects) | set(problem.fixtures) | {
                n for n in problem.obj_of_interest if n.endswith("_region") or "_region" in n or "_side" in n}


def test_a_missing_libero_install_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "libero.libero", None)
    catalog._suite_tasks_cached.cache_clear()
    try:
        with pytest.raises(TargetError, match=r"LIBERO is not installed .*pip install -e '\.\[libero\]'"):
            suite_tasks("libero_spatial")
    finally:
        catalog._suite_tasks_cached.cache_clear()


def test_a_generated_scene_has_no_init_state_and_keeps_declared_looks_as_plain_data():
    from phyagentos.yamlsource import load_yaml

    raw = load_yaml("suite: libero_object\ntask: 2\ngenerated: true\n"
                    "objects: [{name: salad_dressing_1, class: salad_dressing, colour: [0.09, 0.094, 0.082]}]\n",
                    error=TargetError)
    scene = LiberoScene.from_dict(raw)
    assert scene.generated and scene.to_dict()["generated"] is True
    assert type(scene.objects[0]["colour"]) is list  # writable into protocol documents (ground_truth.yaml)
    assert "generated" not in LiberoScene(suite="libero_object", task=2).to_dict()  # the bench's scenes unchanged
    with pytest.raises(TargetError, match="generated scene has no init state"):
        LiberoScene(suite="libero_object", task=2, init=0, generated=True)
    with pytest.raises(TargetError, match="generated must be true or false"):
        LiberoScene.from_dict({"suite": "libero_object", "task": 2, "generated": "yes"})
