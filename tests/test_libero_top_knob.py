""""Put the moka pot on the stove" on a generated LIBERO scene: the pot, wider than the gripper
opens, is taken by the knob on its lid, carried and set on the stove; the verifier and LIBERO's
own checker agree (issue 28).

The scene is generated (LIBERO's placement sampler, ``generated: true``) for LIBERO-90 task 19
(LIBERO's training set), never an evaluation init state. The stove's look is the one
``measure_fixture_looks`` measures (as in ``test_libero_knob``).
"""

from __future__ import annotations

import json

import pytest
import yaml
from libero_generated_pick import run_generated_graph
from test_libero_knob import STOVE

from phyagentos.bench.libero import instruction_nodes, workspace_box

pytestmark = pytest.mark.sim

#: The moka pot's look, measured by the bench on generated scenes (its ``libero/descriptors.yaml``).
MOKA_POT = {"colour": [0.627, 0.619, 0.6], "size_m": [0.1234, 0.0772, 0.1442], "shape": "box"}


def test_a_moka_pot_too_wide_for_the_hand_is_carried_by_its_lid_knob_onto_the_stove(tmp_path):
    nodes = instruction_nodes("put the moka pot on the stove", {"moka_pot_1": "moka_pot"},
                              {"kitchen_table": "kitchen_table", "flat_stove_1": "flat_stove"})
    rep = run_generated_graph(
        tmp_path, name="moka_pot", description="put the moka pot on the stove", suite="libero_90", task=19,
        objects=[{"name": "moka_pot_1", "class": "moka_pot", **MOKA_POT}],
        fixtures=[{"name": "kitchen_table", "class": "kitchen_table"}, STOVE],
        nodes=[{k: v for k, v in n.items() if k != "limits"} for n in nodes],
        workspace_box=workspace_box("LIBERO_Kitchen_Tabletop_Manipulation"), seed=500)
    pick, place = rep["sessions"]
    assert (pick["verdict"], place["verdict"]) == ("success", "success"), (pick["reason"], place["reason"])
    evidence = tmp_path / "ws" / pick["evidence"]
    trace = [json.loads(line) for line in (evidence / "trace.jsonl").read_text().splitlines()]
    grasp = [t for t in trace if t["kind"] == "grasp_pose"][-1]
    assert grasp["grasp_kind"] == "top_knob"
    before = {e["name"]: e for e in yaml.safe_load((evidence / "initial.yaml").read_text())["entities"]}
    pot = before["moka_pot_1"]
    assert 2 * min(pot["size"][:2]) > 0.065  # seen about as wide as the hand opens
    assert pot["attributes"]["top_knob_z_m"] > pot["position"][2] + pot["size"][2] + 0.012  # the knob stands up
    # what really happened (the privileged record, read by this test only): LIBERO's checker agrees
    truth = yaml.safe_load((tmp_path / "ws" / place["evidence"] / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["generated"] is True and truth["benchmark"]["success"] is True
