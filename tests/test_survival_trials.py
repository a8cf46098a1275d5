"""Survival lessons are decided by a randomised with/without comparison, not by survivors."""

from __future__ import annotations

import pytest

from phyagentos.agent.memory.context_builder import ContextBuilder
from phyagentos.agent.memory.deaths import DeathBook, trial_arm, trial_decision
from phyagentos.bench.memory import merge_lessons
from phyagentos.protocol import LessonsDoc, SessionContext, SessionRecord, Trial, Workspace
from phyagentos.protocol.lifecycle import utc_now

THIRST = [{"kind": "game_vitals", "step": 100, "drink": 1}, {"kind": "game_damage", "step": 140, "adjacent": [],
                                                            "drink": 0}, {"kind": "game_death", "step": 149, "drink": 0,
                                                                          "food": 5, "energy": 5}]


def _session(sid: str, run_id: str, context: SessionContext | None = None) -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id=sid, run_id=run_id, node="collect_stone", skill="game_collect", target="crafter",
                         parameters={"material": "stone"}, context=context, created_at=now, updated_at=now)


def _walk(first: int, last: int) -> list[dict]:
    return [{"kind": "game_vitals", "step": first}, {"kind": "game_vitals", "step": last}]


def _build(ws: Workspace, run_id: str, *, trials: bool = True):
    return ContextBuilder(ws, trials=trials).build(goal="tech/collect_stone", skill="game_collect", target="crafter",
                                                   parameters={"material": "stone", "item": "stone"}, scene=None,
                                                   run_id=run_id)


def test_a_trial_decides_on_deaths_per_step_with_the_exact_poisson_rate_test():
    # no deaths in 3000 steps with it, 6 in 3000 without: P(X <= 0 | n=6, share 0.5) = 0.5**6
    state, p = trial_decision(Trial(steps_with=3000, deaths_with=0, steps_without=3000, deaths_without=6))
    assert state == "verified" and p == pytest.approx(0.5 ** 6)
    assert trial_decision(Trial(steps_with=3000, deaths_with=6, steps_without=3000, deaths_without=0))[0] == "refuted"
    assert trial_decision(Trial(steps_with=3000, deaths_with=2, steps_without=3000, deaths_without=3))[0] == "open"
    # too little exposure or too few deaths: no decision at all
    assert trial_decision(Trial(steps_with=500, deaths_with=0, steps_without=3000, deaths_without=6)) == ("open", None)
    assert trial_decision(Trial(steps_with=3000, deaths_with=0, steps_without=3000, deaths_without=3)) == ("open", None)
    # rates, not counts: 4 deaths in 12000 steps with it against 4 in 2000 without is fewer per step
    assert trial_decision(Trial(steps_with=12000, deaths_with=4, steps_without=2000, deaths_without=4))[0] == "verified"


def test_a_death_makes_a_candidate_that_only_runs_in_the_with_arm_apply_and_only_while_learning(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    book = DeathBook(ws)
    book.learn(_session("s-die", "r-0"), THIRST, ["evidence/s-die/trace.jsonl"])
    (cand,) = ws.read("LESSONS").data.candidates
    assert cand.cause == "death.thirst" and cand.revision == {"drink_below": 6} and cand.trial == Trial()
    arms = {}
    for k in range(40):
        run = f"r-{k}"
        params, ctx = _build(ws, run)
        (item,) = [i for i in ctx.items if i.id == cand.id]
        arms[run] = bool(item.applied)
        assert item.applied == ({"drink_below": 6} if trial_arm(run, cand.id) else {})
        assert params.get("drink_below") == item.applied.get("drink_below")
        assert "trial arm" in item.summary
    assert 10 < sum(arms.values()) < 30  # about half the runs apply it
    # a frozen measurement applies no open candidate, and does not list it
    params, ctx = _build(ws, "r-frozen", trials=False)
    assert "drink_below" not in params and not [i for i in ctx.items if i.id == cand.id]


def test_sessions_that_apply_a_candidate_and_live_do_not_verify_it_but_a_trial_does(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    book = DeathBook(ws)
    book.learn(_session("s-die", "r-0"), THIRST)
    lid = ws.read("LESSONS").data.candidates[0].id
    runs_with = [f"r-{k}" for k in range(200) if trial_arm(f"r-{k}", lid)][:6]
    runs_without = [f"r-{k}" for k in range(200) if not trial_arm(f"r-{k}", lid)][:6]
    # surviving sessions with the correction applied: the old rule verified it on the first
    for n, run in enumerate(runs_with[:4]):
        _, ctx = _build(ws, run)
        book.learn(_session(f"s-w{n}", run, ctx), _walk(0, 600))
    doc = ws.read("LESSONS").data
    assert doc.lessons == [] and doc.candidates[0].trial.sessions_with == 4
    assert doc.candidates[0].trial.steps_with == 2404 and doc.candidates[0].trial.deaths_with == 0
    # the control arm dies (thirst again: the same candidate, not a new one). The with-arm
    # had no death: p = P(X = 0 | n, share of steps with) = (share of steps without) ** n,
    # 0.062 after four deaths in 2396 steps, 0.053 after five: not yet; 0.046 after six
    for n, run in enumerate(runs_without[:6]):
        _, ctx = _build(ws, run)
        book.learn(_session(f"s-o{n}", run, ctx), [*_walk(0, 598), *THIRST[1:]])
        doc = ws.read("LESSONS").data
        if n == 3:
            assert doc.lessons == [] and doc.candidates[0].trial.p_value == pytest.approx((2396 / 4800) ** 4)
    (lesson,) = doc.lessons
    assert doc.candidates == [] and lesson.id == lid and lesson.verified and lesson.trial.deaths_without == 6
    assert lesson.verified_by == ["s-o5"] and lesson.trial.p_value == pytest.approx((6 * 599 / (2404 + 6 * 599)) ** 6)
    # once verified it applies to every game session, learning or frozen
    params, ctx = _build(ws, runs_without[5], trials=False)
    assert params["drink_below"] == 6 and "verified by its trial" in next(i for i in ctx.items if i.id == lid).summary


def test_trial_counts_of_two_episodes_add_up_when_a_learning_bench_merges_them():
    base = LessonsDoc()
    before = LessonsDoc(candidates=[])
    from phyagentos.protocol import Lesson  # noqa: PLC0415

    def lesson(trial):
        return Lesson(id="D1", objective="o", evidence=[], cause="death.thirst", correction="c",
                      revision={"drink_below": 6}, trial=trial)

    one = merge_lessons(base, before, LessonsDoc(candidates=[lesson(Trial(steps_with=500, sessions_with=2))]))
    start = LessonsDoc(candidates=[lesson(Trial())])
    two = merge_lessons(one, start, LessonsDoc(candidates=[lesson(Trial(steps_without=700, deaths_without=1,
                                                                        sessions_without=3))]))
    (merged,) = two.candidates
    assert (merged.trial.steps_with, merged.trial.steps_without, merged.trial.deaths_without) == (500, 700, 1)
    assert merged.trial.sessions_with + merged.trial.sessions_without == 5
