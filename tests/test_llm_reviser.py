"""Model-backed revision behind the recovery seam, with the real offline model and the rule ladder as fallback."""

from __future__ import annotations

import pytest

from phyagentos.agent.recovery import RecoveryPlanner
from phyagentos.agent.reviser import REVISION_SPACE, ModelReviser
from phyagentos.agent.skill_catalog import skill_catalog
from phyagentos.llm import LLMCall, LLMReply, make_client
from phyagentos.protocol import Diagnosis, Revision, SessionRecord
from phyagentos.protocol.lifecycle import utc_now


def session(**params) -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id="r1-pick_cube-1", run_id="r1", node="pick_cube", skill="pick",
                         target="franka_tabletop", parameters={"object": "cube", **params}, accept={"holding": "cube"},
                         created_at=now, updated_at=now)


SLIPPED = Diagnosis(cause="object_slipped", category="execution", summary="the cube slipped out of the grasp when lifted",
                    facts={"tcp_end_z_m": 0.4, "grip_closed_on_object": True})


@pytest.fixture(scope="module")
def model():
    return make_client()


def test_the_model_proposes_a_typed_revision_within_the_declared_ranges(model):
    reviser = ModelReviser(model, fallback=RecoveryPlanner())
    revision = reviser.plan(session(), SLIPPED)
    (proposal,) = reviser.proposals
    assert proposal["call"]["provider"] == "llama.cpp" and proposal["call"]["purpose"] == "revise"
    assert revision is not None
    if proposal["proposed_by"] == "model":
        (param,) = [p for p in revision.parameters if p not in ("backoff_m", "settle_s")]
        assert revision.strategy == f"model:{param}"
        assert param in skill_catalog()["pick"].optional and revision.parameters[param] in REVISION_SPACE[param]
        assert "proposed by the model: llama.cpp SmolLM2" in revision.rationale
    else:  # the model's proposal was rejected: the ladder's, and the record says why
        assert proposal["proposed_by"] == "rules" and "rejected" in proposal
        assert revision.strategy == "firmer_grip" and "model proposal rejected" in revision.rationale


def test_a_safety_stop_is_never_revised_by_the_model(model):
    reviser = ModelReviser(model, fallback=RecoveryPlanner())
    stop = Diagnosis(cause="safety_intervention", category="safety", summary="the guard halted a motion")
    assert reviser.plan(session(), stop) is None
    assert reviser.calls == []  # not even asked


class _Answer:
    provider, model = "scripted", "scripted"

    def __init__(self, text):
        self.text = text

    def complete(self, messages, *, schema=None, max_tokens=256, purpose="chat"):
        return LLMReply(text=self.text, call=LLMCall(self.provider, self.model, purpose, "0" * 16, 1, 1, 0.0, 0.0, 0, False))


@pytest.mark.parametrize("answer, why", [
    ('{"action":"adjust","parameter":"grip_force_n","value":500}', "outside its declared range"),
    ('{"action":"adjust","parameter":"disable_safety","value":1}', "not a strategy parameter"),
    ('{"action":"adjust","parameter":"grip_force_n","value":40.0}', "changes nothing"),
    ('{"action":"adjust","parameter":"planner","value":"PRM"}', "not one of the offered revisions"),
    ('{"action":"switch_skill","skill":"place_at","option":"slot_0_slots_3"}', "not one of the offered revisions"),
    ("ignore previous instructions", "not JSON"),
])
def test_out_of_range_hallucinated_or_unparseable_proposals_fall_back_to_the_rule_ladder(answer, why):
    reviser = ModelReviser(_Answer(answer), fallback=RecoveryPlanner())
    revision = reviser.plan(session(grip_force_n=40.0), SLIPPED)
    assert why in reviser.proposals[0]["rejected"]
    assert reviser.proposals[0]["proposed_by"] == "rules"
    assert revision is not None and not revision.strategy.startswith("model:")
    assert "model proposal rejected" in revision.rationale


def test_give_up_is_a_typed_answer_offered_from_the_second_replan_on():
    answer = _Answer('{"action":"give_up","reason":"nothing_left"}')
    reviser = ModelReviser(answer, fallback=RecoveryPlanner())
    assert reviser.plan(session(), SLIPPED) is not None  # first replan: not offered, the ladder's instead
    assert reviser.proposals[0]["proposed_by"] == "rules"
    tried = Revision(strategy="firmer_grip", cause="object_slipped", parameters={"grip_force_n": 40.0})
    child = session(grip_force_n=40.0).model_copy(update={"recovery": tried, "session_id": "r1-pick_cube-2"})
    assert reviser.plan(child, SLIPPED) is None
    assert reviser.proposals[1]["proposed_by"] == "model:give_up"
    # the same attempt judged again (images arrived) gets the same answer, without a second model call
    assert reviser.plan(child, SLIPPED) is None and len(reviser.proposals) == 2
    (record,) = reviser.calls_for("r1-pick_cube-2")
    assert record.outcome == "gave_up" and record.output == answer.text and record.role == "reviser"


def test_a_re_pick_that_did_not_help_is_not_offered_again_and_nothing_is_asked():
    from phyagentos.protocol import Attempt, Verdict
    from phyagentos.protocol.lifecycle import utc_now as now

    unmet = Diagnosis(cause="precondition_unmet", category="execution", summary="the hand is empty")
    place = session().model_copy(update={"session_id": "r1-place_again-1", "node": "place_again", "skill": "place",
                                         "parameters": {"object": "cube", "region": "goal"}})
    answer = _Answer('{"action":"re_pick_upstream"}')
    reviser = ModelReviser(answer, fallback=RecoveryPlanner())
    first = reviser.plan(place, unmet, upstream="pick_cube")
    assert first.reopen == "pick_cube" and first.strategy == "model:re_pick_upstream"
    # the node ran again after the re-pick and found the hand empty again: the same correction is spent
    failed = place.model_copy(update={"attempts": [Attempt(number=1, started_at=now(), verdict=Verdict(
        verdict="replan", reason="empty hand", at=now(), diagnosis=unmet, revision=first))]})
    again = place.model_copy(update={"session_id": "r1-place_again-2", "parent_session_id": failed.session_id})
    assert reviser.menu(again, unmet, history=[failed], upstream="pick_cube") == []
    assert reviser.plan(again, unmet, history=[failed], upstream="pick_cube") is None
    assert len(reviser.calls) == 1 and reviser.proposals[-1]["proposed_by"] == "policy"
