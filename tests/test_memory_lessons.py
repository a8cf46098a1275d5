"""LESSONS.md: candidates until a verdict confirms them; merging, refutation, bounded growth."""

from __future__ import annotations

import pytest

from phyagentos.agent.memory import lessons as lessons_mod
from phyagentos.agent.memory.conditions import Conditions
from phyagentos.agent.memory.lessons import LessonBook
from phyagentos.protocol import Attempt, Diagnosis, Revision, SessionContext, SessionRecord, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now

COND = Conditions(goal="g/pick_cube", skill="pick", target="franka_tabletop", embodiment="mujoco_franka",
                  object="cube", object_class="box-medium", risk_factors=("slipped_before",))
SLIP = Diagnosis(cause="object_slipped", category="execution", summary="slipped",
                 evidence=["evidence/r-pick_cube-1/trace.jsonl"])
FIRM = Revision(strategy="firmer_grip", cause="object_slipped", step=1, parameters={"grip_force_n": 40.0})


@pytest.fixture
def book(tmp_path):
    return LessonBook(Workspace.create(tmp_path / "ws"))


def rec(sid, *, params=None, parent=None, recovery=None, verdict=None, context=None) -> SessionRecord:
    now = utc_now()
    attempts = [Attempt(number=1, started_at=now, verdict=verdict)] if verdict else []
    return SessionRecord(session_id=sid, run_id="r", node="pick_cube", skill="pick", target="franka_tabletop",
                         parameters=params or {"object": "cube"}, parent_session_id=parent, recovery=recovery,
                         context=context, attempts=attempts, created_at=now, updated_at=now)


def verdict(kind, diagnosis=None, revision=None):
    return Verdict(verdict=kind, reason=kind, at=utc_now(), diagnosis=diagnosis, revision=revision,
                   evidence=["evidence/x/terminal.yaml"])


def test_a_proposed_correction_is_a_candidate_not_a_lesson(book):
    parent, child = rec("r-pick_cube-1"), rec("r-pick_cube-2", parent="r-pick_cube-1", recovery=FIRM)
    lid = book.propose(parent=parent, child=child, diagnosis=SLIP, revision=FIRM, conditions=COND)
    doc = book.document()
    assert doc.lessons == [] and [c.id for c in doc.candidates] == [lid]
    cand = doc.candidates[0]
    assert not cand.verified and cand.cause == "object_slipped" and cand.revision == {"grip_force_n": 40.0}
    assert cand.provenance == ["r-pick_cube-1"] and cand.evidence == SLIP.evidence
    assert cand.scope == {"embodiment": "mujoco_franka", "skill": "pick", "object_class": "box-medium",
                          "risk_factors": ["slipped_before"]}
    assert book.retrieve(COND) == []  # never retrieved before a verdict confirms it


def test_a_confirming_verdict_makes_it_a_verified_lesson(book):
    parent, child = rec("r-pick_cube-1"), rec("r-pick_cube-2", parent="r-pick_cube-1", recovery=FIRM)
    lid = book.propose(parent=parent, child=child, diagnosis=SLIP, revision=FIRM, conditions=COND)
    assert book.resolve(child, verdict("success"), COND, history=[parent]) == [lid]
    doc = book.document()
    (lesson,) = doc.lessons
    assert doc.candidates == []
    assert lesson.verified and lesson.verified_by == ["r-pick_cube-2"] and lesson.confirmations == 1
    assert "evidence/x/terminal.yaml" in lesson.evidence and "grip_force_n=40.0" in lesson.correction
    assert [entry.id for entry in book.retrieve(COND)] == [lid]


def test_a_refuting_verdict_keeps_it_a_candidate(book):
    parent, child = rec("r-pick_cube-1"), rec("r-pick_cube-2", parent="r-pick_cube-1", recovery=FIRM)
    book.propose(parent=parent, child=child, diagnosis=SLIP, revision=FIRM, conditions=COND)
    book.resolve(child, verdict("failure"), COND, history=[parent])
    doc = book.document()
    assert doc.lessons == [] and doc.candidates[0].refutations == 1
    assert doc.candidates[0].refuted_by == ["r-pick_cube-2"]


def test_the_same_correction_learned_twice_merges_and_counts(book):
    for run in ("a", "b"):
        parent = rec(f"{run}-pick_cube-1")
        child = rec(f"{run}-pick_cube-2", parent=parent.session_id, recovery=FIRM)
        book.propose(parent=parent, child=child, diagnosis=SLIP, revision=FIRM, conditions=COND)
        book.resolve(child, verdict("success"), COND, history=[parent])
    (lesson,) = book.document().lessons
    assert lesson.confirmations == 2 and lesson.verified_by == ["a-pick_cube-2", "b-pick_cube-2"]
    assert lesson.provenance == ["a-pick_cube-1", "b-pick_cube-1"]


