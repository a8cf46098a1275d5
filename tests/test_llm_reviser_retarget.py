"""A revision that moves a node to another target, chosen by the SkillRuntime-Target Selector.

The SO-101 (5 joints, standing at (0.25, 0) on the tabletop) and the Franka share the table,
each in its own simulated world. A randomised world (seed 8: a 2 cm cylinder drawn 0.43 m from
the SO-101's base) puts the object beyond the SO-101's reach: its pick fails at run time with
``ik_unreachable`` (the drawn position is only known once perceived, so the graph check cannot
refuse it). The rule ladder has nothing for that cause and the run fails; the model reviser
is offered ``switch_target`` to the target the selector finds reaching the *perceived* position
(the Runtime's IK through the reach query), and the child runs there and succeeds; the place
downstream follows it to that target's world. The revision records the selector's reasons; the
lesson records who proposed it and the child's confirmation.
"""

from __future__ import annotations

from functools import partial

import pytest
import yaml

from phyagentos.agent.recovery import RecoveryPlanner
from phyagentos.agent.retarget import TargetChooser
from phyagentos.agent.reviser import ModelReviser
from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.llm import make_client
from phyagentos.protocol import Diagnosis, SessionRecord, Workspace
from phyagentos.protocol.lifecycle import utc_now
from phyagentos.runtime.reach_query import answer_reach_query

SCENE = {"objects": [{"name": "cube", "rgba": [0.85, 0.12, 0.1, 1], "class": "block"}],
         "regions": [{"name": "goal", "center": [0.35, 0.2], "half_extents": [0.06, 0.06]}],
         "randomise": {"seed": 8, "distractors": [0, 0]}}
PICK = {"id": "pick_cube", "skill": "pick", "target": "so101_tabletop", "params": {"object": "cube"},
        "accept": {"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}}}
# within both arms' reach: the graph check passes it for the SO-101
PLACE = {"id": "place_cube", "skill": "place", "target": "so101_tabletop", "params": {"object": "cube", "region": "goal"},
         "accept": {"inside": {"object": "cube", "region": "goal"}, "released": "cube"}, "depends_on": ["pick_cube"]}


def run(tmp_path, name, reviser_for):
    graph = tmp_path / f"{name}.yaml"
    graph.write_text(yaml.safe_dump({"version": 1, "name": name, "scene": SCENE, "nodes": [PICK, PLACE]}))
    ws = Workspace.create(tmp_path / name)
    report = run_goal_graph(graph, ws.root, seed=0, reviser=reviser_for(ws))
    return report, ws, [ws.load_session(s.session_id) for s in report.sessions]


@pytest.mark.sim
def test_a_node_out_of_its_targets_reach_is_moved_by_the_model_to_the_target_that_reaches_it(tmp_path):
    # the rule ladder: nothing addresses ik_unreachable; the run fails on the SO-101
    report, _, recs = run(tmp_path, "rules", lambda ws: None)
    assert not report.succeeded and report.node_states["place_cube"] == "blocked"
    (only,) = recs
    assert only.target == "so101_tabletop" and only.attempts[-1].verdict.diagnosis.cause == "ik_unreachable"

    chooser: dict = {}

    def model(ws):
        chooser["c"] = TargetChooser(ws, reach=partial(answer_reach_query, root=ws.root))
        return ModelReviser(make_client(), fallback=RecoveryPlanner(), retarget=chooser["c"])

    report, ws, recs = run(tmp_path, "model", model)
    assert report.succeeded, [(r.session_id, r.target, r.state) for r in recs]
    failed, child, place = recs
    assert failed.target == "so101_tabletop" and failed.state == "replanned"
    assert failed.attempts[-1].verdict.diagnosis.cause == "ik_unreachable"
    rev = failed.attempts[-1].verdict.revision
    assert rev.proposed_by == "model" and rev.target == "franka_tabletop"
    assert rev.strategy == "model:switch_target_to_franka_tabletop"
    # the selector's record: why the failed target is out, why the chosen one fits, why the others do not
    assert rev.selection["so101_tabletop"] == "failed here: ik_unreachable"
    assert rev.selection["franka_tabletop"].startswith("chosen: fits") and "IK" in rev.selection["franka_tabletop"]
    assert rev.selection["crafter"].startswith("lacks")
    (call,) = rev.model_calls
    assert call.role == "reviser" and call.outcome == "accepted" and "switch_target" in call.output
    # compiled as a child session like any replan: same node, skill and criteria, on the other target
    assert child.parent_session_id == failed.session_id and child.node == failed.node and child.skill == "pick"
    assert child.target == "franka_tabletop" and child.recovery == rev and child.accept == failed.accept
    assert child.state == "succeeded"
    # the simulator agrees (scoring-side read of the privileged channel): the Franka holds the object, lifted
    truth = yaml.safe_load((ws.root / child.attempts[-1].evidence / "ground_truth.yaml").read_text())["terminal"]
    assert "cube" in truth["held"] and truth["objects"]["cube"]["position"][2] > 0.05
    # the node downstream follows the world it depends on: the place runs on the Franka too
    assert place.node == "place_cube" and place.target == "franka_tabletop" and place.state == "succeeded"
    truth = yaml.safe_load((ws.root / place.attempts[-1].evidence / "ground_truth.yaml").read_text())["terminal"]
    x, y, _ = truth["objects"]["cube"]["position"]
    assert abs(x - 0.35) <= 0.06 and abs(y - 0.2) <= 0.06 and not truth["held"]
    # the lesson: proposed by the model, a re-target, confirmed by the child's verdict
    lesson = next(entry for entry in ws.read("LESSONS").data.lessons if entry.strategy == rev.strategy)
    assert lesson.proposed_by == "model" and lesson.target == "franka_tabletop" and lesson.verified
    assert lesson.verified_by == [child.session_id] and "on target franka_tabletop" in lesson.correction


def test_a_node_with_upstream_nodes_is_never_moved_to_another_world(tmp_path):
    now = utc_now()
    rec = SessionRecord(session_id="r1-place_cube-1", run_id="r1", node="place_cube", skill="place",
                        target="so101_tabletop", parameters={"object": "cube", "region": "goal"},
                        accept={"inside": {"object": "cube", "region": "goal"}}, depends_on=["pick_cube"],
                        created_at=now, updated_at=now)
    chooser = TargetChooser(Workspace.create(tmp_path / "ws"))
    sel = chooser.choose(rec, cause="ik_unreachable")
    assert sel.target is None and "another target is another world" in sel.reasons["*"]

    class Never:  # the model is not asked when nothing can change the outcome
        provider = model = "never"

        def complete(self, *a, **k):
            raise AssertionError("no model call expected")

    reviser = ModelReviser(Never(), retarget=chooser)
    unreachable = Diagnosis(cause="ik_unreachable", category="planning", summary="IK did not converge")
    assert reviser.menu(rec, unreachable) == []
    assert reviser.plan(rec, unreachable) is None


def test_the_reach_answer_for_a_randomised_world_rests_on_the_perceived_position_not_the_drawn_one():
    # seed 8 draws the object at about (0.66, 0.13), within the Franka's reach; the answer must
    # follow what was perceived (built from the drawn world, the object moved to that position)
    from phyagentos.protocol.reach import ReachQuery

    def ask(xy):
        return answer_reach_query(ReachQuery(target="franka_tabletop", driver="mujoco_franka", scene=SCENE,
                                             positions={"cube": xy}, pick="cube")).status

    assert ask([0.657, 0.13]) == "reachable"
    assert ask([1.4, 0.0]) == "unreachable"
