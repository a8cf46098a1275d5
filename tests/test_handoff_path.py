"""What keeps waiting off the critical path (issue 12), pinned by behaviour, not by timing.

Batched fsyncs, evidence images rendered in the background and settled through the
evidence directory, a runner that starts in the background, cached terminal sessions,
and a run whose supervisor runs event-driven next to the agent.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
import yaml

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.errors import SupervisorError
from phyagentos.protocol import Workspace, atomic
from phyagentos.protocol.atomic import atomic_write_text, batched_durability
from phyagentos.protocol.evidence_markers import (
    PENDING_MARKER,
    PRUNED_MARKER,
    WANTED_MARKER,
    images_pending,
    wait_for_images,
)
from phyagentos.resources import goal_graphs_dir


def _count_fsyncs(monkeypatch) -> list[int]:
    calls: list[int] = []
    real = os.fsync

    def counting(fd):
        calls.append(fd)
        return real(fd)

    monkeypatch.setattr(atomic.os, "fsync", counting)
    return calls


def test_batched_writes_are_visible_at_once_and_fsynced_together_at_the_end(tmp_path, monkeypatch):
    calls = _count_fsyncs(monkeypatch)
    with batched_durability():
        for name in ("a.yaml", "b.yaml", "c.yaml"):
            atomic_write_text(tmp_path / name, name)
            assert (tmp_path / name).read_text() == name  # renamed into place immediately
        atomic_write_text(tmp_path / "a.yaml", "again")  # the same file is synced once
        with batched_durability():  # nested blocks join the outer one
            atomic_write_text(tmp_path / "d.yaml", "d")
        assert calls == []
    assert len(calls) == 4 + 1  # four files, then their directory once
    assert (tmp_path / "a.yaml").read_text() == "again"


def test_outside_a_batch_every_write_is_fsynced_with_its_directory(tmp_path, monkeypatch):
    calls = _count_fsyncs(monkeypatch)
    atomic_write_text(tmp_path / "a.yaml", "a")
    assert len(calls) == 2


def test_a_batch_interrupted_by_an_error_still_syncs_what_it_wrote(tmp_path, monkeypatch):
    calls = _count_fsyncs(monkeypatch)
    with pytest.raises(RuntimeError):
        with batched_durability():
            atomic_write_text(tmp_path / "a.yaml", "a")
            raise RuntimeError("boom")
    assert len(calls) == 2


@pytest.fixture()
def target():
    from phyagentos.targets import DEFAULT_SCENE, MuJoCoTarget

    t = MuJoCoTarget("franka_tabletop", DEFAULT_SCENE, seed=0)
    yield t
    t.close()


@pytest.mark.sim
def test_images_owed_to_a_pruned_success_are_never_rendered(tmp_path, target):
    from phyagentos.runtime.evidence_writer import EvidenceImageWriter

    writer = EvidenceImageWriter(decide_s=5.0)
    assert writer.capture(target, tmp_path / "initial.png") == "initial.png"
    assert images_pending(tmp_path)
    (tmp_path / PRUNED_MARKER).touch()  # the verdict came first
    writer.release(tmp_path)
    assert wait_for_images(tmp_path, timeout_s=30)
    writer.close()
    assert not (tmp_path / "initial.png").exists() and not (tmp_path / PENDING_MARKER).exists()


@pytest.mark.sim
def test_images_a_verdict_needs_are_rendered_from_the_captured_state(tmp_path, target):
    from phyagentos.runtime.evidence_writer import EvidenceImageWriter

    writer = EvidenceImageWriter(decide_s=60.0)  # the answer, not the timeout, starts the render
    writer.capture(target, tmp_path / "initial.png")
    target.set_gripper(opening_m=0.0, settle_s=0.3)  # the scene moves on after the capture
    writer.capture(target, tmp_path / "terminal.png")
    writer.release(tmp_path)
    started = time.monotonic()
    assert wait_for_images(tmp_path, timeout_s=30)
    assert time.monotonic() - started < 30
    writer.close()
    a, b = (tmp_path / "initial.png").read_bytes(), (tmp_path / "terminal.png").read_bytes()
    assert a[:8] == b[:8] == b"\x89PNG\r\n\x1a\n"
    assert a != b


@pytest.mark.sim
def test_a_scene_taken_earlier_is_rendered_as_it_was_not_as_the_target_is_now(tmp_path, target):
    from phyagentos.runtime.evidence_writer import EvidenceImageWriter

    writer = EvidenceImageWriter(decide_s=60.0)
    writer.capture(target, tmp_path / "before.png")
    earlier = writer.scene(target)  # what a runner takes while it prepares a session
    assert earlier is not None
    target.set_gripper(opening_m=0.0, settle_s=0.3)
    writer.capture(target, tmp_path / "taken_earlier.png", scene=earlier)
    writer.capture(target, tmp_path / "now.png")
    writer.release(tmp_path)
    assert wait_for_images(tmp_path, timeout_s=30)
    writer.close()
    before, earlier_png, now = ((tmp_path / n).read_bytes() for n in ("before.png", "taken_earlier.png", "now.png"))
    assert earlier_png == before != now


def test_a_runner_answers_a_job_sent_while_it_was_still_starting(tmp_path):
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.worker import RunnerProcess

    runner = RunnerProcess(skills_dir=skills_dir(), trees_dir=trees_dir())
    try:
        assert runner.alive()  # starting counts as alive: nobody replaces it meanwhile
        kind, _ = runner.request("ping", timeout=120, expect=("pong",))
        assert kind == "pong" and runner.pid and runner.wait_started(0)
    finally:
        runner.close()
    assert not runner.alive()


@pytest.mark.sim
def test_terminal_sessions_come_from_the_cache_as_independent_copies(tmp_path):
    from phyagentos.app.orchestrator import run_goal_graph
    from phyagentos.resources import goal_graphs_dir

    report = run_goal_graph(goal_graphs_dir() / "hold.yaml", tmp_path / "ws")
    assert report.succeeded
    ws = Workspace.open(tmp_path / "ws")
    (first,) = ws.list_sessions(run_id=report.run_id)
    first.parameters["mutated"] = True
    (again,) = ws.list_sessions(run_id=report.run_id)
    assert "mutated" not in again.parameters and again.state == "succeeded"
    # the session's transitions are complete although `finish` was written with `submit`
    assert [t.dest for t in again.transitions][2:5] == ["running", "finalizing", "awaiting_verification"]
    bundle = yaml.safe_load((tmp_path / "ws" / again.attempts[0].evidence / "bundle.yaml").read_text())
    assert bundle["outcome"]["actuation_started_at"] <= bundle["outcome"]["actuation_ended_at"]


def test_a_run_nobody_can_advance_is_reported_as_stalled(tmp_path):
    from phyagentos.agent.coordinator import AgentCoordinator
    from phyagentos.app.orchestrator import drive_run
    from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor

    class Stuck(AgentCoordinator):
        """A coordinator whose node never becomes terminal and never submits anything."""

        def __init__(self, workspace):  # noqa: D107 - minimal stand-in
            self.workspace = workspace
            self.run_id = "r-stuck"

        def step(self):
            return 0

        def done(self):
            return False

        def node_states(self, sessions=None):
            return {"n": "running"}

    ws = Workspace.create(tmp_path / "ws")
    supervisor = WatchdogSupervisor(ws, config=SupervisorConfig(poll_interval_s=0.1))
    try:
        with pytest.raises(SupervisorError, match="stalled"):
            drive_run(Stuck(ws), supervisor)
    finally:
        supervisor.close()


@pytest.mark.sim
def test_the_in_flight_marker_and_the_world_state_record_are_written_without_pyyaml_and_read_back(tmp_path,
                                                                                                  monkeypatch):
    # Both are written on the path from a verdict to the next session's first tick: by the
    # codec's block emitter, a tenth of yaml.safe_dump's time.
    from supervisor_util import make_workspace, submit

    from phyagentos.runtime.target_lock import read_marker, write_marker
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    rec = submit(ws, "s1", skill="hold", parameters={"duration_s": 0.0})
    spec = ws.read("TARGETS").data.targets[0]
    pool = TargetPool(ws.root / "targets")
    try:
        target = pool.acquire(rec, spec)

        def refuse(*args, **kwargs):
            raise AssertionError("PyYAML's emitter on the hand-off path")

        monkeypatch.setattr(yaml, "safe_dump", refuse)
        monkeypatch.setattr(yaml, "dump", refuse)
        write_marker(ws.root / "targets", spec.name, session_id="s1", token="t-1", owner="vm:1:x")
        pool.checkpoint(rec, target)
        target.hold(duration_s=0.2)
        monkeypatch.undo()
        marker = read_marker(ws.root / "targets", spec.name)
        assert {k: marker[k] for k in ("session_id", "token", "owner")} == {"session_id": "s1", "token": "t-1",
                                                                              "owner": "vm:1:x"}
        assert isinstance(marker["since"], float) and abs(marker["since"] - time.time()) < 60
        state = yaml.safe_load((ws.root / "targets" / spec.name / "state.yaml").read_text())
        assert state["run_id"] == rec.run_id and state["session_id"] == "s1"
        checkpointed = target.sim_time - 0.2
    finally:
        pool.close()
    pool = TargetPool(ws.root / "targets")  # a fresh runner continues the episode from the record
    try:
        assert pool.acquire(ws.load_session("s1"), spec).sim_time == pytest.approx(checkpointed)
    finally:
        pool.close()


@pytest.mark.sim
def test_bundles_read_for_verdicts_serve_the_next_nodes_observations_and_a_replaced_bundle_is_read_again(
        tmp_path, monkeypatch):
    # A place's context holds what the pick observed of the cube, from the pick's evidence
    # bundle; the agent read that bundle for the pick's verdict a moment before.
    from phyagentos.agent import coordinator as coordmod
    from phyagentos.agent.agent_loop import load_run_graph
    from phyagentos.agent.memory.observed import observe_object
    from phyagentos.agent.verifier import load_evidence
    from phyagentos.app.orchestrator import run_goal_graph, skill_names

    graph = goal_graphs_dir() / "pick_and_place.yaml"
    report = run_goal_graph(graph, tmp_path / "ws", seed=0)
    assert report.succeeded
    ws = Workspace.open(tmp_path / "ws")
    agent = coordmod.AgentCoordinator(ws, load_run_graph(ws, report.run_id, skills=skill_names()),
                                      run_id=report.run_id)
    sessions = agent.sessions()
    dirs = [ws.root / a.evidence for s in sessions for a in s.attempts if a.evidence]
    assert len(dirs) == 2
    loads: list[Path] = []

    def counting(directory):
        loads.append(Path(directory))
        return load_evidence(directory)

    monkeypatch.setattr(coordmod, "load_evidence", counting)
    expected = observe_object([load_evidence(d) for d in dirs], "cube")
    assert expected is not None and expected.size_m is not None
    assert agent.observed("cube", sessions) == expected and len(loads) == 2
    assert agent.observed("cube", sessions) == expected and len(loads) == 2  # nothing read again
    bundle = dirs[0] / "bundle.yaml"
    atomic_write_text(bundle, bundle.read_text())  # the same text in a new file
    assert agent.observed("cube", sessions) == expected
    assert loads[2:] == [dirs[0]]


@pytest.mark.sim
def test_a_background_image_shows_the_scene_at_the_joint_values_captured(tmp_path, target):
    # The writer restores the captured integration state and recomputes the poses from
    # it: the image is the scene at exactly the qpos a snapshot of that moment records
    # (the live MjData's poses lag qpos by one physics step after mj_step).
    import mujoco
    import numpy as np
    from PIL import Image

    from phyagentos.runtime.evidence_images import save_scene_image
    from phyagentos.runtime.evidence_writer import EvidenceImageWriter

    target.set_gripper(opening_m=0.0, settle_s=0.3)
    writer = EvidenceImageWriter(decide_s=60.0)
    writer.capture(target, tmp_path / "background.png")
    (tmp_path / WANTED_MARKER).touch()
    writer.release(tmp_path)
    assert wait_for_images(tmp_path, timeout_s=30)
    writer.close()
    mujoco.mj_forward(target.model, target.data)  # the live poses of the current qpos
    save_scene_image(target, tmp_path / "synchronous.png")
    background, synchronous = (np.asarray(Image.open(tmp_path / n)) for n in ("background.png", "synchronous.png"))
    assert background.shape == synchronous.shape and np.array_equal(background, synchronous)
