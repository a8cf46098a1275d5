"""Fault injection: supervisors and runners killed with SIGKILL at random points, then restarted.

Nothing may be corrupted or lost, nothing may stay non-terminal once leases have
expired and recovery ran, and a session that was actuating when its runner or
supervisor died is never started again: it is judged from a fresh observation.
"""

from __future__ import annotations

import os
import random
import signal
import time
from datetime import datetime, timezone

import pytest
import yaml
from soak import scaled
from supervisor_util import Drill, assert_run_ended_whole, descends_from, make_workspace, presence, wait_for

from phyagentos.errors import PhyAgentOSError

pytestmark = [pytest.mark.sim, pytest.mark.soak]

SEED = 20261121
KILLS = scaled(26, 52)  # one in five a supervisor (see tests/soak.py)
NODES = 18
SUPERVISORS = 3


def hold_graph(path, rng: random.Random) -> None:
    nodes = [{"id": f"n{i:02d}", "skill": "hold", "target": f"franka_{i % SUPERVISORS}",
              "params": {"duration_s": round(rng.uniform(2.0, 12.0), 2)},
              "accept": {"still": {"max_joint_motion_rad": 0.01}}} for i in range(NODES)]
    path.write_text(yaml.safe_dump({"version": 1, "name": "faults", "description": "independent holds",
                                    "nodes": nodes}))


def actuating_for(ws, session_id: str) -> float:
    """Seconds of hold left to the session ``session_id`` if it is actuating (started,
    not finished), else 0.0."""
    try:
        rec = ws.load_session(session_id)
    except PhyAgentOSError:
        return 0.0
    if rec.state != "running":
        return 0.0
    started = next((t.at for t in reversed(rec.transitions) if t.event.split(":")[0] == "start"), None)
    if started is None:
        return 0.0
    elapsed = (datetime.now(timezone.utc) - datetime.fromisoformat(str(started).replace("Z", "+00:00"))).total_seconds()
    return float(rec.parameters["duration_s"]) - elapsed


def test_random_sigkills_of_supervisors_and_runners_lose_and_rerun_nothing(tmp_path):
    rng = random.Random(SEED)
    ws = make_workspace(tmp_path / "ws", targets=SUPERVISORS)
    graph = tmp_path / "faults.yaml"
    hold_graph(graph, rng)
    drill = Drill.start(ws, graph, tmp_path, supervisors=SUPERVISORS)
    run_id, sups = drill.run_id, drill.sups
    kills = {"supervisor": 0, "runner": 0}
    # The kinds of the kills are a shuffled schedule of their own (1 in 5 a supervisor),
    # drawn from a generator that nothing timing-dependent consumes, and each kind is kept
    # until it lands: the mix no longer depends on how many waits a loaded machine needed
    # (the shared generator's draws used to shift it, down to 5 supervisor kills in 52).
    schedule = ["supervisor"] * (KILLS // 5) + ["runner"] * (KILLS - KILLS // 5)
    random.Random(SEED + 1).shuffle(schedule)
    kind = None
    first_victim = None
    try:
        while sum(kills.values()) < KILLS:
            time.sleep(rng.uniform(0.05, 0.3))
            if kind is None:
                kind = schedule[sum(kills.values())]
            # a started supervisor (or its runner), mostly one in the middle of a session
            live = {p.pid: i for i, p in enumerate(sups)}
            present = [r for r in presence(ws) if r.get("pid") in live]
            if kind == "runner":
                present = [r for r in present
                           if r.get("runner_pid") and descends_from(r["runner_pid"], r["pid"])]
            if not present:
                continue
            busy = [r for r in present if r.get("session")]
            if not sum(kills.values()):
                # The first kill always lands mid-actuation (a session started, a second or
                # more of its hold still to go), so the recovery it drills does not depend
                # on how a loaded machine times the random ones: under load none did once.
                busy = [r for r in busy if actuating_for(ws, r["session"]) >= 1.0]
                if not busy:
                    continue
                victim = rng.choice(busy)
                first_victim = victim["session"]
            else:
                victim = rng.choice(busy) if busy and rng.random() < 0.7 else rng.choice(present)
            k = live[victim["pid"]]
            if kind == "supervisor":
                drill.kill_supervisor(k)
                kills["supervisor"] += 1
            else:
                try:
                    os.kill(victim["runner_pid"], signal.SIGKILL)
                except ProcessLookupError:
                    continue  # it exited between the check and the kill: not a kill of ours
                kills["runner"] += 1
            kind = None
        wait_for(lambda: run_id not in ws.runs.active_ids(), timeout=180, interval=0.25, what="the run to finish")
    finally:
        codes = drill.stop()
    assert codes == [0] * SUPERVISORS, drill.log.read_text()[-3000:]
    assert kills == {"supervisor": KILLS // 5, "runner": KILLS - KILLS // 5}, kills  # every scheduled kill landed

    records = assert_run_ended_whole(ws, run_id, {f"n{i:02d}" for i in range(NODES)})

    recovered = 0
    for rec in records:
        events = [t.event.split(":")[0] for t in rec.transitions]
        # actuation at most once per session, whatever was killed when
        assert events.count("start") <= 1, (rec.session_id, events)
        if "outcome_unknown" in events:
            recovered += 1
            after = events[events.index("outcome_unknown") + 1]
            assert after == "verify", (rec.session_id, events)  # judged before anything moved again
            attempt = rec.attempts[-1]
            assert attempt.outcome == "unknown" and attempt.error.code.startswith("runtime.")
            assert attempt.verdict is not None
            bundle = yaml.safe_load((ws.root / attempt.evidence / "bundle.yaml").read_text())
            assert "terminal" in bundle["files"]  # a fresh observation of the halted target
        if "start" in events:
            assert len(rec.attempts) == 1 and rec.attempts[0].ended_at is not None
    assert recovered >= 1
    first = next(r for r in records if r.session_id == first_victim)
    assert "outcome_unknown" in [t.event.split(":")[0] for t in first.transitions], first_victim
    for name in ("franka_0", "franka_1", "franka_2"):
        assert not (ws.root / "targets" / name / "inflight.yaml").exists()
