""""Open the middle drawer of the cabinet" on a generated LIBERO scene: the handle is grasped,
the drawer pulled to its open stop and read from its handle; the verifier and LIBERO's own
checker agree (issue 28).

The scene is generated (LIBERO's placement sampler, ``generated: true``) for libero_goal's
task 0, never an evaluation init state; in it a plate lies 3.5 cm in front of the drawer's
handle (what the hand's pitched approach clears). The cabinet's look (its ``drawers`` from its
model) is the one ``measure_fixture_looks`` measures on that world.
"""

from __future__ import annotations

import pytest
import yaml
from libero_generated_pick import run_generated_graph

from phyagentos.bench.libero import OPEN_FRACTION, OPENED_MIN_FRACTION, workspace_box

pytestmark = pytest.mark.sim


def _drawer(name: str, height: float, top: float) -> dict:
    return {"name": name, "handle_offset_m": [0.0053, 0.1019], "height_m": height, "half_length_m": 0.0444,
            "axis_xy": [0.0, 1.0], "travel_m": [-0.01, 0.16], "face_m": 0.008, "half_width_m": 0.1093, "top_m": top,
            "back_m": 0.111}


CABINET = {"name": "wooden_cabinet_1", "class": "wooden_cabinet", "size_m": [0.2569, 0.2207, 0.2272],
           "place": {"offset_m": [-0.001, -0.0154], "half_extents_m": [0.1253, 0.0944], "height_m": 0.2272},
           "drawers": [_drawer("top", 0.1889, 0.2223), _drawer("middle", 0.1154, 0.1526),
                       _drawer("bottom", 0.0461, 0.084)]}


def test_opening_the_middle_drawer_is_confirmed_on_its_handle_and_libero_agrees(tmp_path):
    drawer = "wooden_cabinet_1_middle_drawer"
    rep = run_generated_graph(
        tmp_path, name="open_drawer", description="open the middle drawer of the cabinet", suite="libero_goal", task=0,
        objects=[], fixtures=[{"name": "main_table", "class": "table"}, CABINET],
        nodes=[{"id": "open", "skill": "slide_drawer", "params": {"object": drawer, "to_fraction": OPEN_FRACTION},
                "accept": [{"articulated": {"object": drawer, "min_fraction": OPENED_MIN_FRACTION}}]}],
        workspace_box=workspace_box("LIBERO_Kitchen_Tabletop_Manipulation"), seed=103)
    (session,) = rep["sessions"]
    assert session["verdict"] == "success", session["reason"]
    evidence = tmp_path / "ws" / session["evidence"]
    before = {e["name"]: e for e in yaml.safe_load((evidence / "initial.yaml").read_text())["entities"]}
    after = {e["name"]: e for e in yaml.safe_load((evidence / "terminal.yaml").read_text())["entities"]}
    assert abs(before[drawer]["attributes"]["joint_position"]) < 0.01  # read shut at the start
    assert after[drawer]["attributes"]["joint_position"] > 0.14  # and out near its stop (0.16 m) at the end
    # what really happened (the privileged record, read by this test only): LIBERO's checker agrees
    truth = yaml.safe_load((evidence / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["generated"] is True and truth["benchmark"]["success"] is True
