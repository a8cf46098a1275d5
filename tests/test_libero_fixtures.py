"""A place onto a LIBERO fixture's top, on a generated scene, is confirmed by the verifier (issue 28).

libero_goal's "put the bowl on top of the cabinet" (task 4) and "put the wine bottle on top
of the cabinet" (task 2) failed because the cabinet was never perceived: fixtures had no look,
and its top (0.23 m over the table) was above the perceiver's 0.2 m height crop. The fixture
is now declared with its look, measured on its model on generated scenes
(``phyagentos.targets.libero.descriptors.measure_fixture_looks``: each fixture alone; the
cabinet's ``top_side`` site relative to the perceived body). The scene is generated (LIBERO's
placement sampler, ``generated: true``), never an evaluation init state.
"""

from __future__ import annotations

import pytest
import yaml
from libero_generated_pick import run_generated_pick

from phyagentos.bench.libero import workspace_box

pytestmark = pytest.mark.sim

# object looks measured on generated cluttered scenes (the bench's libero/descriptors.yaml, generated_clutter_v2,
# libero_spatial's worlds); fixture looks as the bench measures them (libero/fixture_looks.yaml, generated_alone_v2;
# v3 adds the stove's knob, which this test does not turn)
LOOKS = {
    "akita_black_bowl": {"colour": [0.49, 0.506, 0.498], "size_m": [0.1124, 0.1124, 0.0504], "shape": "cylinder"},
    "plate": {"colour": [0.62, 0.463, 0.435], "size_m": [0.1384, 0.1384, 0.0186], "shape": "cylinder"},
}
FIXTURES = [
    {"name": "wooden_cabinet_1", "class": "wooden_cabinet", "size_m": [0.2569, 0.2207, 0.2272],
     "place": {"offset_m": [-0.001, -0.0154], "half_extents_m": [0.1253, 0.0944], "height_m": 0.2272}},
    {"name": "flat_stove_1", "class": "flat_stove", "size_m": [0.2966, 0.1905, 0.0318],
     "place": {"offset_m": [0.0497, 0.0001], "half_extents_m": [0.075, 0.075], "height_m": 0.0312}},
    {"name": "wine_rack_1", "class": "wine_rack", "size_m": [0.2743, 0.1419, 0.3201]},
]


def test_a_bowl_placed_on_top_of_the_cabinet_is_confirmed_on_the_perceived_top_and_libero_agrees(tmp_path):
    rep = run_generated_pick(tmp_path, name="cabinet_top", description="put the bowl on top of the cabinet",
                             suite="libero_goal", task=4, looks=LOOKS, fixture={"name": "main_table", "class": "table"},
                             fixtures=FIXTURES, obj="akita_black_bowl_1", place_on="wooden_cabinet_1",
                             workspace_box=workspace_box("LIBERO_Tabletop_Manipulation"))
    pick, place = rep["sessions"][0], rep["sessions"][-1]
    assert pick["verdict"] == "success", pick["reason"]
    assert place["node"] == "place" and place["verdict"] == "success", place["reason"]
    evidence = tmp_path / "ws" / place["evidence"]
    terminal = yaml.safe_load((evidence / "terminal.yaml").read_text())
    ents = {e["name"]: e for e in terminal["entities"]}
    cabinet = ents["wooden_cabinet_1"]
    assert cabinet["kind"] == "fixture" and cabinet["attributes"]["confidence"] >= 0.5
    # the bowl is seen up there (above the old 0.2 m crop), resting on the cabinet's perceived top
    bowl = ents["akita_black_bowl_1"]
    top = cabinet["position"][2] + cabinet["size"][2]
    assert top > 0.9 + 0.2 and abs(bowl["position"][2] - bowl["size"][2] - top) < 0.015
    assert any(r["relation"] == "on" and r["subject"] == "akita_black_bowl_1" and r["object"] == "wooden_cabinet_1"
               for r in terminal["relations"])
    # what really happened (the privileged record, read by this test only): LIBERO's checker agrees
    truth = yaml.safe_load((evidence / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["generated"] is True and truth["benchmark"]["task_name"] == "put_the_bowl_on_top_of_the_cabinet"
    assert truth["benchmark"]["success"] is True


def test_a_fixture_standing_against_another_still_gets_its_look():
    """LIBERO-PRO's ``libero_goal_swap`` stands the stove against the wine rack: measured with
    the other fixtures in place, their shared body's centre lies in both footprints and the
    stove had no look in any generated scene. Seen again with the others out of view, it has
    one: its knob and its burner's place patch, the patch's surface as in libero_goal's
    standard scenes (3.1 cm)."""
    from phyagentos.targets.libero import LiberoScene
    from phyagentos.targets.libero.descriptors import measure_fixture_looks
    from phyagentos.targets.libero.target import LiberoTarget

    t = LiberoTarget("swap", LiberoScene(suite="libero_goal_swap", task=1, generated=True), seed=500)
    try:
        looks = measure_fixture_looks(t, scenes=2)
    finally:
        t.close()
    assert {"flat_stove", "wine_rack", "wooden_cabinet"} <= set(looks)
    stove = looks["flat_stove"]
    assert "knob" in stove and stove["place"]["height_m"] == pytest.approx(0.031, abs=0.003)
