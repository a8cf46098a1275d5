"""A runner sets a session up while the supervisor persists ``start`` (issue 12).

After a passed preflight the runner acquires and observes the target and builds the
skill context (:meth:`SessionRunner.prepare`), while the WatchdogSupervisor writes the
``start`` transition; ``go`` then ticks at once. Pinned here with a real supervisor and
a real runner process: nothing ticks before ``start`` is durable, a session whose
runtime fields changed between preflight and start is set up afresh from its file, and
a prepared session that never starts leaves nothing behind.
"""

from __future__ import annotations

import datetime as dt
import multiprocessing

import pytest
import yaml
from supervisor_util import make_workspace, state_of, submit

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.errors import DocumentError, SupervisorError
from phyagentos.protocol import Workspace
from phyagentos.resources import skill_dirs, tree_dirs
from phyagentos.runtime.heartbeat import Heartbeats
from phyagentos.runtime.session_basis import RUNTIME_FIELDS, runtime_basis
from phyagentos.runtime.supervisor import WatchdogSupervisor
from phyagentos.runtime.worker import RunnerProcess, _Runner

HOLD = {"duration_s": 0.0}


def _at(stamp) -> dt.datetime:
    """A UTC timestamp as the protocol writes it (YAML may have parsed it already)."""
    if isinstance(stamp, dt.datetime):
        return stamp if stamp.tzinfo else stamp.replace(tzinfo=dt.timezone.utc)
    return dt.datetime.fromisoformat(str(stamp).replace("Z", "+00:00"))


def _bundle(ws: Workspace, sid: str) -> dict:
    rec = ws.load_session(sid)
    return yaml.safe_load((ws.root / rec.attempts[-1].evidence / "bundle.yaml").read_text())


def _before_start(monkeypatch, action) -> None:
    """Have ``action(supervisor, inflight)`` happen after the runner replied to its
    preflight (and began preparing) and before the supervisor writes ``start``."""
    real = WatchdogSupervisor._on_preflight

    def wrapped(self, inf, payload):
        action(self, inf)
        return real(self, inf, payload)

    monkeypatch.setattr(WatchdogSupervisor, "_on_preflight", wrapped)


def test_the_runtime_basis_survives_the_session_file_and_ignores_what_the_supervisor_owns(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    rec = submit(ws, "s1", skill="hold", parameters={"duration_s": 0.1, "note": [1, 2.5e-07]})
    loaded = ws.load_session("s1")
    assert runtime_basis(loaded) == runtime_basis(rec)
    claimed = loaded.model_copy(update={"state": "claimed", "updated_at": "2030-01-01T00:00:00Z"})
    assert runtime_basis(claimed) == runtime_basis(rec)  # state and timestamps are not runtime inputs
    for field, value in [("parameters", {"duration_s": 0.2, "note": [1, 2.5e-07]}), ("seed", 8),
                         ("adapter_plan", {"x": 1}), ("tool_manifest", {"operations": []})]:
        assert field in RUNTIME_FIELDS
        assert runtime_basis(loaded.model_copy(update={field: value})) != runtime_basis(rec), field


@pytest.mark.sim
def test_a_session_is_set_up_before_go_and_ticks_only_after_start_is_recorded(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    for sid in ("a", "b"):
        submit(ws, sid, skill="hold", parameters=HOLD)
    sup = WatchdogSupervisor(ws)
    try:
        assert sup.run_once() == 2
    finally:
        sup.close()
    for sid in ("a", "b"):
        rec = ws.load_session(sid)
        assert rec.state == "awaiting_verification"
        timings = rec.attempts[-1].timings
        assert timings["set_up_before_go"] > 0 and timings["set_up_before_go"] == timings["set_up"]
        started = next(t.at for t in rec.transitions if t.dest == "running")
        bundle = _bundle(ws, sid)
        assert _at(bundle["outcome"]["actuation_started_at"]) >= _at(started)
        assert {"task", "initial"} <= set(bundle["files"])
        for name in bundle["files"].values():
            if not name.endswith(".png"):  # images are rendered in the background
                assert (ws.root / rec.attempts[-1].evidence / name).is_file(), name
    state = yaml.safe_load((ws.root / "targets" / "franka_tabletop" / "state.yaml").read_text())
    assert state["session_id"] == "b"


@pytest.mark.sim
def test_a_session_edited_between_preflight_and_start_runs_as_its_file_says(tmp_path, monkeypatch):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "edited", skill="hold", parameters=HOLD)

    def longer(rec):
        rec.parameters = {"duration_s": 0.25}

    # an operator's edit lands after the runner prepared from the file, before start
    _before_start(monkeypatch, lambda sup, inf: sup.workspace.update_session(inf.session_id, longer))
    sup = WatchdogSupervisor(ws)
    try:
        assert sup.run_once() == 1
    finally:
        sup.close()
    rec = ws.load_session("edited")
    assert rec.state == "awaiting_verification" and rec.attempts[-1].outcome == "completed"
    assert rec.attempts[-1].timings["set_up_before_go"] == 0.0  # the preparation was not used
    evidence = ws.root / rec.attempts[-1].evidence
    assert yaml.safe_load((evidence / "task.yaml").read_text())["parameters"] == {"duration_s": 0.25}
    terminal = yaml.safe_load((evidence / "terminal.yaml").read_text())
    initial = yaml.safe_load((evidence / "initial.yaml").read_text())
    assert terminal["sim_time_s"] - initial["sim_time_s"] == pytest.approx(0.25, abs=0.01)


@pytest.mark.sim
def test_a_prepared_session_that_never_starts_leaves_no_evidence_and_the_next_one_runs(tmp_path, monkeypatch):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "cancelled", skill="hold", parameters=HOLD)

    def cancel(sup, inf):
        if inf.session_id == "cancelled":  # an operator's cancel arrives while start is due
            inf.cancel = ("cancelled.operator", "changed my mind")

    _before_start(monkeypatch, cancel)
    sup = WatchdogSupervisor(ws)
    try:
        assert sup.run_once() == 1
        rec = ws.load_session("cancelled")
        assert rec.state == "cancelled" and rec.attempts == []
        submit(ws, "next", skill="hold", parameters=HOLD)
        assert sup.run_once() == 1
    finally:
        sup.close()
    assert not (ws.root / "evidence" / "cancelled").exists()
    nxt = ws.load_session("next")
    assert nxt.state == "awaiting_verification" and nxt.attempts[-1].timings["set_up_before_go"] > 0


