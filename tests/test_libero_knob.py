""""Turn on the stove" on a generated LIBERO scene: the knob is grasped, turned to mid-travel and
read from its bar; the verifier and LIBERO's own checker agree (issue 28).

The scene is generated (LIBERO's placement sampler, ``generated: true``) for LIBERO-90's
"turn on the stove" (task 44, KITCHEN_SCENE9: the frying pan's handle lies against the
stove in many of its scenes), never an evaluation init state. The stove's look (its
``knob`` from its model) is the one ``measure_fixture_looks`` measures on that world.
"""

from __future__ import annotations

import pytest
import yaml
from libero_generated_pick import run_generated_graph

from phyagentos.bench.libero import TURN_ON_FRACTION, TURNED_ON_MIN_FRACTION, workspace_box

pytestmark = pytest.mark.sim

STOVE = {"name": "flat_stove_1", "class": "flat_stove", "size_m": [0.2927, 0.1911, 0.0451],
         "place": {"offset_m": [0.0492, 0.0002], "half_extents_m": [0.075, 0.075], "height_m": 0.0317},
         "knob": {"offset_m": [-0.1008, 0.0002], "top_m": 0.0599, "rest_yaw_rad": -0.0135, "range_rad": [-0.005, 2.1]}}


def test_turning_on_the_stove_is_confirmed_on_the_knob_read_from_its_bar_and_libero_agrees(tmp_path):
    rep = run_generated_graph(
        tmp_path, name="turn_on", description="turn on the stove", suite="libero_90", task=44, objects=[],
        fixtures=[{"name": "kitchen_table", "class": "kitchen_table"}, STOVE],
        nodes=[{"id": "turn_on", "skill": "turn_knob", "params": {"object": "flat_stove_1", "to_fraction": TURN_ON_FRACTION},
                "accept": [{"articulated": {"object": "flat_stove_1", "min_fraction": TURNED_ON_MIN_FRACTION}}]}],
        workspace_box=workspace_box("LIBERO_Kitchen_Tabletop_Manipulation"), seed=101)
    (session,) = rep["sessions"]
    assert session["verdict"] == "success", session["reason"]
    evidence = tmp_path / "ws" / session["evidence"]
    before = {e["name"]: e for e in yaml.safe_load((evidence / "initial.yaml").read_text())["entities"]}
    after = {e["name"]: e for e in yaml.safe_load((evidence / "terminal.yaml").read_text())["entities"]}
    q0 = before["flat_stove_1"]["attributes"]["joint_position"]
    q1 = after["flat_stove_1"]["attributes"]["joint_position"]
    assert abs(q0) < 0.12 and 0.9 < q1 < 1.3  # read off at the start, about mid-travel (1.05 rad) at the end
    # what really happened (the privileged record, read by this test only): LIBERO's checker agrees
    truth = yaml.safe_load((evidence / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["generated"] is True and truth["benchmark"]["success"] is True
