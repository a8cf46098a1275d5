"""Workspace: layout, templates, locked updates, session files and bounded logs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from phyagentos.errors import DocumentError, ProtocolError
from phyagentos.protocol import (
    DOCUMENTS,
    SAFETY_FILE,
    Attempt,
    Document,
    EnvironmentDoc,
    LogEntry,
    SafetyConfig,
    SessionRecord,
    TaskDoc,
    TransitionRecord,
    Verdict,
    Workspace,
    export_json_schemas,
    parse_document,
    render_document,
    templates_dir,
)

REPO = Path(__file__).resolve().parents[1]
T0 = "2024-05-01T12:00:00Z"


@pytest.fixture
def ws(tmp_path) -> Workspace:
    return Workspace.create(tmp_path / "ws")


def make_record(session_id: str = "s1", **overrides) -> SessionRecord:
    fields = dict(
        session_id=session_id,
        run_id="run-1",
        node="pick_cube",
        skill="pick_place",
        target="franka_tabletop",
        parameters={"object": "cube", "place_xyz": [0.5, 0.1, 0.02]},
        created_at=T0,
        updated_at=T0,
    )
    fields.update(overrides)
    return SessionRecord(**fields)


def transition(source: str, dest: str, event: str) -> TransitionRecord:
    return TransitionRecord(at=T0, source=source, dest=dest, event=event)


def log_entry(at: str, message: str = "") -> LogEntry:
    return LogEntry(at=at, session_id="s1", node="pick_cube", event="transition", state="running", message=message)


# ---------------------------------------------------------------------------
# Templates and JSON Schemas.


def test_templates_parse_and_render_back_byte_for_byte():
    for name, (filename, model) in DOCUMENTS.items():
        text = (templates_dir() / filename).read_text(encoding="utf-8")
        assert render_document(parse_document(text, model)) == text, name


def test_templates_define_default_target_runtime_and_safety(ws):
    targets = ws.read("TARGETS").data.targets
    assert [(t.name, t.kind, t.driver, t.enabled) for t in targets] == [
        ("franka_tabletop", "simulation", "mujoco_franka", True),
        ("franka_kitchen", "simulation", "gymnasium_kitchen", True),
        ("so101_tabletop", "simulation", "mujoco_so101", True),
        ("crafter", "game", "crafter", True),
    ]
    assert targets[0].action == {"space": "joint_position", "dof": 7, "gripper": "opening_m", "control_rate_hz": 500}
    runtime = ws.read("SKILLRUNTIME").data.runtimes[0]
    assert (runtime.name, runtime.orchestration) == ("builtin", "behaviour_tree")
    safety = ws.read_safety()
    assert safety == SafetyConfig()
    assert safety.workspace_box.min == [-0.2, -0.8, -0.01] and safety.workspace_box.max == [1.0, 0.8, 1.2]


def test_committed_json_schemas_are_up_to_date(tmp_path):
    committed = templates_dir() / "schemas"
    generated = {p.name: p.read_text(encoding="utf-8") for p in export_json_schemas(tmp_path)}
    on_disk = {p.name: p.read_text(encoding="utf-8") for p in committed.glob("*.schema.json")}
    assert on_disk == generated, (
        "phyagentos/data/protocol/schemas is stale; regenerate with "
        "python -c \"from phyagentos.protocol import export_json_schemas as e; e('phyagentos/data/protocol/schemas')\""
    )


# ---------------------------------------------------------------------------
# create / open / read / update.


def test_create_makes_layout_and_copies_every_template(ws):
    for sub in ("sessions", "evidence", "targets", ".locks"):
        assert (ws.root / sub).is_dir()
    for filename, _ in DOCUMENTS.values():
        assert (ws.root / filename).read_bytes() == (templates_dir() / filename).read_bytes()
    assert (ws.root / SAFETY_FILE).read_bytes() == (templates_dir() / SAFETY_FILE).read_bytes()


def test_create_never_overwrites_existing_documents(ws):
    task = ws.path("TASK")
    task.write_text(task.read_text(encoding="utf-8").replace("# Task", "# My task notes"), encoding="utf-8")
    before = task.read_bytes()
    ws.path("LOG").unlink()

    Workspace.create(ws.root)

    assert task.read_bytes() == before
    assert ws.path("LOG").read_bytes() == (templates_dir() / "LOG.md").read_bytes()


def test_create_rejects_malformed_document_and_leaves_it_intact(tmp_path):
    root = tmp_path / "ws"
    root.mkdir()
    bad = "# Task\n\n```yaml\nversion: 1\nnodez: []\n```\n"
    (root / "TASK.md").write_text(bad, encoding="utf-8")

    with pytest.raises(DocumentError) as info:
        Workspace.create(root)

    assert (info.value.path, info.value.line) == (root / "TASK.md", 5)
    assert (root / "TASK.md").read_text(encoding="utf-8") == bad


def test_create_rejects_malformed_safety_yaml_with_line(tmp_path):
    root = tmp_path / "ws"
    root.mkdir()
    bad = "version: 1\nmax_joint_velocity_scale: 1.5\n"
    (root / SAFETY_FILE).write_text(bad, encoding="utf-8")

    with pytest.raises(DocumentError) as info:
        Workspace.create(root)

    assert info.value.line == 2 and "max_joint_velocity_scale" in str(info.value)
    assert (root / SAFETY_FILE).read_text(encoding="utf-8") == bad


def test_open_requires_an_existing_workspace(tmp_path):
    with pytest.raises(ProtocolError, match="no workspace"):
        Workspace.open(tmp_path / "nowhere")
    Workspace.create(tmp_path / "ws")
    assert Workspace.open(tmp_path / "ws").root == tmp_path / "ws"


def test_unknown_document_name_lists_valid_names(ws):
    with pytest.raises(ProtocolError, match="'TASK'"):
        ws.path("TASKS")
    assert ws.path("TASK.md") == ws.root / "TASK.md"


def test_update_mutates_data_and_preserves_prose(ws):
    path = ws.path("TASK")
    path.write_text(path.read_text(encoding="utf-8") + "\n<!-- operator note: ünïcode -->\n", encoding="utf-8")

    def add_node(task: TaskDoc) -> None:
        task.run_id = "run-1"
        task.nodes.append({"id": "n1", "skill": "pick_place", "target": "franka_tabletop", "state": "ready"})

    ws.update("TASK", add_node)

    doc = ws.read("TASK")
    assert doc.data.run_id == "run-1" and doc.data.nodes[0].state == "ready"
    assert doc.suffix.endswith("<!-- operator note: ünïcode -->\n")


def test_update_accepts_a_returned_replacement_and_bumps_revision(ws):
    ws.update("ENVIRONMENT", lambda env: EnvironmentDoc(target="franka_tabletop"))
    ws.update("ENVIRONMENT", lambda env: None)
    env = ws.read("ENVIRONMENT").data
    assert env.target == "franka_tabletop" and env.revision == 2


def test_update_rejects_a_replacement_of_another_type(ws):
    before = ws.path("TASK").read_bytes()
    with pytest.raises(ProtocolError, match="expected TaskDoc"):
        ws.update("TASK", lambda task: EnvironmentDoc())
    assert ws.path("TASK").read_bytes() == before


def test_update_of_malformed_document_raises_and_never_overwrites(ws):
    path = ws.path("TASK")
    bad = "# Task\n\n```yaml\nversion: 1\nnodes:\n- id: n1\n  skill: s\n  target: t\n  state: done\n```\n"
    path.write_text(bad, encoding="utf-8")
    called = []

    with pytest.raises(DocumentError) as info:
        ws.update("TASK", called.append)

    assert info.value.line == 9 and "'done'" in str(info.value) and "'succeeded'" in str(info.value)
    assert called == []
    assert path.read_text(encoding="utf-8") == bad


def test_update_that_leaves_invalid_data_writes_nothing(ws):
    before = ws.path("TASK").read_bytes()

    def corrupt(task: TaskDoc) -> None:
        task.version = 7

    with pytest.raises(DocumentError, match="unsupported version 7"):
        ws.update("TASK", corrupt)
    assert ws.path("TASK").read_bytes() == before


def test_update_whose_function_raises_writes_nothing(ws):
    before = ws.path("TASK").read_bytes()

    def fail(task: TaskDoc) -> None:
        task.run_id = "changed"
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        ws.update("TASK", fail)
    assert ws.path("TASK").read_bytes() == before


def test_concurrent_updates_from_several_processes_lose_nothing(ws):
    script = (
        "import sys\n"
        "from phyagentos.protocol import Workspace, LogEntry\n"
        "ws = Workspace.open(sys.argv[1])\n"
        "for i in range(10):\n"
        "    ws.append_log(LogEntry(at='2024-05-01T12:00:00Z', event='tick', message=f'{sys.argv[2]}-{i}'))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    procs = [
        subprocess.Popen([sys.executable, "-c", script, str(ws.root), f"p{n}"], env=env) for n in range(4)
    ]
    assert [p.wait(timeout=120) for p in procs] == [0, 0, 0, 0]

    messages = [e.message for e in ws.read("LOG").data.entries]
    assert sorted(messages) == sorted(f"p{n}-{i}" for n in range(4) for i in range(10))


# ---------------------------------------------------------------------------
# Sessions.


def test_submit_session_writes_document_and_index(ws):
    ws.submit_session(make_record("s1"))

    path = ws.root / "sessions" / "s1.md"
    doc = parse_document(path.read_text(encoding="utf-8"), SessionRecord)
    assert doc.prefix.startswith("# Session s1\n")
    assert doc.data == make_record("s1")
    assert ws.load_session("s1") == make_record("s1")
    index = ws.read("SESSIONS").data.sessions
    assert [(e.session_id, e.state, e.skill) for e in index] == [("s1", "pending", "pick_place")]


def test_submit_session_rejects_duplicate_ids(ws):
    ws.submit_session(make_record("s1"))
    before = (ws.root / "sessions" / "s1.md").read_bytes()

    with pytest.raises(ProtocolError, match="already exists"):
        ws.submit_session(make_record("s1", skill="other"))
    assert (ws.root / "sessions" / "s1.md").read_bytes() == before


def test_submit_session_rejects_non_pending_state(ws):
    with pytest.raises(ProtocolError, match="'pending'.*'running'"):
        ws.submit_session(make_record("s1", state="running"))
    assert not (ws.root / "sessions" / "s1.md").exists()


def test_submit_session_rejects_invalid_values_assigned_after_construction(ws):
    record = make_record("s1")
    record.state = "bogus"
    with pytest.raises(ProtocolError, match="state"):
        ws.submit_session(record)


def test_session_ids_that_could_escape_the_sessions_dir_are_rejected(ws):
    with pytest.raises(ProtocolError, match="invalid session id"):
        ws.load_session("../TASK")
    with pytest.raises(ValueError):
        make_record("a/b")


def test_load_unknown_session_raises(ws):
    with pytest.raises(ProtocolError, match="unknown session 'nope'"):
        ws.load_session("nope")


def test_save_session_appends_transitions_and_sets_updated_at(ws):
    ws.submit_session(make_record("s1"))
    record = ws.load_session("s1")
    record.state = "claimed"
    record.transitions.append(transition("pending", "claimed", "claim"))

    saved = ws.save_session(record)

    assert saved.updated_at > T0
    stored = ws.load_session("s1")
    assert stored.state == "claimed" and stored.transitions == record.transitions
    assert ws.read("SESSIONS").data.sessions[0].state == "claimed"


def test_save_session_preserves_prose_in_the_session_file(ws):
    ws.submit_session(make_record("s1"))
    path = ws.root / "sessions" / "s1.md"
    path.write_text(path.read_text(encoding="utf-8") + "\nOperator: watch the cube.\n", encoding="utf-8")
    record = ws.load_session("s1")
    record.state = "claimed"

    ws.save_session(record)

    assert path.read_text(encoding="utf-8").endswith("\nOperator: watch the cube.\n")


def test_save_session_rejects_rewriting_an_earlier_transition(ws):
    ws.submit_session(make_record("s1"))
    record = ws.load_session("s1")
    record.transitions.append(transition("pending", "claimed", "claim"))
    ws.save_session(record)
    before = (ws.root / "sessions" / "s1.md").read_bytes()

    record.transitions[0] = transition("pending", "running", "claim")
    with pytest.raises(ProtocolError, match=r"session 's1'.*'transitions'"):
        ws.save_session(record)

    record.transitions = []
    with pytest.raises(ProtocolError, match="'transitions'"):
        ws.save_session(record)
    assert (ws.root / "sessions" / "s1.md").read_bytes() == before


def test_save_session_rejects_rewriting_an_earlier_attempt(ws):
    ws.submit_session(make_record("s1"))
    record = ws.load_session("s1")
    record.attempts.append(Attempt(number=1, started_at=T0, ended_at=T0, outcome="failed"))
    record.attempts.append(Attempt(number=2, started_at=T0))
    ws.save_session(record)

    record.attempts[0].outcome = "succeeded"
    with pytest.raises(ProtocolError, match=r"session 's1'.*'attempts'"):
        ws.save_session(record)
    record.attempts[0].outcome = "failed"

    record.attempts.pop(0)
    with pytest.raises(ProtocolError, match="'attempts'"):
        ws.save_session(record)


def test_save_session_lets_the_latest_attempt_gain_fields_but_not_change_them(ws):
    ws.submit_session(make_record("s1"))
    record = ws.load_session("s1")
    record.attempts.append(Attempt(number=1, started_at=T0, timings={"preflight": 0.5}))
    ws.save_session(record)

    record.attempts[0].ended_at = T0
    record.attempts[0].outcome = "completed"
    record.attempts[0].timings["execution"] = 4.0
    record.attempts[0].verdict = Verdict(verdict="success", reason="cube placed", at=T0)
    ws.save_session(record)
    assert ws.load_session("s1").attempts[0].verdict.verdict == "success"

    record.attempts[0].outcome = "aborted"
    with pytest.raises(ProtocolError, match=r"attempts\[0\]\.outcome"):
        ws.save_session(record)
    record.attempts[0].outcome = "completed"
    record.attempts[0].timings["preflight"] = 9.0
    with pytest.raises(ProtocolError, match=r"attempts\[0\]\.timings"):
        ws.save_session(record)


def test_save_session_rejects_changing_identity_fields(ws):
    ws.submit_session(make_record("s1"))
    record = ws.load_session("s1")
    record.node = "other_node"
    with pytest.raises(ProtocolError, match=r"session 's1'.*'node'"):
        ws.save_session(record)


def test_save_session_requires_a_submitted_session(ws):
    with pytest.raises(ProtocolError, match="unknown session"):
        ws.save_session(make_record("ghost"))


def test_save_session_is_reentrant_under_the_callers_session_lock(ws):
    ws.submit_session(make_record("s1"))
    with ws.session_lock("s1"):
        record = ws.load_session("s1")
        record.state = "claimed"
        ws.save_session(record)
    assert ws.load_session("s1").state == "claimed"


def test_save_session_never_overwrites_a_malformed_session_file(ws):
    ws.submit_session(make_record("s1"))
    path = ws.root / "sessions" / "s1.md"
    bad = path.read_text(encoding="utf-8").replace("state: pending", "state: [")
    path.write_text(bad, encoding="utf-8")

    with pytest.raises(DocumentError) as info:
        ws.save_session(make_record("s1"))
    assert info.value.line is not None
    assert path.read_text(encoding="utf-8") == bad


def test_list_sessions_filters_by_state(ws):
    ws.submit_session(make_record("s1"))
    ws.submit_session(make_record("s2", created_at="2024-05-01T12:00:01Z"))
    record = ws.load_session("s2")
    record.state = "running"
    ws.save_session(record)

    assert [r.session_id for r in ws.list_sessions()] == ["s1", "s2"]
    assert [r.session_id for r in ws.list_sessions(states=["running"])] == ["s2"]
    with pytest.raises(ProtocolError, match="'runing'"):
        ws.list_sessions(states=["runing"])


def test_index_keeps_active_sessions_and_only_the_most_recent_terminal_ones(ws):
    ws.INDEX_MAX_TERMINAL = 2
    for n in range(5):
        ws.submit_session(make_record(f"s{n}"))
    for n in range(4):  # s0..s3 finish, in that order; s4 stays pending
        record = ws.load_session(f"s{n}")
        record.state = "succeeded"
        ws.save_session(record)

    ids = [e.session_id for e in ws.read("SESSIONS").data.sessions]
    assert ids == ["s4", "s3", "s2"]
    assert [e.session_id for e in ws.rebuild_index().data.sessions] == ["s4", "s3", "s2"]


def test_evidence_dir_is_created_per_session(ws):
    path = ws.evidence_dir("s1")
    assert path == ws.root / "evidence" / "s1" and path.is_dir()


# ---------------------------------------------------------------------------
# LOG.md


def test_log_stays_bounded_and_archives_oldest_entries_by_month(ws):
    assert ws.LOG_MAX_ENTRIES == 200
    old = [log_entry("2024-04-30T23:59:59Z", "april")] + [log_entry(T0, f"may-{i}") for i in range(199)]
    ws.update("LOG", lambda doc: setattr(doc, "entries", old))

    ws.append_log(log_entry("2024-06-01T00:00:00Z", "june-0"))
    ws.append_log(log_entry("2024-06-01T00:00:01Z", "june-1"))

    entries = ws.read("LOG").data.entries
    assert len(entries) == 200
    assert [e.message for e in entries[:1] + entries[-2:]] == ["may-1", "june-0", "june-1"]
    april = (ws.root / "log" / "archive-2024-04.jsonl").read_text(encoding="utf-8").splitlines()
    may = (ws.root / "log" / "archive-2024-05.jsonl").read_text(encoding="utf-8").splitlines()
    assert [json.loads(line)["message"] for line in april] == ["april"]
    assert [json.loads(line)["message"] for line in may] == ["may-0"]
    assert LogEntry.model_validate(json.loads(may[0])) == old[1]


def test_log_below_the_bound_archives_nothing(ws):
    for i in range(3):
        ws.append_log(log_entry(T0, str(i)))
    assert [e.message for e in ws.read("LOG").data.entries] == ["0", "1", "2"]
    assert not (ws.root / "log").exists()


def test_append_log_to_malformed_log_raises_and_keeps_file(ws):
    path = ws.path("LOG")
    bad = "# Log\n```yaml\nversion: 1\nentries:\n- at: yesterday\n  event: x\n```\n"
    path.write_text(bad, encoding="utf-8")
    with pytest.raises(DocumentError) as info:
        ws.append_log(log_entry(T0))
    assert info.value.line == 5 and "ISO-8601" in str(info.value)
    assert path.read_text(encoding="utf-8") == bad


def test_documents_written_by_the_workspace_reparse_with_document_api(ws):
    ws.append_log(log_entry(T0, "multi\nline message  \nwith trailing spaces"))
    doc = ws.read("LOG")
    assert isinstance(doc, Document)
    assert doc.data.entries[0].message == "multi\nline message  \nwith trailing spaces"