@pytest.mark.sim
@pytest.mark.parametrize("how", ["cancelled", "unreadable", "write_fails"])
def test_a_claim_that_is_not_made_leaves_the_target_free_and_unmarked(tmp_path, monkeypatch, caplog, how):
    """The runner preflights (and prepares) while the claim is written. A claim that is
    not made (the session was cancelled or broken just before it, or the claim's write
    failed after the preflight was sent) releases the target, leaves no marker and no
    evidence for the session, and the next claim on the same runner goes as usual."""
    import errno
    import logging

    from phyagentos.protocol.lifecycle import SessionLifecycle
    from phyagentos.protocol.workspace import sessions as workspace_module  # where session files are written
    from phyagentos.runtime.target_lock import read_marker

    ws = make_workspace(tmp_path / "ws")
    submit(ws, "lost", skill="hold", parameters=HOLD)
    real_claim, real_write = WatchdogSupervisor._claim_record, workspace_module.write_document
    spoiled = []

    def spoil_then_claim(self, session_id, lease, **kwargs):
        if session_id == "lost" and not spoiled:
            spoiled.append(session_id)
            if how == "cancelled":  # an operator's cancel lands between the listing and the claim
                def cancel(rec):
                    lc = SessionLifecycle(rec)
                    lc.fire("cancel", reason="operator")
                    lc.fire("cancelled", reason="operator")

                self.workspace.update_session(session_id, cancel)
            elif how == "unreadable":  # a hand edit breaks the file
                path = self.workspace.find_session_path(session_id)
                path.write_text(path.read_text().replace("skill: hold", "skill: [hold"))
        return real_claim(self, session_id, lease, **kwargs)

    def full_disk_once(doc, *args, **kwargs):
        if how == "write_fails" and doc.path.name == "lost.md" and doc.data.state == "preflight_checking" \
                and "disk" not in spoiled:
            spoiled.append("disk")
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(doc, *args, **kwargs)

    monkeypatch.setattr(WatchdogSupervisor, "_claim_record", spoil_then_claim)
    monkeypatch.setattr(workspace_module, "write_document", full_disk_once)
    sup = WatchdogSupervisor(ws)
    try:
        with caplog.at_level(logging.WARNING, logger="phyagentos.runtime.supervisor"):
            assert sup.run_once() == 0
        assert "could not release" not in caplog.text
        marker = read_marker(ws.root / "targets", "franka_tabletop")
        assert marker is None or marker.get("session_id") != "lost"
        assert not (ws.root / "evidence" / "lost").exists()
        if how == "write_fails":  # the file is as it was: the session is claimed next time
            assert "claim of lost not written" in caplog.text and state_of(ws, "lost") == "pending"
            assert sup.run_once() == 1
            ran = "lost"
        else:
            submit(ws, "next", skill="hold", parameters=HOLD)
            assert sup.run_once() == 1
            ran = "next"
    finally:
        sup.close()
    rec = ws.load_session(ran)
    assert rec.state == "awaiting_verification" and rec.attempts[-1].timings["set_up_before_go"] > 0
    if how == "cancelled":
        assert ws.load_session("lost").state == "cancelled"


