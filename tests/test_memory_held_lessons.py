"""A lesson whose cause belongs to the scene (a collision of the goal, an unseen object) is
never applied to a first attempt: it is held in the session's context and becomes the
first revision when that cause recurs; that revision's verdict confirms or refutes it."""

from __future__ import annotations

import pytest

from phyagentos.agent.memory import ContextBuilder, LessonBook
from phyagentos.agent.recovery import MEMORY, RecoveryPlanner
from phyagentos.protocol import Attempt, Diagnosis, Revision, SessionRecord, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now

SCENE = {"objects": [{"name": "cube", "size_m": [0.04, 0.04, 0.04]}]}
#: The second rung of the goal-in-collision ladder, learned on the cube.
PLACEMENT = Revision(strategy="another_placement_pose", cause="goal_in_collision", step=2,
                     parameters={"approach_height_m": 0.05})
COLLIDES = Diagnosis(cause="goal_in_collision", category="policy", summary="the placement pose collides")


@pytest.fixture
def ws(tmp_path):
    return Workspace.create(tmp_path / "ws")


def rec(sid, params, *, recovery=None, context=None, verdict=None) -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id=sid, run_id="r", node="place_cube", skill="place", target="franka_tabletop",
                         parameters={"object": "cube", "region": "bin", **params}, recovery=recovery, context=context,
                         attempts=[Attempt(number=1, started_at=now, verdict=verdict)] if verdict else [],
                         created_at=now, updated_at=now)


def verdict(kind: str, revision: Revision | None = None) -> Verdict:
    return Verdict(verdict=kind, reason=kind, at=utc_now(), diagnosis=COLLIDES if kind != "success" else None,
                   revision=revision)


def learn(ws) -> str:
    cond = ContextBuilder(ws).conditions(goal="learn/place", skill="place", target="franka_tabletop",
                                         parameters={"object": "cube"}, scene=SCENE)
    book = LessonBook(ws)
    parent = rec("l-1", {})
    child = rec("l-2", PLACEMENT.parameters, recovery=PLACEMENT)
    book.propose(parent=parent, child=child, diagnosis=COLLIDES, revision=PLACEMENT, conditions=cond)
    book.resolve(child, verdict("success"), cond, history=[parent])
    return LessonBook(ws).document().lessons[0].id


def first_attempt(ws):
    params, ctx = ContextBuilder(ws).build(goal="eval/place", skill="place", target="franka_tabletop",
                                           parameters={"object": "cube", "region": "bin"}, scene=SCENE)
    return params, ctx


def test_a_scene_lesson_is_held_not_applied_up_front(ws):
    lid = learn(ws)
    params, ctx = first_attempt(ws)
    assert params == {"object": "cube", "region": "bin"} and ctx.parameters == {}
    [item] = [i for i in ctx.items if i.kind == "lesson"]
    assert item.id == lid and item.applied == {} and "held until goal_in_collision recurs" in item.summary
    assert item.held == {"cause": "goal_in_collision", "strategy": "another_placement_pose",
                         "parameters": PLACEMENT.parameters, "skill": None}


def test_the_held_lesson_is_the_first_revision_when_its_cause_recurs_and_the_ladder_goes_on_past_it(ws):
    lid = learn(ws)
    _, ctx = first_attempt(ws)
    failed = rec("e-1", {}, context=ctx)
    revision = RecoveryPlanner().plan(failed, COLLIDES)
    assert revision is not None and revision.proposed_by == MEMORY
    assert revision.strategy == "another_placement_pose" and revision.step == 2  # its rung on the ladder
    assert revision.parameters == PLACEMENT.parameters and lid in revision.rationale
    # it failed again: the ladder goes on past the held lesson's rung (here: nothing left)
    failed_child = rec("e-2", PLACEMENT.parameters, recovery=revision, context=ctx,
                       verdict=verdict("replan", revision))
    history = [failed.model_copy(update={"attempts": [Attempt(number=1, started_at=utc_now(),
                                                              verdict=verdict("replan", revision))]})]
    assert RecoveryPlanner().plan(failed_child, COLLIDES, history=history) is None


def test_a_held_lesson_waits_for_its_own_cause(ws):
    learn(ws)
    _, ctx = first_attempt(ws)
    slipped = Diagnosis(cause="placement_off", category="execution", summary="off the region")
    revision = RecoveryPlanner().plan(rec("e-1", {}, context=ctx), slipped)
    assert revision is not None and revision.proposed_by == "rules"


def test_without_a_held_lesson_the_ladder_starts_at_its_first_rung(ws):
    revision = RecoveryPlanner().plan(rec("e-1", {}), COLLIDES)
    assert revision is not None and revision.proposed_by == "rules" and revision.step == 1


@pytest.mark.parametrize("outcome", ["success", "failure"])
def test_the_replan_a_held_lesson_made_confirms_or_refutes_it(ws, outcome):
    lid = learn(ws)
    _, ctx = first_attempt(ws)
    failed = rec("e-1", {}, context=ctx)
    revision = RecoveryPlanner().plan(failed, COLLIDES)
    child = rec("e-2", revision.parameters, recovery=revision, context=ctx)
    cond = ContextBuilder(ws).conditions(goal="eval/place", skill="place", target="franka_tabletop",
                                         parameters={"object": "cube"}, scene=SCENE)
    book = LessonBook(ws)
    book.propose(parent=failed, child=child, diagnosis=COLLIDES, revision=revision, conditions=cond)
    book.resolve(child, verdict(outcome), cond, history=[failed])
    [lesson] = book.document().lessons
    assert lesson.id == lid
    assert (lesson.confirmations, lesson.refutations) == ((2, 0) if outcome == "success" else (1, 1))
