"""The model reviser on real MuJoCo runs: a corrective node inserted upstream (re-pick) and a
skill switched (place -> place_at), each proposed by the real offline model under a schema of
only the revisions that can change the outcome, validated, and kept with its model call in
the sessions' contexts."""

from __future__ import annotations

import pytest
import yaml

from phyagentos.agent.recovery import RecoveryPlanner
from phyagentos.agent.reviser import ModelReviser
from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.llm import make_client
from phyagentos.protocol import Workspace

pytestmark = pytest.mark.sim

CUBE = {"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.5, -0.2], "rgba": [0.8, 0.1, 0.1, 1]}
PICK = {"id": "pick_cube", "skill": "pick", "params": {"object": "cube"},
        "accept": {"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}}}


def place(node_id, region, after):
    return {"id": node_id, "skill": "place", "params": {"object": "cube", "region": region},
            "accept": {"inside": {"object": "cube", "region": region}, "released": "cube"}, "depends_on": [after]}


def run(tmp_path, scene, nodes, reviser):
    graph = tmp_path / "g.yaml"
    graph.write_text(yaml.safe_dump({"version": 1, "name": "revised", "defaults": {"target": "franka_tabletop"},
                                     "scene": scene, "nodes": nodes}))
    report = run_goal_graph(graph, tmp_path / "ws", seed=0, reviser=reviser)
    ws = Workspace.open(tmp_path / "ws")
    return report, [ws.load_session(s.session_id) for s in report.sessions]


@pytest.fixture
def reviser():
    return ModelReviser(make_client(), fallback=RecoveryPlanner())


def test_a_place_whose_goal_collides_is_switched_by_the_model_to_an_off_centre_place_at(tmp_path, reviser):
    # A 30 cm column stands in the middle of a long region: every place pose over the centre
    # collides (goal_in_collision). The rule ladder's approach heights cannot move it (it
    # fails this run: see docs/agent.md); another skill for the same goal, a place_at in an
    # outer cell of the region, can.
    scene = {"objects": [CUBE], "regions": [{"name": "goal", "center": [0.5, 0.25], "half_extents": [0.15, 0.06]}],
             "obstacles": [{"name": "column", "center": [0.5, 0.25, 0.15], "half_extents": [0.02, 0.02, 0.15]}]}
    report, recs = run(tmp_path, scene, [PICK, place("place_cube", "goal", "pick_cube")], reviser)
    assert report.succeeded, [(r.session_id, r.skill, r.state, r.recovery and r.recovery.strategy) for r in recs]
    first = next(r for r in recs if r.node == "place_cube" and r.parent_session_id is None)
    assert first.attempts[-1].verdict.diagnosis.cause == "goal_in_collision"
    switched = next(r for r in recs if r.skill == "place_at")
    rev = switched.recovery
    assert rev.strategy == "model:switch_to_place_at" and rev.proposed_by == "model"
    assert rev.cause == "goal_in_collision" and rev.parameters["slots"] == 3 and rev.parameters["slot"] in (0, 2)
    assert switched.node == "place_cube" and switched.accept == first.accept and switched.state == "succeeded"
    # the model call behind the switch: in the revision, the child's context and the revised session's context
    (call,) = rev.model_calls
    assert call.role == "reviser" and call.outcome == "accepted" and call.provider == "llama.cpp"
    assert "switch_skill" in call.output and call.prompt_tokens > 0 and call.parameters["temperature"] == 0.0
    assert call in switched.context.model_calls
    parent = next(r for r in recs if r.session_id == switched.parent_session_id)
    assert call in parent.context.model_calls
    # the lesson says who proposed the switch and that the child's verdict confirmed it
    lessons = Workspace.open(tmp_path / "ws").read("LESSONS").data
    lesson = next(entry for entry in lessons.lessons if entry.strategy == "model:switch_to_place_at")
    assert lesson.proposed_by == "model" and lesson.skill == "place_at" and lesson.cause == "goal_in_collision"
    assert lesson.verified and lesson.confirmations == 1 and lesson.verified_by == [switched.session_id]
    assert lesson.provenance == [parent.session_id] and "run skill place_at" in lesson.correction
    # the rule ladder's corrections along the way (if any) are recorded as the rules'
    assert all(entry.proposed_by == "rules" for entry in [*lessons.lessons, *lessons.candidates]
               if not entry.strategy.startswith("model:"))
    assert not any(c.strategy == "model:switch_to_place_at" for c in lessons.candidates)


def test_an_empty_hand_makes_the_model_insert_a_re_pick_upstream(tmp_path, reviser):
    # Pick, place, then place the same cube again: the second place starts with an empty hand
    # (precondition_unmet); the only revision that can change that is re-opening the pick.
    goal2 = {"name": "goal2", "center": [0.62, -0.25], "half_extents": [0.06, 0.06]}
    scene = {"objects": [CUBE], "regions": [{"name": "goal", "center": [0.5, 0.25], "half_extents": [0.08, 0.08]},
                                            goal2]}
    nodes = [PICK, place("place_cube", "goal", "pick_cube"), place("place_again", "goal2", "place_cube")]
    report, recs = run(tmp_path, scene, nodes, reviser)
    assert report.succeeded, [(r.session_id, r.skill, r.state, r.recovery and r.recovery.strategy) for r in recs]
    failed = next(r for r in recs if r.node == "place_again" and r.state == "replanned")
    verdict = failed.attempts[-1].verdict
    assert verdict.diagnosis.cause == "precondition_unmet"
    rev = verdict.revision
    assert rev.strategy == "model:re_pick_upstream" and rev.reopen == "pick_cube" and rev.proposed_by == "model"
    repick = next(r for r in recs if r.session_id == failed.child_session_ids[0])
    assert repick.node == "pick_cube" and repick.recovery == rev and repick.state == "succeeded"
    assert [c.outcome for c in repick.context.model_calls if c.role == "reviser"] == ["accepted"]
    assert next(r for r in recs if r.node == "place_again" and r.state == "succeeded")
    # (another failure of the world along the way, e.g. a slip upstream, is revised too; this one was the model's)
    assert [p["proposed_by"] for p in reviser.proposals if p["session"] == failed.session_id] == ["model"]