def test_a_reply_left_on_the_pipe_by_an_earlier_job_is_not_taken_for_the_next_ones(tmp_path):
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.worker import RunnerProcess

    ws = make_workspace(tmp_path / "ws")
    runner = RunnerProcess(skills_dir=skills_dir(), trees_dir=trees_dir())
    try:
        # a job whose reply nobody waits for: its error stays on the pipe
        runner.send("preflight", root=str(ws.root), session_id="missing", token="t", owner="test")
        kind, payload = runner.request("reserve", timeout=120, expect=("reserved", "busy"), root=str(ws.root),
                                       target="franka_tabletop")
        assert kind == "reserved", payload
        kind, payload = runner.request("nonsense", timeout=30, expect=("never",))
        assert kind == "error" and payload["job"] == "nonsense"  # a job's own error still ends its wait
    finally:
        runner.close()


@pytest.mark.sim
def test_an_error_while_preparing_becomes_the_attempts_error_outcome_with_its_evidence(tmp_path):
    from phyagentos.errors import TargetError
    from phyagentos.primitives.context import CancelToken
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.runner import SessionRunner
    from phyagentos.runtime.target_pool import TargetPool

    class BrokenPool(TargetPool):
        def acquire(self, session, spec):
            raise TargetError("the scene does not build: mesh missing")

    ws = make_workspace(tmp_path / "ws")
    rec = submit(ws, "broken", skill="hold", parameters=HOLD)
    runner = SessionRunner(ws, rec, BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir()),
                           BrokenPool(ws.root / "targets"), cancel=CancelToken())
    runner.prepare()  # never raises: the error waits for run()
    assert runner.prepared
    report = runner.run()
    assert report.outcome == "error" and report.error_code == "target.error"
    assert "mesh missing" in report.message and report.timings["set_up_before_go"] > 0
    bundle = yaml.safe_load((ws.root / report.evidence / "bundle.yaml").read_text())
    assert bundle["outcome"]["status"] == "error" and bundle["files"]["task"] == "task.yaml"
    assert (ws.root / report.evidence / "task.yaml").is_file()
    with pytest.raises(SupervisorError, match="prepare called twice"):
        runner.prepare()


@pytest.mark.sim
def test_preparing_a_session_beats_after_building_its_target_and_after_perceiving_it(tmp_path, monkeypatch):
    """Setting a session up (the target built on a new runner, the initial perception) can
    take longer than a heartbeat timeout on a loaded machine: the runner beats between
    those steps, so only a runner that stops working goes silent."""
    from phyagentos.primitives.context import CancelToken
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.runner import SessionRunner
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    rec = submit(ws, "s1", skill="hold", parameters=HOLD)
    pool = TargetPool(ws.root / "targets")
    steps: list[str] = []
    real_acquire, real_view = TargetPool.acquire, SessionRunner._initial_view
    monkeypatch.setattr(TargetPool, "acquire", lambda self, *a: steps.append("acquire") or real_acquire(self, *a))
    monkeypatch.setattr(SessionRunner, "_initial_view",
                        lambda self, *a: steps.append("initial view") or real_view(self, *a))
    runner = SessionRunner(ws, rec, BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir()), pool,
                           cancel=CancelToken(), heartbeat=lambda: steps.append("beat"))
    try:
        runner.prepare()
        assert steps == ["acquire", "beat", "initial view", "beat"]
        runner.discard()
    finally:
        pool.close()


@pytest.mark.sim
def test_the_recorded_actuation_start_is_the_first_tick_after_the_tree_is_built_and_set_up(tmp_path, monkeypatch):
    """``actuation_started_at`` (where bench/end_to_end.py ends a hand-off) is stamped
    right before the skill's first tick, not before its tree is built and set up."""
    import py_trees

    from phyagentos.primitives.context import CancelToken
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.runner import SessionRunner
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    rec = submit(ws, "s1", skill="hold", parameters=HOLD)
    set_up: list[dt.datetime] = []
    ticked: list[dt.datetime] = []
    real_setup, real_tick = py_trees.trees.BehaviourTree.setup, py_trees.trees.BehaviourTree.tick

    def setup(self, *a, **kw):
        result = real_setup(self, *a, **kw)
        set_up.append(dt.datetime.now(dt.timezone.utc))
        return result

    def tick(self, *a, **kw):
        ticked.append(dt.datetime.now(dt.timezone.utc))
        return real_tick(self, *a, **kw)

    monkeypatch.setattr(py_trees.trees.BehaviourTree, "setup", setup)
    monkeypatch.setattr(py_trees.trees.BehaviourTree, "tick", tick)
    pool = TargetPool(ws.root / "targets")
    runner = SessionRunner(ws, rec, BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir()), pool,
                           cancel=CancelToken())
    try:
        report = runner.run()
    finally:
        pool.close()
    assert report.outcome == "completed", report.message
    started = _at(yaml.safe_load((ws.root / report.evidence / "bundle.yaml").read_text())["outcome"]
                  ["actuation_started_at"])
    assert set_up and ticked
    assert set_up[0] <= started <= ticked[0]


