"""The plate against the cabinet, pressed from above and dragged to the front of the stove
(issue 28, libero_goal task 5's instruction, seventeenth pass).

Generated scene 104 (LIBERO's placement sampler, ``generated: true``, never an evaluation init
state) sets the plate 2.7 cm from the wooden cabinet's side, where no hand fits behind it: every
start of the push from behind collides with the cabinet (as in 6 of 16 development scenes). The
push presses the plate from above at its perceived centre instead and drags it. The looks are
the ones the bench measures on generated scenes (``generated_clutter_v3``); the skill parameters
are the LIBERO bench's (``SKILL_DEFAULTS``).
"""

from __future__ import annotations

import json

import pytest
import yaml
from libero_generated_pick import run_generated_graph
from test_libero_goal_pick import FIXTURE_LOOKS, LOOKS, SCENE

from phyagentos.bench.libero import SKILL_DEFAULTS, workspace_box

pytestmark = pytest.mark.sim


def test_the_plate_against_the_cabinet_is_dragged_to_the_front_of_the_stove(tmp_path):
    from phyagentos.bench.libero import instruction_plan
    from phyagentos.targets.libero import parse_bddl, resolve_task

    task = resolve_task("libero_goal", 5)
    problem = parse_bddl(task.bddl_path)
    nodes, _ = instruction_plan(task.instruction, problem.objects, problem.fixtures,
                                skill_params={"push": SKILL_DEFAULTS["push"]})
    assert [n["skill"] for n in nodes] == ["push"]
    objects = [{"name": n, "class": c, **LOOKS[c]} for n, c in problem.objects.items()]
    rep = run_generated_graph(tmp_path, name="push_plate", description=task.instruction, suite="libero_goal", task=5,
                              objects=objects, fixtures=[{"name": n, "class": c, **FIXTURE_LOOKS.get(c, {})}
                                        for n, c in problem.fixtures.items()],
                              nodes=nodes, workspace_box=workspace_box(SCENE), seed=104)
    first = rep["sessions"][0]
    ws = tmp_path / "ws"
    trace = [json.loads(line) for line in (ws / first["evidence"] / "trace.jsonl").read_text().splitlines()]
    pose = next(r for r in trace if r.get("kind") == "push_pose")
    assert pose["press"] and pose["direction"][1] > 0.8  # pressed from above, dragged away from the cabinet
    [landed] = [r for r in trace if r.get("kind") == "press"]
    # the robot's own parts touched (its force sensing names nothing else): the fingers
    assert landed["touched"] and all("finger" in t for t in landed["touched"])
    # LIBERO's checker (the privileged record, read by this test only): the plate in front of the stove
    truth = yaml.safe_load((ws / first["evidence"] / "ground_truth.yaml").read_text())
    # on the plate's floor (5 mm above its origin here), not on a neighbour's top (the cream cheese
    # box stands 1.8 cm, a bowl's rim 5.1 cm) nor on the plate's rim (1.9 cm)
    plate_z = truth["initial"]["objects"]["plate_1"]["position"][2]
    assert plate_z < landed["tips_z"] < plate_z + 0.01
    moved = [b - a for a, b in zip(truth["initial"]["objects"]["plate_1"]["position"],
                                   truth["terminal"]["objects"]["plate_1"]["position"])]
    assert moved[1] > 0.15 and abs(moved[2]) < 0.005  # dragged along the table, not lifted or tipped
    signals = truth["benchmark"]
    assert signals["success"] is True and signals["first_success_step"] <= signals["step_budget"] == 300
    # whatever our verifier decides, it never calls a plate LIBERO does not count a success
    assert all(s["verdict"] != "success" or signals["success"] for s in rep["sessions"])
