"""A LIBERO bowl, wider than the gripper, is picked by its rim and the verifier confirms it (issue 28).

libero_spatial's ``akita_black_bowl`` is 11.2 cm across: the fingers (7.6 cm at most) cannot
take it across, so the pick takes its wall, one finger inside, one outside. The scene is
generated (LIBERO's placement sampler for libero_spatial task 1, ``generated: true``), never
an evaluation init state; the looks are the ones the bench measures on generated scenes.
The physics is robosuite's: the bowl's own collision mesh, the Panda's position-servo fingers.
"""

from __future__ import annotations

import json

import pytest
import yaml
from libero_generated_pick import run_generated_graph

from phyagentos.bench.libero import workspace_box

pytestmark = pytest.mark.sim

# looks measured on generated cluttered scenes (the bench's libero/descriptors.yaml, generated_clutter_v2)
LOOKS = {
    "akita_black_bowl": {"colour": [0.49, 0.506, 0.498], "size_m": [0.1124, 0.1124, 0.0504], "shape": "cylinder"},
    "cookies": {"colour": [0.424, 0.255, 0.129], "size_m": [0.085, 0.0644, 0.0208], "shape": "box"},
    "glazed_rim_porcelain_ramekin": {"colour": [0.6, 0.6, 0.62], "size_m": [0.0904, 0.0904, 0.0426],
                                     "shape": "cylinder"},
    "plate": {"colour": [0.62, 0.463, 0.435], "size_m": [0.1384, 0.1384, 0.0186], "shape": "cylinder"},
}


def test_a_bowl_wider_than_the_gripper_is_lifted_by_its_rim_and_the_held_width_check_passes(tmp_path):
    # the table scene's safety cell, as the bench sets it. Both physical bowls are declared, the
    # one picked by the instruction's relation ("the black bowl next to the ramekin", task 1's
    # words): with one bowl declared, perception that sees both (the one against the ramekin is
    # split from it at the neck of their footprint) rightly names neither.
    bowl = {"class": "akita_black_bowl", **LOOKS["akita_black_bowl"]}
    objects = [{"name": "akita_black_bowl_1", **bowl,
                "where": {"relation": "next_to", "of": ["glazed_rim_porcelain_ramekin_1"]}},
               {"name": "akita_black_bowl_2", **bowl},
               *({"name": f"{c}_1", "class": c, **look} for c, look in LOOKS.items() if c != "akita_black_bowl")]
    rep = run_generated_graph(
        tmp_path, name="rim_pick", description="pick up the black bowl next to the ramekin", suite="libero_spatial",
        task=1, objects=objects, fixtures=[{"name": "main_table", "class": "table"}],
        nodes=[{"id": "pick", "skill": "pick", "params": {"object": "akita_black_bowl_1", "rim_liftoff_m": 0.02},
                "accept": [{"holding": "akita_black_bowl_1"}, {"lifted": {"object": "akita_black_bowl_1", "min_height": 0.05}}]}],
        workspace_box=workspace_box("LIBERO_Tabletop_Manipulation"), seed=108)
    first = rep["sessions"][0]
    assert first["verdict"] == "success", first["reason"]
    evidence = tmp_path / "ws" / first["evidence"]
    trace = [json.loads(line) for line in (evidence / "trace.jsonl").read_text().splitlines()]
    grasp = [r for r in trace if r["kind"] == "grasp_pose"][-1]
    assert grasp["grasp_kind"] == "rim"
    # the tcp went to the rim, not the bowl's centre
    dxy = ((grasp["grasp"][0] - grasp["observed_position"][0]) ** 2
           + (grasp["grasp"][1] - grasp["observed_position"][1]) ** 2) ** 0.5
    assert 0.045 < dxy < 0.06
    # the fingers closed on the wall (a few mm), not on nothing and not across the bowl, and
    # the held-width check after the lift passed
    close = next(r for r in trace if r["kind"] == "gripper" and r["command"] == "close")
    assert close["closed_on_something"] and 0.0008 < close["opening_m"] < 0.012
    assert any(r["kind"] == "load" and r["leaf"] == "CheckHolding" for r in trace)
    # a rim grasp rises its first 2 cm slowly (rim_liftoff_m), then the rest of the lift
    moves = [r for r in trace if r["kind"] == "execute_start" and r["leaf"] in ("LiftOff", "Lift")]
    assert [r["leaf"] for r in moves] == ["LiftOff", "Lift"] and moves[0]["duration_s"] > 0
    lifting = [r["tcp_position_m"][2] for r in trace if r["kind"] == "proprio" and r.get("leaf") == "LiftOff"]
    at_close = next(r for r in trace if r["kind"] == "proprio" and r.get("phase") == "after_close")["tcp_position_m"][2]
    assert lifting and 0.0 < max(lifting) - at_close <= 0.02 + 0.003
    assert not any(r["kind"] == "failure" for r in trace)
    # what really happened (the privileged record, read by this test only): a bowl rose with the hand
    truth = yaml.safe_load((evidence / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["generated"] is True
    rose = {n: truth["terminal"]["objects"][n]["position"][2] - truth["initial"]["objects"][n]["position"][2]
            for n in ("akita_black_bowl_1", "akita_black_bowl_2")}
    assert rose["akita_black_bowl_1"] > 0.1 and rose["akita_black_bowl_2"] < 0.01, rose  # the one next to the ramekin