@pytest.mark.sim
def test_go_writes_what_preparing_serialised_and_captured_and_ticks_without_serialising(tmp_path, monkeypatch):
    from phyagentos.primitives.context import CancelToken
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime import runner as runner_mod
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.evidence_writer import EvidenceImageWriter
    from phyagentos.runtime.runner import SessionRunner
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    rec = submit(ws, "s1", skill="hold", parameters=HOLD)
    runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    images = EvidenceImageWriter(decide_s=60.0)
    pool = TargetPool(ws.root / "targets")
    runner = SessionRunner(ws, rec, runtime, pool, cancel=CancelToken(), images=images)
    dumps: list[str] = []
    real_dump, real_copy = runner_mod.dump_yaml, EvidenceImageWriter.scene
    monkeypatch.setattr(runner_mod, "dump_yaml", lambda data: dumps.append("dump") or real_dump(data))
    monkeypatch.setattr(EvidenceImageWriter, "scene", lambda self, t: dumps.append("scene") or real_copy(self, t))
    runner.prepare()
    assert dumps == ["dump", "dump", "scene"]  # task.yaml, initial.yaml and the initial scene, before go
    real_run = runtime.run
    at_first_tick: list[int] = []

    def run(skill, ctx, **kw):
        at_first_tick.append(len(dumps))
        return real_run(skill, ctx, **kw)

    monkeypatch.setattr(runtime, "run", run)
    report = runner.run()
    try:
        assert report.outcome == "completed", report.message
        assert at_first_tick == [3]  # go serialised and copied nothing before the skill ticked
        evidence = ws.root / report.evidence
        assert yaml.safe_load((evidence / "task.yaml").read_text())["session_id"] == "s1"
        assert isinstance(yaml.safe_load((evidence / "initial.yaml").read_text()), dict)
        bundle = yaml.safe_load((evidence / "bundle.yaml").read_text())
        assert bundle["files"]["initial_image"] == "initial.png"
        images.release(evidence)
    finally:
        images.close()
        pool.close()
    assert (evidence / "initial.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.sim
def test_the_preflight_judges_the_record_the_claim_writes_and_the_runner_does_not_parse_the_file(tmp_path,
                                                                                                 monkeypatch):
    ws = make_workspace(tmp_path / "ws")
    submit(ws, "s1", skill="hold", parameters=HOLD)
    sent: list[dict] = []
    real_send = RunnerProcess.send

    def spy(self, kind, **payload):
        if kind == "preflight":
            sent.append(payload)
        return real_send(self, kind, **payload)

    monkeypatch.setattr(RunnerProcess, "send", spy)
    sup = WatchdogSupervisor(ws)
    try:
        assert sup.run_once() == 1
    finally:
        sup.close()
    assert len(sent) == 1
    claim, written = sent[0]["record"], ws.load_session("s1")
    assert claim.session_id == "s1" and claim.state == "preflight_checking"
    assert claim.lease.token == sent[0]["token"]
    assert claim.transitions == written.transitions[:2]  # claim and preflight, as the claim wrote them

    # The runner's side, in this process: the record sent is what is judged and prepared,
    # even when the file it stands for cannot be parsed; without one, the file is read.
    near, far = multiprocessing.Pipe()
    runner = _Runner(near, Heartbeats(), skill_dirs(), tree_dirs())
    try:
        submit(ws, "s2", skill="hold", parameters=HOLD)
        record = ws.load_session("s2")
        ws.session_path("s2").write_text("# not a session any more\n")
        root = str(ws.root)
        runner.job_reserve(root, record.target)
        far.recv()
        runner.job_preflight(root, "s2", token="t", owner="test", record=record)
        kind, payload = far.recv()
        assert kind == "preflight" and payload["ok"], payload
        assert runner.prepared is not None and runner.prepared[1].record.session_id == "s2"
        runner.discard_prepared()
        with pytest.raises(DocumentError):
            runner.job_preflight(root, "s2", token="t", owner="test")
    finally:
        runner.release_all()
        runner.images.close()
        for pool in runner.pools.values():
            pool.close()
        near.close()
        far.close()
