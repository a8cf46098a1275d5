"""Picks on libero_goal's kitchen table, confirmed by the verifier (issue 28).

On the kitchen table the arm's move uncovers strips of the fixtures (the stove's white base)
the size of the cream cheese; one was taken for the picked cream cheese at confidence 0.23 and
vetoed its hold, though the simulator had it 15 cm up in the hand. The scene is generated
(LIBERO's placement sampler, ``generated: true``, seed 105), never an evaluation init state; the
looks are the ones the bench measures on generated scenes, clear of the fixtures
(``generated_clutter_v3``).
"""

from __future__ import annotations

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
