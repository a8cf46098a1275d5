"""Scoring the verifier against ground_truth.yaml: the confusion matrix (on real MuJoCo runs)."""

from __future__ import annotations

import pytest
import yaml

from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.bench.verifier_scoring import (
    confusion,
    judged_ground_truth,
    load_ground_truth,
    score_session,
    truth_of_criteria,
    wilson_interval,
)
from phyagentos.protocol import Workspace

pytestmark = pytest.mark.sim

PICK = {"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from unchecked_run import run_unchecked

    root = tmp_path_factory.mktemp("scoring")
    objects = [{"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.5, -0.2], "rgba": [0.8, 0.1, 0.1, 1]},
               {"name": "far_cube", "half_extents": [0.02, 0.02, 0.02], "position": [1.3, 0.3],
                "rgba": [0.1, 0.1, 0.8, 1]}]

    def graph(name, nodes):
        path = root / f"{name}.yaml"
        path.write_text(yaml.safe_dump({"version": 1, "name": name, "defaults": {"target": "franka_tabletop"},
                                        "scene": {"objects": objects}, "nodes": nodes}))
        return path

    near = graph("near", [{"id": "pick_cube", "skill": "pick", "params": {"object": "cube"}, "accept": PICK}])
    far = graph("far", [{"id": "pick_far", "skill": "pick", "params": {"object": "far_cube"},
                         "accept": {"holding": "far_cube"}}])
    near_report = run_goal_graph(near, root / "ws")
    # `run` refuses the far cube before anything moves (out of reach, issue 11): the failure
    # at run time is registered without that check, as a hand-written run would be.
    far_report = run_unchecked(far, root / "ws")
    ws = Workspace.open(root / "ws")
    recs = [ws.load_session(s.session_id) for s in near_report.sessions + far_report.sessions]
    # the pick of the near cube, and the last attempt at the far one (out of reach or out of sight)
    return (next(r for r in recs if r.node == "pick_cube"), [r for r in recs if r.node == "pick_far"][-1]), ws


def _score(ws, rec, verdict=None):
    attempt = rec.attempts[-1]
    gt = load_ground_truth(ws.root / attempt.evidence)
    return {"session_id": rec.session_id,
            **score_session(accept=rec.accept, verdict=verdict or attempt.verdict.model_dump(), gt=gt)}


def test_true_verdicts_land_on_the_diagonal(run):
    (pick, far), ws = run
    s1, s2 = _score(ws, pick), _score(ws, far)
    assert s1["session"] == "true_success" and s1["truth_met"] is True
    assert [c["cell"] for c in s1["criteria"]] == ["true_success", "true_success"]
    assert s2["session"] == "true_failure" and s2["criteria"][0]["truth"] is False
    m = confusion([s1, s2])
    assert m["session_matrix"] == {"true_success": 1, "false_success": 0, "true_failure": 1, "false_failure": 0}
    assert m["false_success_rate_pct"] == 0.0 and m["false_failure_rate_pct"] == 0.0


def test_a_success_claimed_against_ground_truth_is_counted_as_self_deception(run):
    (pick, far), ws = run
    claimed = far.attempts[-1].verdict.model_dump()
    claimed["verdict"] = "success"
    claimed["criteria"] = [{**c, "status": "satisfied"} for c in claimed["criteria"]]
    lie = _score(ws, far, claimed)
    assert lie["session"] == "false_success" and lie["criteria"][0]["cell"] == "false_success"
    denied = pick.attempts[-1].verdict.model_dump()
    denied["verdict"] = "replan"
    denied["criteria"][0]["status"] = "unsatisfied"
    denied["criteria"][1]["status"] = "unknown"
    miss = _score(ws, pick, denied)
    assert miss["session"] == "false_failure"
    assert [c["cell"] for c in miss["criteria"]] == ["false_failure", "unknown_met"]
    m = confusion([lie, miss, _score(ws, pick)])
    assert m["false_success_sessions"] == [far.session_id] and m["false_failure_sessions"] == [pick.session_id]
    assert m["false_success_rate_pct"] == pytest.approx(33.333) and m["false_success_given_unmet_pct"] == 100.0
    assert m["per_predicate"]["holding"]["false_success"] == 1


def test_truth_is_judged_exactly_on_ground_truth(run):
    (pick, _), ws = run
    gt = load_ground_truth(ws.root / pick.attempts[-1].evidence)
    assert {c.name: t for c, t in truth_of_criteria(pick.accept, gt)} == {"holding": True, "lifted": True}
    lowered = {**gt, "terminal": {**gt["terminal"], "held": []}}
    assert {c.name: t for c, t in truth_of_criteria(pick.accept, lowered)}["holding"] is False
    assert [t for _, t in truth_of_criteria({"still": {}}, gt)] == [None]  # no joint state in ground truth


def test_an_another_view_child_is_scored_from_the_acting_sessions_start(run):
    """The another-view child starts with the object already raised; it judges the acting
    pick's criteria, so its truth takes the pick's initial state (else a confirmed lift
    would count as self-deception)."""
    (pick, _), ws = run
    gt = load_ground_truth(ws.root / pick.attempts[-1].evidence)
    child = {**gt, "initial": gt["terminal"]}  # what the child's own ground truth records
    assert {c.name: t for c, t in truth_of_criteria(pick.accept, child)}["lifted"] is False
    judged = judged_ground_truth(child, gt)
    assert {c.name: t for c, t in truth_of_criteria(pick.accept, judged)}["lifted"] is True
    assert judged_ground_truth(child, None) is child and judged_ground_truth(None, gt) is None


def test_wilson_intervals_bound_the_rates():
    # 0 of 200: the upper bound is what "no false success seen" allows (about 1.9 %)
    assert wilson_interval(0, 200) == pytest.approx((0.0, 1.885), abs=1e-3)
    lo, hi = wilson_interval(10, 124)
    assert lo < 100 * 10 / 124 < hi and hi - lo < 10.0
    assert wilson_interval(5, 5)[1] == 100.0 and wilson_interval(0, 0) is None


def test_per_predicate_rates_count_unknown_while_met_as_false_failure():
    rows = [{"predicate": "lifted(object=cube)", "cell": c} for c in
            ("true_success", "unknown_met", "false_failure", "true_failure")]
    v = confusion([{"session_id": "s", "session": "false_failure", "criteria": rows}])
    r = v["per_predicate_rates"]["lifted"]
    assert r["scored"] == 4 and r["false_failure_pct"] == 50.0 and r["false_success_pct"] == 0.0
    assert v["false_failure_ci95_pct"] == wilson_interval(1, 1)


def test_an_object_without_extents_in_ground_truth_leaves_on_unscorable_not_unmet():
    """LIBERO's ground truth has positions and orientations, no extents: ``on`` cannot be
    judged on it (LIBERO's own checker is the reference there). Scored with zero extents it
    was never met, and every confirmed place counted as a false success (26 % of LIBERO-10's
    sessions at 7e40e83)."""
    state = {"objects": {"mug_1": {"position": [0.0, 0.0, 0.46], "quat_wxyz": [1, 0, 0, 0]},
                         "plate_1": {"position": [0.0, 0.0, 0.43], "quat_wxyz": [1, 0, 0, 0]}}, "held": []}
    gt = {"initial": state, "terminal": state}
    truths = dict((c.name, t) for c, t in truth_of_criteria(
        [{"on": {"object": "mug_1", "support": "plate_1"}}, {"released": "mug_1"}], gt))
    assert truths == {"on": None, "released": True}
    sized = {"objects": {n: {**o, "half_extents": [0.04, 0.04, 0.015 if n == "plate_1" else 0.045]}
                         for n, o in state["objects"].items()}, "held": []}
    sized["objects"]["mug_1"]["position"] = [0.0, 0.0, 0.43 + 0.015 + 0.045]
    assert dict((c.name, t) for c, t in truth_of_criteria(
        [{"on": {"object": "mug_1", "support": "plate_1"}}], {"initial": sized, "terminal": sized})) == {"on": True}
