"""Fault injection in the hand-off: SIGKILLs that land while sessions are claimed,
preflighted and prepared, not while they run.

``tests/test_supervisor_faults.py`` kills during holds of seconds, so its kills land
mostly in the runtime phase. Here every session is a 0 s hold: a session spends most of
its life being claimed (the runner's preflight runs while the claim is written) and
prepared (while ``start`` is written), so that is where the kills land. Nothing may be
lost or corrupted, no session may start twice, and a session that never started has
no attempt and never ticked.
"""

from __future__ import annotations

import os
import random
import signal
import time

import pytest
import yaml
from soak import scaled
from supervisor_util import Drill, assert_run_ended_whole, descends_from, make_workspace, presence, wait_for

pytestmark = [pytest.mark.sim, pytest.mark.soak]

SEED = 20261122
KILLS = scaled(20, 40)  # a third of them supervisors (see tests/soak.py)
NODES = 60
SUPERVISORS = 2


def test_sigkills_during_hand_offs_lose_nothing_and_start_nothing_twice(tmp_path):
    rng = random.Random(SEED)
    ws = make_workspace(tmp_path / "ws", targets=SUPERVISORS)
    graph = tmp_path / "handoffs.yaml"
    nodes = [{"id": f"n{i:02d}", "skill": "hold", "target": f"franka_{i % SUPERVISORS}",
              "params": {"duration_s": 0.0}, "accept": {"still": {"max_joint_motion_rad": 0.01}}}
             for i in range(NODES)]
    graph.write_text(yaml.safe_dump({"version": 1, "name": "handoff_faults", "description": "0 s holds",
                                     "nodes": nodes}))
    drill = Drill.start(ws, graph, tmp_path, supervisors=SUPERVISORS)
    run_id, sups = drill.run_id, drill.sups
    schedule = ["supervisor"] * (KILLS // 3) + ["runner"] * (KILLS - KILLS // 3)
    random.Random(SEED + 1).shuffle(schedule)
    kills = {"supervisor": 0, "runner": 0}
    try:
        while sum(kills.values()) < KILLS and run_id in ws.runs.active_ids():
            # aim: a session being claimed or preflighted (and, on the runner, prepared),
            # killed at once or a few milliseconds later (while ``start`` is written)
            handing = [sid for sid, _, _ in ws.active_sessions(("claimed", "preflight_checking"))]
            if not handing:
                time.sleep(0.0005)
                continue
            try:
                rec = ws.load_session(rng.choice(handing))
            except Exception:  # noqa: BLE001 - it moved on (archived, rewritten): aim again
                continue
            if rec.lease is None or rec.state not in ("claimed", "preflight_checking"):
                continue
            live = {p.pid: i for i, p in enumerate(sups)}
            owner = int(rec.lease.owner.split(":")[1])
            if owner not in live:
                continue
            kind = schedule[sum(kills.values())]
            runner = next((r.get("runner_pid") for r in presence(ws) if r.get("pid") == owner), None)
            if kind == "runner" and not (runner and descends_from(runner, owner)):
                continue
            time.sleep(rng.uniform(0.0, 0.006))
            k = live[owner]
            if kind == "supervisor":
                drill.kill_supervisor(k)
            else:
                try:
                    os.kill(runner, signal.SIGKILL)
                except ProcessLookupError:
                    continue
            kills[kind] += 1
        wait_for(lambda: run_id not in ws.runs.active_ids(), timeout=300, interval=0.25, what="the run to finish")
    finally:
        codes = drill.stop()
    assert codes == [0] * SUPERVISORS, drill.log.read_text()[-3000:]
    assert kills["supervisor"] >= 3 and kills["runner"] >= 6, kills

    records = assert_run_ended_whole(ws, run_id, {f"n{i:02d}" for i in range(NODES)})
    referenced = set()
    for rec in records:
        events = [t.event.split(":")[0] for t in rec.transitions]
        assert events.count("start") <= 1, (rec.session_id, events)  # actuation at most once
        if "start" not in events:
            assert rec.attempts == [], (rec.session_id, events)  # never started, never ticked
            continue
        attempt = rec.attempts[0]
        assert len(rec.attempts) == 1 and attempt.ended_at is not None and attempt.evidence
        bundle = yaml.safe_load((ws.root / attempt.evidence / "bundle.yaml").read_text())
        assert bundle["session_id"] == rec.session_id and "terminal" in bundle["files"]
        if attempt.outcome != "unknown":  # a session that ran to its end was prepared and ticked
            assert "initial" in bundle["files"] and bundle["outcome"]["actuation_started_at"] is not None
        referenced.add(attempt.evidence)
    # evidence directories belong to attempts; a preparation killed before its go may leave
    # one only for a session that then ran (and wrote its bundle there)
    for directory in (ws.root / "evidence").iterdir():
        assert f"evidence/{directory.name}" in referenced, directory.name
    for name in (f"franka_{i}" for i in range(SUPERVISORS)):
        assert not (ws.root / "targets" / name / "inflight.yaml").exists()
