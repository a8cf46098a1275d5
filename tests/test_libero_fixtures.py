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

import numpy as np
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


# libero_goal_swap task 8's objects, as the bench measured their looks (libero/descriptors.yaml,
# generated_clutter_v6: generated scenes, never an init state)
SWAP_LOOKS = {
    "akita_black_bowl": {"colour": [0.561, 0.569, 0.549], "size_m": [0.113, 0.113, 0.0506], "shape": "cylinder"},
    "cream_cheese": {"colour": [0.253, 0.279, 0.443], "size_m": [0.0846, 0.0451, 0.0196], "shape": "box"},
    "wine_bottle": {"colour": [0.013, 0.039, 0.008], "size_m": [0.0163, 0.0163, 0.1561], "shape": "cylinder"},
    "plate": {"colour": [0.639, 0.475, 0.448], "size_m": [0.1385, 0.1385, 0.0186], "shape": "cylinder"},
}


def test_the_wine_racks_base_is_the_racks_own_and_a_plate_standing_against_it_is_seen():
    """LIBERO-PRO's ``libero_goal_swap`` task 8 ("put the bowl on the plate") stands the plate
    against the wine rack. The rack's look is fitted to its racks; its base and front bar stand
    5 cm further out, stayed in the object cloud, and joined the plate (and the cream cheese
    beside it) into one segment that matched nothing: the plate was never seen. With the
    footprint of the rack's fixed parts in its look (``model_box``), those points are the
    rack's, and the plate is seen where it stands. Generated scene 500 (LIBERO's sampler)."""
    from phyagentos.perception import Perceiver
    from phyagentos.primitives.observation import robot_capsules
    from phyagentos.targets.libero import LiberoScene
    from phyagentos.targets.libero.descriptors import measure_fixture_looks
    from phyagentos.targets.libero.target import LiberoTarget

    t = LiberoTarget("swap8", LiberoScene(suite="libero_goal_swap", task=8, generated=True), seed=500)
    try:
        looks = measure_fixture_looks(t)
        t.generate_scene(500)
        objects = [{"name": n, "class": c, **SWAP_LOOKS[c]} for n, c in t._problem.objects.items()]
        fixtures = [{"name": n, "class": c, **looks.get(c, {})} for n, c in t._problem.fixtures.items()]
        frames = [t.capture(c) for c in t.camera_names()]
        truth = t.data.xpos[t._obj_body["plate_1"]][:2].copy()  # scoring only

        config, proprio, capsules = t.perception_config(), t.proprioception(), robot_capsules(t)
    finally:
        t.close()

    def seen(fx):
        snap = Perceiver(config, {"objects": objects, "fixtures": fx}).observe(frames, proprio, robot_capsules=capsules)
        return {e["name"]: e for e in snap["entities"]}

    box = looks["wine_rack"]["model_box"]
    assert box["hi"][1] - box["lo"][1] > looks["wine_rack"]["size_m"][1] + 0.1  # the model reaches past the racks
    ents = seen(fixtures)
    assert "plate_1" in ents and np.linalg.norm(np.subtract(ents["plate_1"]["position"][:2], truth)) < 0.01
    assert "cream_cheese_1" in ents
    # without the box (the look as before), the base's strip joins the plate and it goes unseen
    assert "plate_1" not in seen([{k: v for k, v in f.items() if k != "model_box"} for f in fixtures])
