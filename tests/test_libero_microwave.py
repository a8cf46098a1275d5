""""Put the yellow and white mug in the microwave and close it" (LIBERO-10 task 9) on a generated
LIBERO scene: the mug is taken by its handle, carried level into the microwave through its
mouth, seen there from the mouth, and the door pushed shut; our verdicts and LIBERO's own checker
agree (issue 28).

The scene is generated (LIBERO's placement sampler, ``generated: true``), never an init state.
The looks are the ones the bench measures on that world (objects on generated cluttered scenes,
the microwave on its model with its door shut).
"""

from __future__ import annotations

import json
import math

import pytest
import yaml
from libero_generated_pick import MICROWAVE, run_generated_graph

from phyagentos.bench.libero import workspace_box

pytestmark = pytest.mark.sim

MUGS = [
    {"name": "porcelain_mug_1", "class": "porcelain_mug", "colour": [0.45, 0.453, 0.461], "handle_origin_m": 0.0172,
     "shape": "cylinder", "size_m": [0.0971, 0.0969, 0.1118]},
    {"name": "white_yellow_mug_1", "class": "white_yellow_mug", "colour": [0.604, 0.527, 0.255], "handle_origin_m": 0.018,
     "size_m": [0.1038, 0.1036, 0.1038]},
]
def test_a_mug_taken_by_its_handle_goes_into_the_microwave_which_is_then_shut_and_libero_agrees(tmp_path):
    from phyagentos.bench.libero import instruction_nodes  # noqa: PLC0415

    nodes = instruction_nodes("put the yellow and white mug in the microwave and close it",
                              {"porcelain_mug_1": "porcelain_mug", "white_yellow_mug_1": "white_yellow_mug"},
                              {"kitchen_table": "kitchen_table", "microwave_1": "microwave"})
    assert [n["skill"] for n in nodes] == ["pick_by_handle", "place_inside", "close_door"]
    rep = run_generated_graph(
        tmp_path, name="mug_in_microwave", description="put the yellow and white mug in the microwave and close it",
        suite="libero_10", task=9, objects=MUGS, fixtures=[{"name": "kitchen_table", "class": "kitchen_table"}, MICROWAVE],
        nodes=[{k: v for k, v in n.items() if k != "limits"} for n in nodes],
        workspace_box=workspace_box("LIBERO_Kitchen_Tabletop_Manipulation"), seed=503)
    sessions = {s["node"]: s for s in rep["sessions"]}
    for node in ("pick_white_yellow_mug_1", "place_white_yellow_mug_1", "close_microwave_1"):
        assert sessions[node]["verdict"] == "success", (node, sessions[node]["reason"])
    # the pick's trace names the grasp by the handle and the mug's centre it was seen at: the
    # held-object model judges the close at the handle, and carries the centre
    pick = tmp_path / "ws" / sessions["pick_white_yellow_mug_1"]["evidence"]
    grasp = [json.loads(line) for line in (pick / "trace.jsonl").read_text().splitlines()
             if '"grasp_pose"' in line]
    assert grasp and grasp[-1]["grasp_kind"] == "handle" and len(grasp[-1]["observed_position"]) == 3
    place = tmp_path / "ws" / sessions["place_white_yellow_mug_1"]["evidence"]
    after = yaml.safe_load((place / "terminal.yaml").read_text())
    assert any(r["relation"] == "on" and r["subject"] == "white_yellow_mug_1" and r["object"] == "microwave_1_inside"
               for r in after["relations"])
    # what really happened (the privileged record, read by this test only): LIBERO's checker agrees
    close = tmp_path / "ws" / sessions["close_microwave_1"]["evidence"]
    truth = yaml.safe_load((close / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["generated"] is True and truth["benchmark"]["success"] is True


def test_a_mug_lifted_by_its_handle_is_carried_where_its_cup_hangs_and_its_lift_confirmed(tmp_path):
    """The porcelain mug taken by its handle (LIBERO-PRO's ``libero_10_object`` task 9 puts it in
    the yellow and white mug's place; generated scene 504): the hand, pitched at the bar, rises
    10 cm. Carried as if held by its rim, the mug read 7.1 cm of rise, 2.5 cm further out along
    its handle than its cup hung (seen there as an unknown thing), and the lift was undecided."""
    rep = run_generated_graph(
        tmp_path, name="mug_by_handle", description="pick up the porcelain mug by its handle", suite="libero_10_object",
        task=9, objects=[MUGS[0], {"name": "red_coffee_mug_1", "class": "red_coffee_mug", "colour": [0.345, 0.176, 0.173],
                                   "handle_origin_m": 0.0186, "size_m": [0.0998, 0.091, 0.1358]}],
        fixtures=[{"name": "kitchen_table", "class": "kitchen_table"}, MICROWAVE],
        nodes=[{"id": "pick_porcelain_mug_1", "skill": "pick_by_handle", "params": {"object": "porcelain_mug_1"},
                "accept": [{"holding": "porcelain_mug_1"}, {"lifted": {"object": "porcelain_mug_1", "min_height": 0.05}}]}],
        workspace_box=workspace_box("LIBERO_Kitchen_Tabletop_Manipulation"), seed=504)
    [pick] = rep["sessions"]
    assert pick["verdict"] == "success", pick["reason"]
    after = yaml.safe_load((tmp_path / "ws" / pick["evidence"] / "terminal.yaml").read_text())
    mug = next(e for e in after["entities"] if e["name"] == "porcelain_mug_1")
    assert mug["attributes"]["held"] is True
    assert not [e for e in after["entities"] if e["kind"] == "unknown"]  # its cup is the hand's, not a rival
    # what really happened (read by this test only): the carried origin within 1 cm of the mug's
    truth = yaml.safe_load((tmp_path / "ws" / pick["evidence"] / "ground_truth.yaml").read_text())
    true_xy = truth["terminal"]["robosuite_observations"]["porcelain_mug_1_pos"][:2]
    assert math.dist(mug["attributes"]["origin_xy"], true_xy) < 0.01
