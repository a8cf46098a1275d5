"""Bench memory protocols (learn merges increments, frozen writes nothing back) and the error taxonomy."""

from __future__ import annotations

from phyagentos.bench.memory import MemoryPolicy, merge_knowledge, merge_lessons
from phyagentos.protocol import KnowledgeDoc, KnowledgeEntry, Lesson, LessonsDoc, Workspace


def entry(successes: int, attempts: int, provenance: list[str]) -> KnowledgeEntry:
    return KnowledgeEntry(id="pick-cube", pattern="pick cube top-down", successes=successes, attempts=attempts,
                          provenance=provenance)


def test_two_episodes_learning_from_one_snapshot_both_count():
    snapshot = KnowledgeDoc(entries=[entry(2, 3, ["s1"])])
    ep_a = KnowledgeDoc(entries=[entry(3, 4, ["s1", "a1"])])   # +1 success, +1 attempt
    ep_b = KnowledgeDoc(entries=[entry(2, 5, ["s1", "b1"])])   # +0 success, +2 attempts
    bench = merge_knowledge(snapshot, snapshot, ep_a)
    bench = merge_knowledge(bench, snapshot, ep_b)
    (e,) = bench.entries
    assert (e.successes, e.attempts) == (3, 6)
    assert e.provenance == ["s1", "a1", "b1"]


def test_a_candidate_confirmed_in_an_episode_becomes_a_lesson_of_the_bench():
    cand = Lesson(id="L1", objective="pick cube", evidence=["e1"], cause="slip", correction="grip 30 N")
    base = LessonsDoc(candidates=[cand])
    after = LessonsDoc(lessons=[cand.model_copy(update={"verified": True, "verified_by": ["s9"], "confirmations": 1})])
    merged = merge_lessons(base, base, after)
    assert [x.id for x in merged.lessons] == ["L1"] and merged.candidates == []
    assert merged.lessons[0].verified and merged.lessons[0].verified_by == ["s9"]


def test_frozen_memory_never_writes_back(tmp_path):
    bench = Workspace.create(tmp_path / "bench")
    episode = Workspace.create(tmp_path / "ep")
    policy = MemoryPolicy(mode="frozen", bench_root=bench.root, snapshot_dir=tmp_path / "snap")
    episode.update("KNOWLEDGE", lambda doc: doc.model_copy(update={"entries": [entry(1, 1, ["x"])]}))
    policy.before_episode(episode)
    policy.after_episode(episode)
    assert bench.read("KNOWLEDGE").data.entries == []


def test_learn_memory_flows_from_an_episode_into_the_next(tmp_path):
    bench = Workspace.create(tmp_path / "bench")
    policy = MemoryPolicy(mode="learn", bench_root=bench.root, snapshot_dir=tmp_path / "snap")
    first = Workspace.create(tmp_path / "ep1")
    policy.before_episode(first)
    first.update("KNOWLEDGE", lambda doc: doc.model_copy(update={"entries": [entry(1, 1, ["a"])]}))
    policy.after_episode(first)
    second = Workspace.create(tmp_path / "ep2")
    policy.before_episode(second)
    assert [e.successes for e in second.read("KNOWLEDGE").data.entries] == [1]


def test_error_taxonomy_prefers_the_verifiers_diagnosis_and_falls_back_to_codes_and_states():
    from phyagentos.bench.taxonomy import classify

    diag = {"category": "perception", "cause": "object_moved"}
    assert classify(state="replanned", error_code="grasp.missed", diagnosis=diag) == ("perception", "object_moved")
    assert classify(state="rejected", error_code=None, rejection_codes=["preflight.target_disabled"]) == \
        ("adapter", "preflight.target_disabled")
    assert classify(state="timed_out", error_code=None) == ("timeout", "timeout.execution")
    assert classify(state="failed", error_code="ik.unreachable") == ("policy", "ik.unreachable")
    assert classify(state="failed", error_code=None, events=[{"code": "safety.joint_limit"}]) == \
        ("safety", "safety.joint_limit")
    assert classify(state="failed", error_code=None) == ("verifier", "verdict.unsatisfied")
    assert classify(state="failed", error_code="quantum.flux") == ("other", "quantum.flux")
