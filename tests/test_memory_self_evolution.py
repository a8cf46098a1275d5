"""Self-evolution, measured: the same perturbed episodes with empty memory, then with the
memory the first pass consolidated (frozen). The full measurement is bench/self_evolution.py."""

from __future__ import annotations

import pytest

from phyagentos.protocol import Workspace
from phyagentos.self_evolution import PERTURBATION_KINDS, measure, perturbed_episodes

pytestmark = pytest.mark.sim


def test_second_pass_with_consolidated_memory_succeeds_more_often_at_the_first_attempt(tmp_path):
    episodes = perturbed_episodes(seeds=(0, 1), kinds=PERTURBATION_KINDS)
    first, second = measure(episodes, tmp_path)
    print(f"\npass 1 (empty memory): first-attempt {first.first_attempt_rate:.0%}, final {first.final_rate:.0%}, "
          f"{first.sessions} sessions; pass 2 (memory): first-attempt {second.first_attempt_rate:.0%}, "
          f"final {second.final_rate:.0%}, {second.sessions} sessions")
    assert len(first.episodes) == len(second.episodes) == 8
    assert second.first_attempt_rate > first.first_attempt_rate
    for p in (first, second):
        assert p.final_rate >= p.first_attempt_rate
    # every perturbation genuinely fails without memory, and recovery rescues what it can
    assert {e.kind for e in first.episodes if not e.first_attempt_success} == set(PERTURBATION_KINDS)
    assert first.final_rate > first.first_attempt_rate
    # what pass 2 used is traceable to verified lessons and to the pass-1 sessions that verified them
    memory = Workspace.open(first.workspace).read("LESSONS").data
    assert memory.lessons and all(l.verified and l.verified_by for l in memory.lessons)
    pass1_sessions = {s for e in first.episodes for s in e.session_ids}
    by_id = {l.id: l for l in memory.lessons}
    used = [i for e in second.episodes for i in e.memory_items]
    assert used and all(i in by_id and set(by_id[i].verified_by) <= pass1_sessions for i in used)
    # pass 2 was a measurement: its memory documents were not written
    frozen = Workspace.open(second.workspace)
    for key in ("LESSONS", "KNOWLEDGE", "SKILL"):
        assert frozen.path(key).read_bytes() == Workspace.open(first.workspace).path(key).read_bytes()
