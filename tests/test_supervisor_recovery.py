"""Lease expiry, deterministically: the state a dead supervisor leaves behind, picked up by another."""

from __future__ import annotations

import time

import numpy as np
import pytest
import yaml
from supervisor_util import make_workspace, submit

from phyagentos.agent.coordinator import AgentCoordinator
from phyagentos.agent.goal_graph import parse_goal_graph
from phyagentos.protocol import Attempt, Workspace, new_lease, utc_now_iso
from phyagentos.protocol.lifecycle import SessionLifecycle
from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor
from phyagentos.runtime.target_lock import write_marker
from phyagentos.runtime.target_pool import TargetPool

pytestmark = pytest.mark.sim

DEAD = "deadhost:4242:gone00"


def expired_lease():
    return new_lease(DEAD, ttl_s=5.0, now=time.time() - 60.0)


def supervisor(ws: Workspace) -> WatchdogSupervisor:
    return WatchdogSupervisor(ws, config=SupervisorConfig(lease_s=5.0, poll_interval_s=0.2))


def test_session_whose_supervisor_died_before_actuation_goes_back_to_pending_and_runs_once(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "s1", skill="noop")

    def crashed_in_preflight(rec):
        rec.lease = expired_lease()
        lc = SessionLifecycle(rec)
        lc.fire("claim", reason=f"by {DEAD}")
        lc.fire("preflight")

    ws.update_session("s1", crashed_in_preflight)
    with supervisor(ws) as sup:
        assert sup.run_once() == 1
    rec = ws.load_session("s1")
    events = [t.event.split(":")[0] for t in rec.transitions]
    assert events == ["claim", "preflight", "release", "claim", "preflight", "start", "finish", "submit"]
    assert rec.state == "awaiting_verification" and len(rec.attempts) == 1
    assert sup.stats["taken_over"] == 1 and sup.stats["released"] == 1


def test_session_whose_supervisor_died_while_actuating_is_observed_from_its_checkpoint_never_rerun(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "s1", skill="hold", parameters={"duration_s": 5.0}, accept={"still": {"max_joint_motion_rad": 0.01}})
    rec = ws.load_session("s1")
    # The dead supervisor's runner had held the arm for 0.7 s of simulated time and
    # checkpointed the world before it died.
    spec = ws.read("TARGETS").data.targets[0]
    pool = TargetPool(ws.root / "targets")
    target = pool.acquire(rec, spec)
    target.hold(duration_s=0.7)
    pool.checkpoint(rec, target)
    checkpoint_time = target.sim_time
    pool.close()
    lease = expired_lease()

    def crashed_while_running(r):
        r.lease = lease
        lc = SessionLifecycle(r)
        lc.fire("claim", reason=f"by {DEAD}")
        lc.fire("preflight")
        r.attempts.append(Attempt(number=1, started_at=utc_now_iso(), runner=f"{DEAD}/runner:4243"))
        lc.fire("start")

    ws.update_session("s1", crashed_while_running)
    write_marker(ws.root / "targets", spec.name, session_id="s1", token=lease.token, owner=DEAD)
    with supervisor(ws) as sup:
        sup.run_once()
    rec = ws.load_session("s1")
    events = [t.event.split(":")[0] for t in rec.transitions]
    assert events == ["claim", "preflight", "start", "outcome_unknown"] and rec.state == "awaiting_verification"
    attempt = rec.attempts[0]
    assert attempt.outcome == "unknown" and attempt.error.code == "runtime.lease_expired"
    terminal = yaml.safe_load((ws.root / attempt.evidence / "terminal.yaml").read_text())
    assert terminal["sim_time_s"] == pytest.approx(checkpoint_time)  # the restored world, not a reset one
    with np.load(ws.root / "targets" / spec.name / "state.npz") as state:
        assert np.allclose(state["ctrl"][:7], state["qpos"][:7], atol=1e-6)  # halted and persisted
    assert not (ws.root / "targets" / spec.name / "inflight.yaml").exists()

    # The Agent judges it from that fresh observation; it is not started again.
    graph = parse_goal_graph(yaml.safe_dump({"version": 1, "name": "g", "nodes": [
        {"id": "s1", "skill": "hold", "target": spec.name, "params": {"duration_s": 5.0},
         "accept": {"still": {"max_joint_motion_rad": 0.01}}}]}), skills=["hold"], targets=[spec.name])
    AgentCoordinator(ws, graph, run_id="r-test")._verify("s1")
    rec = ws.load_session("s1")
    assert [t.event.split(":")[0] for t in rec.transitions][-2:] == ["verify", "succeed"]
    assert [t.event.split(":")[0] for t in rec.transitions].count("start") == 1


def test_verification_whose_agent_died_is_taken_up_by_the_next_agent(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "n1", skill="noop", accept={})
    with supervisor(ws) as sup:
        sup.run_once()

    def agent_died_while_verifying(rec):
        rec.lease = new_lease("agent:deadhost:1", ttl_s=5.0, now=time.time() - 60.0)
        SessionLifecycle(rec).fire("verify")

    ws.update_session("n1", agent_died_while_verifying)
    graph = parse_goal_graph(yaml.safe_dump({"version": 1, "name": "g", "nodes": [
        {"id": "n1", "skill": "noop", "target": "franka_tabletop", "params": {}, "accept": {}}]}),
        skills=["noop"], targets=["franka_tabletop"])
    AgentCoordinator(ws, graph, run_id="r-test").step()
    rec = ws.load_session("n1")
    events = [t.event.split(":")[0] for t in rec.transitions]
    assert events[-2:] == ["verify", "fail"] and events.count("verify") == 1  # resumed, not re-entered
    assert rec.lease is None and rec.attempts[0].verdict.verdict == "failure"  # no criteria: never a success
