"""The language bench scores an executed plan on the simulator's ground truth at scoring time.

A stacked cube hides its support from the cameras, so the perceived terminal snapshot is no
ground for scoring (the previous scorer read it and missed the cube underneath). The bench's
``truth_world`` reads the newest ``ground_truth.yaml``; a real MuJoCo stacking run is scored
met for "blue on red" and unmet for the reverse.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest
import yaml

from phyagentos.app.orchestrator import run_goal_graph

BENCH = Path(__file__).resolve().parents[1] / "bench" / "language.py"


@pytest.fixture(scope="module")
def language():
    spec = importlib.util.spec_from_file_location("language_bench", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.mark.sim
def test_an_executed_stack_is_scored_on_the_simulators_ground_truth(tmp_path, language):
    case = language.Case("stack", 0, "stack the blue cube on the red cube", {
        "objects": [{"name": "blue_cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.41, -0.236],
                     "rgba": [0.1, 0.2, 0.8, 1]},
                    {"name": "red_cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.611, -0.1],
                     "rgba": [0.8, 0.1, 0.1, 1]}],
        "regions": [{"name": "left_bin", "center": [0.42, 0.24], "half_extents": [0.07, 0.07]}]},
        {"blue_cube": ("on", "red_cube"), "red_cube": ("stay", None)})
    graph = tmp_path / "g.yaml"
    graph.write_text(yaml.safe_dump({"version": 1, "name": "stack", "scene": case.scene, "nodes": [
        {"id": "stack", "skill": "pick_and_place", "target": "franka_tabletop",
         "params": {"object": "blue_cube", "region": "red_cube"},
         "accept": [{"on": {"object": "blue_cube", "support": "red_cube"}}, {"released": "blue_cube"}]}]}))
    ws = tmp_path / "ws"
    run_goal_graph(graph, ws, seed=0, use_memory=False, consolidate=False)
    ents = language.truth_world(ws, case.scene)
    newest = max(ws.glob("evidence/*/ground_truth.yaml"), key=lambda p: p.stat().st_mtime_ns)
    truth = yaml.safe_load(newest.read_text())["terminal"]["objects"]
    assert ents["red_cube"]["position"] == truth["red_cube"]["position"]  # the support, hidden or not
    assert ents["blue_cube"]["position"] == truth["blue_cube"]["position"]
    assert language.truth_misses(case, ents, language.declared_world(case.scene)) == []
    reverse = language.Case("stack", 0, "", case.scene, {"red_cube": ("on", "blue_cube")})
    (miss,) = language.truth_misses(reverse, ents, language.declared_world(case.scene))
    assert miss.startswith("red_cube not on blue_cube")


def test_the_held_out_part_loads_apart_from_the_tuned_categories_and_is_summarised_on_its_own(language):
    held = language.held_out_cases()
    assert held and {c.part for c in held} == {"held_out"}
    stack = next(c for c in held if c.category == "stack")
    assert ("on", "blue_cube") in stack.truth.values()  # a bare `on` in YAML is true: read as the relation
    assert {"hold", "nothing", "comparative", "unknown_destination", "other_language",
            "instruction_names"} <= {c.category for c in held}
    tuned = [language.make_case(cat, 0) for cat in language.CATEGORIES]
    assert {c.part for c in tuned} == {"tuned"} and not {c.instruction for c in tuned} & {c.instruction for c in held}
    rows = [{"part": c.part, "category": c.category, "must_refuse": c.must_refuse, "status": "refused",
             "seconds": 0.0, "correct": c.must_refuse, "valid": False, "symbolic_correct": False}
            for c in tuned + held]
    summary = language.summarise(rows)
    assert set(summary["parts"]) == {"tuned", "held_out"}
    assert summary["parts"]["held_out"]["overall"]["instructions"] == len(held)
    assert summary["parts"]["tuned"]["overall"]["instructions"] == len(tuned)


def test_the_outside_authors_held_out_file_loads_with_scenes_and_truths_that_exist_and_is_reported_as_its_own_part(language):
    path = BENCH.parent / "language_heldout_outside.yaml"
    outside = language.held_out_cases(path)
    assert len(outside) >= 30 and {c.part for c in outside} == {"held_out_outside"}
    scenes = yaml.safe_load(path.read_text())["scenes"]
    for case, raw in zip(outside, yaml.safe_load(path.read_text())["cases"], strict=True):
        assert raw["scene"] in scenes and case.category in language.CATEGORIES
        objects = {o["name"] for o in case.scene["objects"]}
        regions = {r["name"] for r in case.scene["regions"]}
        assert case.must_refuse or case.truth, case.instruction
        for obj, (rel, where, *n) in case.truth.items():
            if obj == "*":  # counting: ("count", region, n)
                assert rel == "count" and where in regions and 0 < n[0] <= len(objects)
                continue
            assert obj in objects and rel in {"inside", "on", "stay", "held"}, case.instruction
            assert where is None or where in (regions if rel == "inside" else objects), case.instruction
    author = language.held_out_cases()
    assert {c.part for c in author} == {"held_out"}
    assert not {c.instruction for c in outside} & {c.instruction for c in author}
    rows = [{"part": c.part, "category": c.category, "must_refuse": c.must_refuse, "status": "refused",
             "seconds": 0.0, "correct": c.must_refuse, "valid": False, "symbolic_correct": False}
            for c in author + outside]
    summary = language.summarise(rows)
    assert set(summary["parts"]) == {"held_out", "held_out_outside"}
    assert summary["parts"]["held_out_outside"]["overall"]["instructions"] == len(outside)
    assert language.held_out_part(path) == "held_out_outside" and language.held_out_part(language.HELD_OUT) == "held_out"
