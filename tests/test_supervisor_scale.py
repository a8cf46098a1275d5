"""Four supervisor processes on one workspace: every session is claimed and run exactly once
(200 sessions in ``make test``, 500 under ``make soak``: tests/soak.py)."""

from __future__ import annotations

from collections import Counter

import pytest
from soak import scaled
from supervisor_util import make_workspace, stop, submit, target_names, wait_for, watch

pytestmark = [pytest.mark.sim, pytest.mark.soak]

SESSIONS = scaled(200, 500)  # either way ten times the index's bound of 20 listed sessions
SUPERVISORS = 4
RUN_TO_VERIFICATION = ["claimed", "preflight_checking", "running", "finalizing", "awaiting_verification"]


def test_four_supervisors_claim_and_run_each_of_hundreds_of_sessions_exactly_once(tmp_path):
    ws = make_workspace(tmp_path / "ws", targets=SUPERVISORS)
    targets = target_names(ws)
    # Submitted before any supervisor starts, so all four race for the same queue head.
    for i in range(SESSIONS):
        submit(ws, f"s{i:04d}", skill="noop", target=targets[i % len(targets)])
    logs = [tmp_path / f"watch{k}.log" for k in range(SUPERVISORS)]
    procs = [watch(ws, "--lease-s", "30", log=logs[k]) for k in range(SUPERVISORS)]
    try:
        wait_for(lambda: len(ws.active_sessions("awaiting_verification")) == SESSIONS, timeout=240, interval=0.5,
                 what="every session to reach awaiting_verification")
    finally:
        codes = [stop(p) for p in procs]
    assert codes == [0] * SUPERVISORS, [log.read_text()[-2000:] for log in logs]

    records = ws.list_sessions(run_id="r-test")
    assert len(records) == SESSIONS
    for rec in records:
        assert [t.dest for t in rec.transitions] == RUN_TO_VERIFICATION, rec.session_id
        assert [t.event.split(":")[0] for t in rec.transitions].count("claim") == 1
        assert len(rec.attempts) == 1 and rec.attempts[0].outcome == "completed", rec.session_id
        assert rec.lease is None
        claim_owner = rec.transitions[0].event.removeprefix("claim: by ")
        assert rec.attempts[0].runner.startswith(claim_owner + "/runner:")  # the claimer ran it
    per_supervisor = Counter(r.transitions[0].event.removeprefix("claim: by ") for r in records)
    assert len(per_supervisor) == SUPERVISORS, per_supervisor  # all four really competed
    index = ws.read("SESSIONS").data
    assert index.counts == {"awaiting_verification": SESSIONS}
    assert len(index.sessions) <= ws.INDEX_MAX_WAITING + ws.INDEX_MAX_TERMINAL  # bounded, whatever the queue
