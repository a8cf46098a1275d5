"""Picks on libero_goal's kitchen table, confirmed by the verifier (issue 28).

On the kitchen table the arm's move uncovers strips of the fixtures (the stove's white base)
the size of the cream cheese; one was taken for the picked cream cheese at confidence 0.23 and
vetoed its hold, though the simulator had it 15 cm up in the hand. The scene is generated
(LIBERO's placement sampler, ``generated: true``, seed 105), never an evaluation init state; the
looks are the ones the bench measures on generated scenes, clear of the fixtures
(``generated_clutter_v3``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from libero_generated_pick import run_generated_pick

from phyagentos.bench.libero import LIBERO_CELLS, workspace_box

pytestmark = pytest.mark.sim

# looks measured on generated cluttered scenes of libero_goal task 1 (the bench's
# libero/descriptors.yaml, generated_clutter_v3)
LOOKS = {
    "akita_black_bowl": {"colour": [0.549, 0.559, 0.531], "size_m": [0.113, 0.113, 0.0506], "shape": "cylinder"},
    "cream_cheese": {"colour": [0.255, 0.285, 0.456], "size_m": [0.0848, 0.0448, 0.0198], "shape": "box"},
    "plate": {"colour": [0.643, 0.478, 0.451], "size_m": [0.1382, 0.1382, 0.0184], "shape": "cylinder"},
    "wine_bottle": {"colour": [0.014, 0.039, 0.008], "size_m": [0.0161, 0.0161, 0.157], "shape": "cylinder"},
}
SCENE = "LIBERO_Tabletop_Manipulation"
# the fixtures' looks of libero_goal's world as the bench measures them (measure_fixture_looks,
# generated_alone_v8): found by their looks, each fixture's model stands in the planning world
# where the perceiver sees it (its ``root``); a fixture without a look is not perceived, so the
# motion planner does not know it is there
FIXTURE_LOOKS = {
    "flat_stove": {"size_m": [0.2966, 0.1905, 0.0318],
                   "place": {"offset_m": [0.0497, 0.0001], "half_extents_m": [0.075, 0.075], "height_m": 0.0312},
                   "knob": {"offset_m": [-0.1003, 0.0001], "top_m": 0.0605, "rest_yaw_rad": -0.0249,
                            "range_rad": [-0.005, 2.1]},
                   "root": {"offset_m": [-0.1003, 0.0001, 0.005], "yaw_rad": 0.0, "body_yaw_rad": -0.0022}},
    "wine_rack": {"size_m": [0.2743, 0.1419, 0.3201],
                  "root": {"offset_m": [-0.0003, -0.0088, 0.02], "yaw_rad": -3.1416, "body_yaw_rad": 0.0011}},
    "wooden_cabinet": {"size_m": [0.2569, 0.2207, 0.2272],
                       "place": {"offset_m": [-0.001, -0.0154], "half_extents_m": [0.1253, 0.0944], "height_m": 0.2272},
                       "root": {"offset_m": [0.0025, 0.0003, 0.005], "yaw_rad": -3.1416, "body_yaw_rad": 0.0051}},
}


def test_the_cream_cheese_pick_beside_the_stove_is_confirmed_and_it_is_really_held(tmp_path):
    assert SCENE in LIBERO_CELLS
    rep = run_generated_pick(tmp_path, name="goal_pick", description="pick up the cream cheese", suite="libero_goal",
                             task=6, looks=LOOKS, fixture={"name": "main_table", "class": "table"},
                             obj="cream_cheese_1", workspace_box=workspace_box(SCENE), seed=105)
    first = rep["sessions"][0]
    assert first["verdict"] == "success", first["reason"]
    truth = yaml.safe_load((tmp_path / "ws" / first["evidence"] / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["init_state"] is None and truth["scene_record"]["generated"] is True
    assert truth["terminal"]["held"] == ["cream_cheese_1"]
    z0 = truth["initial"]["objects"]["cream_cheese_1"]["position"][2]
    assert truth["terminal"]["objects"]["cream_cheese_1"]["position"][2] - z0 > 0.1


def test_a_bowl_held_by_its_rim_is_set_on_a_plate_beside_the_cabinet_with_the_hand_turned_away(tmp_path):
    """Generated scene 102 of "put the bowl on the plate": the plate stands by the cabinet and
    the rim-held bowl's hand, 5.6 cm off its centre, would meet the cabinet top at the usual
    yaw (the place failed with ``goal_in_collision``); another yaw sets the bowl down."""
    from libero_generated_pick import run_generated_graph

    from phyagentos.bench.libero import instruction_plan
    from phyagentos.targets.libero import parse_bddl, resolve_task

    task = resolve_task("libero_goal", 8)
    problem = parse_bddl(task.bddl_path)
    nodes, _ = instruction_plan(task.instruction, problem.objects, problem.fixtures)
    objects = [{"name": n, "class": c, **LOOKS[c]} for n, c in problem.objects.items()]
    rep = run_generated_graph(tmp_path, name="bowl_on_plate", description=task.instruction, suite="libero_goal",
                              task=8, objects=objects,
                              fixtures=[{"name": n, "class": c, **FIXTURE_LOOKS.get(c, {})} for n, c in problem.fixtures.items()],
                              nodes=nodes, workspace_box=workspace_box(SCENE), seed=102)
    assert [s["verdict"] for s in rep["sessions"]] == ["success", "success"], [s["reason"] for s in rep["sessions"]]
    place = rep["sessions"][1]
    trace = [json.loads(line) for line in (tmp_path / "ws" / place["evidence"] / "trace.jsonl").read_text().splitlines()]
    pose = next(r for r in trace if r.get("kind") == "place_pose")
    assert pose["yaw_rad"] != 0.0 and "wooden_cabinet" in pose["rejected_yaws"][0]["why"]
    # LIBERO's checker (the privileged record, read by this test only): the bowl is on the plate,
    # first within libero_goal's 300-step budget
    signals = yaml.safe_load((tmp_path / "ws" / place["evidence"] / "ground_truth.yaml").read_text())["benchmark"]
    assert signals["success"] is True and signals["first_success_step"] <= signals["step_budget"] == 300


def test_place_yaws_try_the_usual_yaw_first_then_the_hands_then_every_45_degrees():
    from phyagentos.primitives.perception import place_yaws

    yaws = place_yaws(0.3)
    assert yaws[:2] == [0.0, 0.3] and len(yaws) == 9
    assert len(place_yaws(0.0)) == 8 and abs(abs(place_yaws(np.pi / 2)[1]) - np.pi / 2) < 1e-9
