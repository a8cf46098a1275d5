"""A session is scored only when every one of its criteria can be judged on ground truth."""

from __future__ import annotations

from phyagentos.agent.criteria import parse_criteria
from phyagentos.bench.verifier_scoring import confusion, score_session

# kitchen-like: the door angle lives in `articulations`, which the truth snapshot does not
# read, so `articulated` is unscorable while `released` is scorable
ACCEPT = {"articulated": {"object": "microwave", "max": -0.6}, "released": "microwave"}
STATE = {"objects": {}, "articulations": {"microwave": {"joint_position": 0.0}}, "held": []}
GT = {"initial": STATE, "terminal": STATE, "scene_record": {}}


def verdict(word, status):
    return {"verdict": word, "criteria": [{"predicate": c.text, "status": status} for c in parse_criteria(ACCEPT)]}


def test_a_failure_judged_on_an_unscorable_criterion_is_not_counted_as_a_false_failure():
    scored = score_session(accept=ACCEPT, verdict=verdict("failure", "unsatisfied"), gt=GT)
    assert scored["session"] is None and scored["truth_met"] is None
    cells = {c["predicate"].split("(")[0]: c["cell"] for c in scored["criteria"]}
    assert cells == {"articulated": "unscorable", "released": "false_failure"}  # criteria still scored
    v = confusion([scored])
    assert v["sessions_scored"] == 0 and v["sessions_unscored"] == 1
    assert v["criterion_matrix"]["unscorable"] == 1 and v["criterion_matrix"]["false_failure"] == 1


def test_a_success_with_an_unscorable_criterion_is_not_counted_as_a_true_success():
    scored = score_session(accept=ACCEPT, verdict=verdict("success", "satisfied"), gt=GT)
    assert scored["session"] is None


def test_truth_uses_the_world_frame_extent_of_a_box_lying_on_its_side():
    # a 5.5 x 2.6 x 4.7 cm box turned so that its 2.6 cm side is vertical rests at z = 1.3 cm
    # (recorded in a put_in_bin episode); judged on its own z half extent it would float
    box = {"shape": "box", "position": [0.504, 0.247, 0.01305], "quat_wxyz": [0.00273, -0.00273, -0.70710, 0.70710],
           "half_extents": [0.02755, 0.01308, 0.02366]}
    state = {"objects": {"cube": box}, "held": []}
    gt = {"initial": state, "terminal": state,
          "scene_record": {"regions": [{"name": "bin", "center": [0.5043, 0.20053], "half_extents": [0.07, 0.07]}]}}
    accept = {"inside": {"object": "cube", "region": "bin"}, "released": "cube"}
    from phyagentos.bench.verifier_scoring import truth_of_criteria  # noqa: PLC0415

    assert [t for _, t in truth_of_criteria(accept, gt)] == [True, True]
    upright = {**box, "quat_wxyz": [1.0, 0.0, 0.0, 0.0]}  # the same record upright: 1.3 cm is below its rest
    gt_up = {**gt, "initial": {"objects": {"cube": upright}, "held": []},
             "terminal": {"objects": {"cube": upright}, "held": []}}
    assert [t for _, t in truth_of_criteria(accept, gt_up)] == [False, True]


def test_a_rolled_sphere_rests_on_its_radius():
    ball = {"shape": "sphere", "position": [0.5, 0.2, 0.0277], "quat_wxyz": [0.6266, -0.4062, 0.2218, -0.6271],
            "half_extents": [0.0277, 0.0277, 0.0277]}
    state = {"objects": {"ball": ball}, "held": []}
    gt = {"initial": state, "terminal": state,
          "scene_record": {"regions": [{"name": "goal", "center": [0.5, 0.2], "half_extents": [0.08, 0.08]}]}}
    from phyagentos.bench.verifier_scoring import truth_of_criteria  # noqa: PLC0415

    assert [t for _, t in truth_of_criteria({"inside": {"object": "ball", "region": "goal"}}, gt)] == [True]
