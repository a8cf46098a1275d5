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
