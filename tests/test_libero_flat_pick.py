"""A flat box on a table whose collision top lies above its seen surface (issue 28).

LIBERO's living-room table is seen at z 0.425 m but its collision box, on which the items stand,
tops out at 0.4368 m: the 1.8 cm cream cheese box is perceived 3.1 cm tall, and the grasp set
above the seen table put the fingertips into the real one (every candidate refused, then the
fingers jammed at 80 mm: LIBERO-90 task 47 and LIBERO-10's cream cheese picks). The grasp is now
raised in small steps until the arm reaches it clear, while the fingertips still close 1 cm
below the top. The scene is generated (LIBERO's placement sampler with seed 101, ``generated:
true``) of LIBERO-90 task 47, a training task; never an evaluation init state.
"""

from __future__ import annotations

import json

import pytest
import yaml
from libero_generated_pick import run_generated_pick

from phyagentos.bench.libero import workspace_box
from phyagentos.primitives.perception import GRASP_RAISE_STEPS_M

pytestmark = pytest.mark.sim

# looks measured on generated cluttered scenes of LIBERO-90's living-room tasks (the bench's
# libero/descriptors.yaml, generated_clutter_v3)
LOOKS = {
    "alphabet_soup": {"colour": [0.186, 0.184, 0.227], "shape": "cylinder", "size_m": [0.068, 0.068, 0.0915]},
    "cream_cheese": {"colour": [0.261, 0.274, 0.409], "shape": "box", "size_m": [0.0843, 0.0446, 0.031]},
    "tomato_sauce": {"colour": [0.236, 0.141, 0.057], "shape": "cylinder", "size_m": [0.0677, 0.0677, 0.0916]},
    "basket": {"colour": [0.533, 0.516, 0.453], "shape": "box", "size_m": [0.1736, 0.1631, 0.152]},
}


def test_a_flat_box_is_grasped_higher_when_the_fingertips_would_enter_the_table_and_is_really_held(tmp_path):
    rep = run_generated_pick(tmp_path, name="flat_pick", description="pick up the cream cheese box", suite="libero_90",
                             task=47, looks=LOOKS, fixture={"name": "living_room_table", "class": "living_room_table"},
                             obj="cream_cheese_1", workspace_box=workspace_box("LIBERO_Living_Room_Tabletop_Manipulation"),
                             seed=101)
    first = rep["sessions"][0]
    assert first["verdict"] == "success", first["reason"]
    trace = [json.loads(line) for line in (tmp_path / "ws" / first["evidence"] / "trace.jsonl").read_text().splitlines()]
    grasp = next(r for r in trace if r.get("kind") == "grasp_pose" and r["leaf"] == "ComputeGrasp")
    assert grasp.get("raised_m") in GRASP_RAISE_STEPS_M
    truth = yaml.safe_load((tmp_path / "ws" / first["evidence"] / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["init_state"] is None and truth["scene_record"]["generated"] is True
    assert truth["terminal"]["held"] == ["cream_cheese_1"]
    z0 = truth["initial"]["objects"]["cream_cheese_1"]["position"][2]
    assert truth["terminal"]["objects"]["cream_cheese_1"]["position"][2] - z0 > 0.1
