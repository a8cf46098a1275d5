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
