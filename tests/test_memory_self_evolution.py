"""Self-evolution, measured rather than assumed: memory learned on training worlds, frozen on
held-out worlds. Whether memory *helps* is a measurement (bench/self_evolution.py reports
it, including no gain); this test pins what must hold whatever the numbers are."""

from __future__ import annotations

import pytest

from phyagentos.agent.memory.conditions import OBSERVABLE_RISK_FACTORS
from phyagentos.bench.random_world import random_episodes
from phyagentos.bench.self_evolution import run_pass
from phyagentos.protocol import Workspace

pytestmark = pytest.mark.sim


def test_frozen_memory_on_held_out_worlds_is_traceable_and_never_written(tmp_path):
    train, heldout = random_episodes([3, 4]), random_episodes([10003])
    learn = run_pass("learn", train, tmp_path / "p1", use_memory=True, consolidate=True)
    frozen = run_pass("frozen", heldout, tmp_path / "p2", use_memory=True, consolidate=False,
                      memory_from=Workspace.open(learn.workspace))
    for p in (learn, frozen):
        for e in p.episodes:
            assert e.final_success >= e.first_attempt_success
    mem = Workspace.open(learn.workspace)
    # what was consolidated is keyed on observable properties only
    for entry in mem.read("KNOWLEDGE").data.entries:
        assert set(entry.conditions["risk_factors"]) <= set(OBSERVABLE_RISK_FACTORS)
        assert not {"mass", "friction", "mass_kg"} & set(entry.conditions["object_properties"])
    assert mem.read("KNOWLEDGE").data.entries  # verdicts were consolidated
    # what the frozen pass applied is a verified item traceable to training sessions
    lessons = {entry.id: entry for entry in mem.read("LESSONS").data.lessons}
    knowledge = {k.id: k for k in mem.read("KNOWLEDGE").data.entries}
    train_sessions = {s for e in learn.episodes for s in e.session_ids}
    for item in (i for e in frozen.episodes for i in e.memory_items):
        src = lessons.get(item) or knowledge.get(item)
        assert src is not None
        prov = set(getattr(src, "verified_by", None) or src.provenance)
        assert prov and prov <= train_sessions
    # the frozen pass was a measurement: its memory documents were not written
    held = Workspace.open(frozen.workspace)
    for key in ("LESSONS", "KNOWLEDGE", "SKILL"):
        assert held.path(key).read_bytes() == mem.path(key).read_bytes()