def test_backing_off_is_situational_and_not_part_of_the_lesson(book):
    revision = FIRM.model_copy(update={"parameters": {"grip_force_n": 40.0, "backoff_m": 0.1, "settle_s": 0.5}})
    parent, child = rec("r-pick_cube-1"), rec("r-pick_cube-2", parent="r-pick_cube-1", recovery=revision)
    book.propose(parent=parent, child=child, diagnosis=SLIP, revision=revision, conditions=COND)
    book.resolve(child, verdict("success"), COND, history=[parent])
    assert book.document().lessons[0].revision == {"grip_force_n": 40.0}


def test_two_replans_verify_the_combination_not_the_step_that_did_not_suffice(book):
    moved = Diagnosis(cause="object_moved", category="perception", summary="moved")
    collision = Diagnosis(cause="collision", category="execution", summary="hit")
    look = Revision(strategy="re_observe", cause="object_moved", parameters={"reobserve_samples": 1})
    turn = Revision(strategy="another_approach_direction", cause="collision", parameters={"grasp_candidate": 1})
    root = rec("r-pick_cube-1", verdict=verdict("replan", moved, look))
    mid = rec("r-pick_cube-2", params={"object": "cube", "reobserve_samples": 1}, parent=root.session_id,
              recovery=look, verdict=verdict("replan", collision, turn))
    last = rec("r-pick_cube-3", params={"object": "cube", "reobserve_samples": 1, "grasp_candidate": 1},
               parent=mid.session_id, recovery=turn)
    book.propose(parent=root, child=mid, diagnosis=moved, revision=look, conditions=COND)
    book.resolve(mid, verdict("replan"), COND, history=[root])
    book.propose(parent=mid, child=last, diagnosis=collision, revision=turn, conditions=COND)
    book.resolve(last, verdict("success"), COND, history=[root, mid])
    doc = book.document()
    by_cause = {entry.cause: entry for entry in doc.lessons}
    assert by_cause["collision"].revision == {"grasp_candidate": 1}
    assert by_cause["object_moved"].revision == {"reobserve_samples": 1, "grasp_candidate": 1}
    assert by_cause["object_moved"].strategy == "re_observe+another_approach_direction"
    assert by_cause["object_moved"].provenance == ["r-pick_cube-1"]
    (alone,) = doc.candidates  # re-observing alone did not do it: still a refuted candidate
    assert alone.revision == {"reobserve_samples": 1} and alone.refutations == 1


def test_applied_lessons_are_confirmed_or_refuted_by_later_first_attempts(book):
    parent, child = rec("r-pick_cube-1"), rec("r-pick_cube-2", parent="r-pick_cube-1", recovery=FIRM)
    lid = book.propose(parent=parent, child=child, diagnosis=SLIP, revision=FIRM, conditions=COND)
    book.resolve(child, verdict("success"), COND, history=[parent])
    from phyagentos.protocol import ContextItem

    ctx = SessionContext(items=[ContextItem(kind="lesson", id=lid, summary="s", applied={"grip_force_n": 40.0})],
                         built_at=utc_now())
    book.resolve(rec("s-pick_cube-1", context=ctx), verdict("success"), COND)
    book.resolve(rec("t-pick_cube-1", context=ctx), verdict("replan"), COND)
    (lesson,) = book.document().lessons
    assert (lesson.confirmations, lesson.refutations) == (2, 1)
    assert lesson.verified_by[-1] == "s-pick_cube-1" and lesson.refuted_by == ["t-pick_cube-1"]
    book.resolve(rec("u-pick_cube-1", context=ctx), verdict("failure"), COND)
    assert book.retrieve(COND) == []  # refuted as often as confirmed: no longer applied


def test_growth_is_bounded(book, monkeypatch):
    monkeypatch.setattr(lessons_mod, "MAX_CANDIDATES", 3)
    monkeypatch.setattr(lessons_mod, "MAX_REFS", 2)
    for i in range(6):
        revision = FIRM.model_copy(update={"parameters": {"grip_force_n": 30.0 + i}})
        book.propose(parent=rec(f"p{i}-pick_cube-1"), child=rec(f"p{i}-pick_cube-2"), diagnosis=SLIP,
                     revision=revision, conditions=COND)
    for i in range(4):  # the same candidate proposed again: provenance keeps the latest two
        book.propose(parent=rec(f"q{i}-pick_cube-1"), child=rec(f"q{i}-pick_cube-2"), diagnosis=SLIP, revision=FIRM,
                     conditions=COND)
    doc = book.document()
    assert len(doc.candidates) == 3
    firm = next(c for c in doc.candidates if c.revision == {"grip_force_n": 40.0})
    assert firm.provenance == ["q2-pick_cube-1", "q3-pick_cube-1"]
