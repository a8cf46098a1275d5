"""Fault injection: supervisors and runners killed with SIGKILL at random points, then restarted.

Nothing may be corrupted or lost, nothing may stay non-terminal once leases have
expired and recovery ran, and a session that was actuating when its runner or
supervisor died is never started again: it is judged from a fresh observation.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import time

import pytest
import yaml

from phyagentos.protocol import TERMINAL_STATES
from supervisor_util import (CLI, ROOT, assert_every_document_parses, descends_from, make_workspace, presence, stop,
                             wait_for, watch)

pytestmark = pytest.mark.sim

SEED = 20261121
KILLS = 52
NODES = 18
SUPERVISORS = 3


def hold_graph(path, rng: random.Random) -> None:
    nodes = [{"id": f"n{i:02d}", "skill": "hold", "target": f"franka_{i % SUPERVISORS}",
              "params": {"duration_s": round(rng.uniform(2.0, 12.0), 2)},
              "accept": {"still": {"max_joint_motion_rad": 0.01}}} for i in range(NODES)]
    path.write_text(yaml.safe_dump({"version": 1, "name": "faults", "description": "independent holds",
                                    "nodes": nodes}))


def test_random_sigkills_of_supervisors_and_runners_lose_and_rerun_nothing(tmp_path):
    rng = random.Random(SEED)
    ws = make_workspace(tmp_path / "ws", targets=SUPERVISORS)
    graph = tmp_path / "faults.yaml"
    hold_graph(graph, rng)
    out = subprocess.run([*CLI, "submit", str(graph), "--workspace", str(ws.root)], capture_output=True, text=True,
                         timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    run_id = out.stdout.strip()
    args = ("--lease-s", "1.0", "--poll-s", "0.2", "--cancel-grace-s", "1")
    log = tmp_path / "watch.log"
    sups = [watch(ws, *args, log=log) for _ in range(SUPERVISORS)]
    agent = subprocess.Popen([*CLI, "agent", str(ws.root), "--poll-s", "0.2"], stdout=subprocess.DEVNULL,
                             stderr=open(tmp_path / "agent.log", "ab"), cwd=ROOT)
    kills = {"supervisor": 0, "runner": 0}
    # The kinds of the kills are a shuffled schedule of their own (1 in 5 a supervisor),
    # drawn from a generator that nothing timing-dependent consumes, and each kind is kept
    # until it lands: the mix no longer depends on how many waits a loaded machine needed
    # (the shared generator's draws used to shift it, down to 5 supervisor kills in 52).
    schedule = ["supervisor"] * (KILLS // 5) + ["runner"] * (KILLS - KILLS // 5)
    random.Random(SEED + 1).shuffle(schedule)
    kind = None
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
            victim = rng.choice(busy) if busy and rng.random() < 0.7 else rng.choice(present)
            k = live[victim["pid"]]
            if kind == "supervisor":
                sups[k].send_signal(signal.SIGKILL)
                sups[k].wait(timeout=30)
                kills["supervisor"] += 1
                sups[k] = watch(ws, *args, log=log)
            else:
                try:
                    os.kill(victim["runner_pid"], signal.SIGKILL)
                except ProcessLookupError:
                    continue  # it exited between the check and the kill: not a kill of ours
                kills["runner"] += 1
            kind = None
        wait_for(lambda: run_id not in ws.runs.active_ids(), timeout=180, interval=0.25, what="the run to finish")
    finally:
        codes = [stop(p) for p in sups]
        assert stop(agent) == 0
    assert codes == [0] * SUPERVISORS, log.read_text()[-3000:]
    assert kills["supervisor"] >= 6 and kills["runner"] >= 30, kills

    # no corrupted document, nothing left active
    assert assert_every_document_parses(ws) > NODES
    assert ws.active_sessions() == []
    records = ws.list_sessions(run_id=run_id)
    assert {r.node for r in records} == {f"n{i:02d}" for i in range(NODES)}  # no lost node
    assert all(r.state in TERMINAL_STATES for r in records)
    assert ws.runs.load(run_id).state == "finished"

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
    for name in ("franka_0", "franka_1", "franka_2"):
        assert not (ws.root / "targets" / name / "inflight.yaml").exists()
