"""The supervisor's execution deadline counts from where the runner's execution clock
starts, not from ``start``: time a runner spends before its first tick (setting the
session up on a loaded machine, here a runner stopped for a second) is not execution.

Before this was so, a 1 s ``execution_timeout_s`` on a loaded machine was cancelled
while the runner was still setting up, the runner was killed for not stopping between
ticks it had not begun, and the session ended only after a recovery in a fresh runner:
7-60 s instead of about 1 s of execution.
"""

from __future__ import annotations

import os
import signal
import threading

import pytest
import yaml
from supervisor_util import make_workspace, submit

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.runtime.heartbeat import ARRAY_LENGTH, SLOTS, Heartbeats
from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor
from phyagentos.runtime.worker import RunnerProcess

TIMEOUT_S = 0.5
STOPPED_S = 1.5  # longer than the timeout plus the supervisor's grace
LONG_HOLD = {"duration_s": 3600.0}  # an hour of simulated time: ended by the timeout


def test_the_execution_clock_cell_is_cleared_with_the_slots_and_is_not_a_heartbeat():
    hb = Heartbeats()
    assert len(hb.array) == ARRAY_LENGTH == len(SLOTS) + 1
    assert hb.execution_started_at() is None
    hb.start_execution(now=12.5)
    assert hb.execution_started_at() == 12.5
    assert hb.stale(0.001, now=1e9) is None  # not judged as a heartbeat
    hb.reset()
    assert hb.execution_started_at() is None
    with pytest.raises(ValueError, match="execution-clock start"):
        Heartbeats([0.0] * len(SLOTS))


@pytest.mark.sim
def test_a_runner_delayed_before_its_first_tick_gets_its_whole_execution_budget_and_is_not_killed(
        tmp_path, monkeypatch):
    ws = make_workspace(tmp_path / "ws")
    # a heartbeat budget far above the stop: only the execution deadline may end it, even when a
    # loaded machine starves the runner for seconds more
    submit(ws, "slow", skill="hold", parameters=LONG_HOLD,
           limits={"execution_timeout_s": TIMEOUT_S, "heartbeat_timeout_s": 120.0})
    original = RunnerProcess.send
    stopped: list[int] = []

    def send(self, kind, **payload):
        original(self, kind, **payload)
        if kind == "go":  # the runner cannot read its go for a while: as if it were still setting up
            os.kill(self.pid, signal.SIGSTOP)
            stopped.append(self.pid)
            threading.Timer(STOPPED_S, os.kill, (self.pid, signal.SIGCONT)).start()

    monkeypatch.setattr(RunnerProcess, "send", send)
    # a runner that has not stopped 0.5 s after a cancel is killed: before the runner resumes
    config = SupervisorConfig(poll_interval_s=0.1, execution_grace_s=0.3, cancel_grace_s=0.5)
    with WatchdogSupervisor(ws, config=config) as sup:
        assert sup.run_once() == 1
        stats = dict(sup.stats)
    assert stopped, "the runner was never told to go"
    rec = ws.load_session("slow")
    assert rec.state == "timed_out" and rec.result.error.code == "timeout.execution"
    assert stats["runner_kills"] == 0 and stats["recovered"] == 0
    bundle = yaml.safe_load((ws.root / rec.attempts[0].evidence / "bundle.yaml").read_text())
    outcome = bundle["outcome"]
    # ended by the runner's own deadline, after executing for the whole budget
    assert outcome["status"] == "timed_out" and outcome["message"] == "execution timeout exceeded"
    executed = (outcome["actuation_ended_at"] - outcome["actuation_started_at"]).total_seconds()
    assert executed >= TIMEOUT_S * 0.9
