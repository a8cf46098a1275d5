"""One bad file never disables anything else (issue 11, item 3), through the CLI.

Each corrupted or hostile stored document ends its own run (or session) ``failed``
with the error (file, line) in ``status``; other runs go on; the bad file itself is
never rewritten; no command prints a file outside the workspace; error messages quote
bounded excerpts; YAML alias bombs fail in milliseconds.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from phyagentos.cli import main
from phyagentos.errors import DocumentError
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

REPO = Path(__file__).resolve().parent.parent
HOLD = goal_graphs_dir() / "hold.yaml"

BOMB = "\n".join(["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
                 + [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)])


def submit(ws: Path, capsys, graph: Path = HOLD) -> str:
    assert main(["submit", str(graph), "--workspace", str(ws)]) == 0
    return capsys.readouterr().out.strip().splitlines()[-1]


def agent_run(ws: Path, run_id: str) -> int:
    return main(["agent", str(ws), "--run", run_id, "--poll-s", "0.1", "--no-inotify"])


CORRUPTIONS = {
    "truncated": lambda b: b[: len(b) // 2],
    "emptied": lambda b: b"",
    "invalid_utf8": lambda b: b.replace(b"version", b"vers\xff\xfeion", 1),
    "duplicate_key": lambda b: b.replace(b"version: 1\n", b"version: 1\nversion: 1\n", 1),
    "tabs": lambda b: b.replace(b"version: 1\n", b"version: 1\n\tseed: 3\n", 1),
}


@pytest.mark.parametrize("which", ["goal_graph.yaml", "RUN.md"])
@pytest.mark.parametrize("how", sorted(CORRUPTIONS))
def test_a_corrupted_stored_run_is_set_aside_as_failed_and_agent_run_exits_non_zero(tmp_path, capsys, which, how):
    ws = tmp_path / "ws"
    run_id = submit(ws, capsys)
    path = ws / "runs" / run_id / which
    bad = CORRUPTIONS[how](path.read_bytes())
    path.write_bytes(bad)

    assert main(["status", str(ws)]) == 2  # an active run that no longer validates is bad input
    out = capsys.readouterr().out
    assert f"run {run_id}: error:" in out and which in out

    assert agent_run(ws, run_id) == 2  # returns (it used to log the error and never return)
    err = capsys.readouterr().err
    assert f"set aside run {run_id} (failed)" in err and str(path) in err

    assert path.read_bytes() == bad  # the bad file is reported, never rewritten
    assert Workspace.open(ws).runs.active_ids() == []
    assert main(["status", str(ws)]) == 0
    out = capsys.readouterr().out
    assert f"{run_id}: failed: set aside" in out and which in out
    assert agent_run(ws, run_id) == 2  # and again, at once
    assert "was set aside" in capsys.readouterr().err


def test_a_bad_run_does_not_stop_the_agent_from_driving_the_others(tmp_path, capsys):
    from phyagentos.agent.agent_loop import AgentLoop
    from phyagentos.app.orchestrator import skill_names

    ws = tmp_path / "ws"
    bad, good = submit(ws, capsys), submit(ws, capsys)
    (ws / "runs" / bad / "goal_graph.yaml").write_text("version: 1\nname: [", encoding="utf-8")
    loop = AgentLoop(Workspace.open(ws), skills=skill_names(), inotify=False)
    try:
        loop.step()
    finally:
        loop.close()
    assert bad in loop.set_aside_runs and Workspace.open(ws).runs.active_ids() == [good]
    assert loop.coordinator(good) is not None


def test_an_unknown_run_id_exits_non_zero_and_lists_the_runs(tmp_path, capsys):
    ws = tmp_path / "ws"
    run_id = submit(ws, capsys)
    assert agent_run(ws, "no-such-run") == 2
    err = capsys.readouterr().err
    assert "unknown run 'no-such-run'" in err and run_id in err


def test_a_stored_graph_symlinked_out_of_the_workspace_is_never_printed(tmp_path, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x:0:0:SECRET-CONTENT-7d1f:/root:/bin/bash\n", encoding="utf-8")
    ws = tmp_path / "ws"
    run_id = submit(ws, capsys)
    graph = ws / "runs" / run_id / "goal_graph.yaml"
    graph.unlink()
    graph.symlink_to(secret)
    assert main(["status", str(ws)]) == 2
    captured = capsys.readouterr()
    assert "SECRET-CONTENT" not in captured.out + captured.err and "leads out of the workspace" in captured.out
    assert main(["status", str(ws), "--json"]) == 2
    assert "SECRET-CONTENT" not in capsys.readouterr().out
    assert agent_run(ws, run_id) == 2
    captured = capsys.readouterr()
    assert "SECRET-CONTENT" not in captured.out + captured.err and "leads out of the workspace" in captured.err
    assert secret.read_text(encoding="utf-8").startswith("root:x")


def test_an_error_quotes_a_bounded_excerpt_of_a_five_megabyte_line(tmp_path, capsys):
    graph = tmp_path / "huge.yaml"
    graph.write_text(HOLD.read_text(encoding="utf-8").replace("skill: hold", "skill: " + "x" * 5_000_000), encoding="utf-8")
    assert main(["validate", str(graph)]) == 2
    err = capsys.readouterr().err
    assert "unknown skill" in err and len(err) < 3000


@pytest.mark.parametrize("where", ["params", "scene"])
def test_an_alias_bomb_in_a_goal_graph_is_refused_in_milliseconds(tmp_path, capsys, where):
    text = HOLD.read_text(encoding="utf-8")
    if where == "params":
        text = text.replace("params: {", "params: {bomb: *a9, ", 1) if "params: {" in text else text
    graph = tmp_path / "bomb.yaml"
    graph.write_text(BOMB + "\n" + (text if where == "params" else text + "scene:\n  objects: *a9\n"), encoding="utf-8")
    ws = tmp_path / "ws"
    Workspace.create(ws)
    for argv in (["validate", str(graph)], ["submit", str(graph), "--workspace", str(ws)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert f"{graph}:" in err and "YAML aliases expand to more than" in err
    assert Workspace.open(ws).runs.active_ids() == []
    # the loader itself refuses it at once (unbounded, it would expand to 9**10 nodes);
    # a generous bound: it separates "refused" from "expanding", not fast from slow
    from phyagentos.agent.goal_graph import load_goal_graph
    from phyagentos.errors import GoalGraphError

    started = time.perf_counter()
    with pytest.raises(GoalGraphError, match="YAML aliases expand"):
        load_goal_graph(graph, skills=["hold"], targets=["franka_tabletop"])
    assert time.perf_counter() - started < 2.0


def test_an_alias_bomb_in_a_pending_session_is_refused_in_milliseconds_and_sets_the_run_aside(tmp_path, capsys):
    ws = tmp_path / "ws"
    run_id = submit(ws, capsys)
    workspace = Workspace.open(ws)
    [(sid, state, _)] = workspace.active_sessions(run_id=run_id)
    assert state == "pending"
    path = workspace.session_path(sid)
    text = path.read_text(encoding="utf-8")
    indented = "\n".join("  " + line for line in BOMB.splitlines())
    bad = text.replace("parameters:", "bomb:\n" + indented + "\nparameters:", 1)
    path.write_text(bad, encoding="utf-8")
    started = time.perf_counter()
    with pytest.raises(DocumentError, match="YAML aliases expand to more than"):
        workspace.load_session(sid)
    assert time.perf_counter() - started < 2.0  # refused, not expanded (see above)
    assert agent_run(ws, run_id) == 2
    assert path.read_text(encoding="utf-8") == bad


def test_a_duplicate_key_in_one_session_sets_aside_that_run_and_reconcile_goes_on(tmp_path, capsys):
    from phyagentos.agent.agent_loop import AgentLoop
    from phyagentos.app.orchestrator import skill_names

    ws = tmp_path / "ws"
    bad, good = submit(ws, capsys), submit(ws, capsys)
    workspace = Workspace.open(ws)
    [(sid, _, _)] = workspace.active_sessions(run_id=bad)
    path = workspace.session_path(sid)
    edited = path.read_text(encoding="utf-8").replace("skill: hold\n", "skill: hold\nskill: hold\n", 1)
    path.write_text(edited, encoding="utf-8")
    assert workspace.reconcile().get("malformed") == 1 and sid in workspace.malformed  # watch starts anyway
    loop = AgentLoop(workspace, skills=skill_names(), inotify=False)
    try:
        loop.step()
    finally:
        loop.close()
    assert bad in loop.set_aside_runs and "duplicate key" in loop.set_aside_runs[bad]
    assert workspace.runs.active_ids() == [good]
    assert path.read_text(encoding="utf-8") == edited


def test_a_truncated_safety_yaml_is_refused_not_filled_with_defaults(tmp_path, capsys):
    ws = tmp_path / "ws"
    Workspace.create(ws)
    safety = ws / "safety.yaml"
    text = safety.read_text(encoding="utf-8").replace("max_command_duration_s: 30", "max_command_duration_s: 2")
    cut = text[: text.index("max_command_rate_hz")]
    safety.write_text(cut, encoding="utf-8")
    before = {p: p.read_bytes() for p in ws.rglob("*") if p.is_file()}
    assert main(["run", str(HOLD), "--workspace", str(ws)]) == 2
    err = capsys.readouterr().err
    assert "safety.yaml is incomplete: missing" in err and "max_command_rate_hz" in err
    assert {p: p.read_bytes() for p in ws.rglob("*") if p.is_file()} == before
    assert not (ws / "targets").exists() or not list((ws / "targets").rglob("state.*"))


def test_reconcile_removes_temp_files_of_killed_writers_and_presence_of_dead_supervisors(tmp_path):
    ws = tmp_path / "ws"
    workspace = Workspace.create(ws)
    old = time.time() - 3600
    stale = [ws / ".TASK.md.k2j3h4.tmp", ws / "sessions" / ".r1-pick-1.md.abcd.tmp"]
    fresh = ws / "sessions" / ".r1-pick-2.md.efgh.tmp"  # a write in progress right now
    for p in stale + [fresh]:
        p.write_text("version: 1\nsession_id: r1-pick-1\n", encoding="utf-8")
    for p in stale:
        os.utime(p, (old, old))
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    presence = ws / ".supervisors"
    presence.mkdir()
    import socket
    (presence / f"{dead.pid}-dead.json").write_text(
        f'{{"owner": "{socket.gethostname()}:{dead.pid}:dead", "pid": {dead.pid}}}', encoding="utf-8")
    (presence / f"{os.getpid()}-live.json").write_text(
        f'{{"owner": "{socket.gethostname()}:{os.getpid()}:live", "pid": {os.getpid()}}}', encoding="utf-8")
    fixed = workspace.reconcile()
    assert fixed["temp_files"] == 2 and fixed["dead_presence"] == 1
    assert not any(p.exists() for p in stale) and fresh.exists()
    assert sorted(p.name for p in presence.iterdir()) == [f"{os.getpid()}-live.json"]


def test_submit_says_when_no_agent_serves_the_workspace_and_status_keeps_finished_runs(tmp_path, capsys):
    ws = tmp_path / "ws"
    assert main(["submit", str(HOLD), "--workspace", str(ws)]) == 0
    captured = capsys.readouterr()
    run_id = captured.out.strip()
    assert "no agent serves" in captured.err and "phyagentos agent" in captured.err
    assert "no supervisor watches" in captured.err
    Workspace.open(ws).runs.finish(run_id, succeeded=True)
    assert main(["status", str(ws)]) == 0
    assert f"{run_id}: succeeded" in capsys.readouterr().out


def test_two_runs_on_one_target_never_reset_each_others_world_the_second_queues(tmp_path, capsys, caplog):
    import logging

    from phyagentos.agent.agent_loop import AgentLoop
    from phyagentos.app.orchestrator import skill_names
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.supervisor import WatchdogSupervisor

    ws = tmp_path / "ws"
    first, second = submit(ws, capsys), submit(ws, capsys)
    workspace = Workspace.open(ws)
    [(sid2, _, _)] = workspace.active_sessions(run_id=second)
    sup = WatchdogSupervisor(workspace, BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir()))
    agent = AgentLoop(workspace, skills=skill_names(), inotify=False)
    try:
        with caplog.at_level(logging.INFO, logger="phyagentos.runtime.supervisor"):
            sup.run_once()
        assert workspace.runs.world_owner("franka_tabletop") == first
        assert workspace.load_session(sid2).state == "pending"  # queued, not started on the first run's world
        assert f"target franka_tabletop holds the world of run {first}" in caplog.text
        capsys.readouterr()
        # `run` drives one run in-process: it refuses and says which run holds the world
        assert main(["run", str(HOLD), "--workspace", str(ws)]) == 2
        assert f"target 'franka_tabletop' holds the world of active run '{first}'" in capsys.readouterr().err
        # `submit` queues, and says so
        assert main(["submit", str(HOLD), "--workspace", str(ws)]) == 0
        assert f"holds the world of run {first} until it finishes" in capsys.readouterr().err
        for _ in range(50):
            agent.step()
            if first not in workspace.runs.active_ids():
                break
            sup.run_once()
        assert first not in workspace.runs.active_ids()
        sup.run_once()  # the first run finished: the second takes the world
        assert workspace.runs.world_owner("franka_tabletop") == second
        assert workspace.load_session(sid2).state != "pending"
    finally:
        agent.close()
        sup.close()


@pytest.mark.parametrize("evidence_file", ["bundle.yaml", "terminal.yaml"])
def test_an_alias_bomb_in_an_evidence_file_is_refused_in_milliseconds_and_sets_the_run_aside(
        tmp_path, capsys, evidence_file):
    """The SessionVerifier reads evidence with the bounded loader: a bomb in the bundle
    index or a snapshot is a VerifierError with the file and the anchor's line, the run
    is set aside (``agent --run`` exits 2 at once), the evidence file is left as it is."""
    from phyagentos.agent.verifier import load_evidence
    from phyagentos.errors import VerifierError
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.supervisor import WatchdogSupervisor

    ws = tmp_path / "ws"
    run_id = submit(ws, capsys)
    workspace = Workspace.open(ws)
    [(sid, _, _)] = workspace.active_sessions(run_id=run_id)
    sup = WatchdogSupervisor(workspace, BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir()))
    try:
        for _ in range(200):
            sup.run_once()
            if workspace.load_session(sid).state == "awaiting_verification":
                break
            time.sleep(0.05)
    finally:
        sup.close()
    rec = workspace.load_session(sid)
    assert rec.state == "awaiting_verification"
    directory = ws / rec.attempts[-1].evidence
    path = directory / evidence_file
    bad = path.read_text(encoding="utf-8") + "\n" + BOMB + "\n"
    path.write_text(bad, encoding="utf-8")
    first = bad.splitlines().index(BOMB.splitlines()[0]) + 1
    bomb_lines = range(first, first + len(BOMB.splitlines()))  # the anchor that expands too far is one of them

    started = time.perf_counter()
    with pytest.raises(VerifierError, match="YAML aliases expand to more than") as exc:
        load_evidence(directory)
    assert time.perf_counter() - started < 0.5  # refused, not expanded
    assert exc.value.path == path and exc.value.line in bomb_lines
    where = f"{path}:{exc.value.line}"

    started = time.perf_counter()
    assert agent_run(ws, run_id) == 2
    assert time.perf_counter() - started < 30.0  # returns: nothing hangs on the bomb
    err = capsys.readouterr().err
    assert f"set aside run {run_id} (failed)" in err and where in err
    assert path.read_text(encoding="utf-8") == bad
    assert Workspace.open(ws).runs.active_ids() == []
    assert main(["status", str(ws)]) == 0
    assert f"{run_id}: failed: set aside" in capsys.readouterr().out


def test_an_alias_bomb_in_a_pending_session_never_hangs_the_supervisors_claim(tmp_path, capsys, caplog):
    """The supervisor's claim reads the session with the bounded loader: the bombed
    session is set aside with a warning naming the file and line, in well under a second
    of work, the file is left as it is and the session is never claimed."""
    import logging

    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.supervisor import WatchdogSupervisor

    ws = tmp_path / "ws"
    run_id = submit(ws, capsys)
    workspace = Workspace.open(ws)
    [(sid, _, _)] = workspace.active_sessions(run_id=run_id)
    path = workspace.session_path(sid)
    text = path.read_text(encoding="utf-8")
    indented = "\n".join("  " + line for line in BOMB.splitlines())
    bad = text.replace("parameters:", "bomb:\n" + indented + "\nparameters:", 1)
    path.write_text(bad, encoding="utf-8")
    sup = WatchdogSupervisor(workspace, BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir()))
    try:
        with caplog.at_level(logging.WARNING, logger="phyagentos.runtime.supervisor"):
            started = time.perf_counter()
            sup.run_once()
            elapsed = time.perf_counter() - started
    finally:
        sup.close()
    assert elapsed < 10.0  # a claim, not a multi-gigabyte expansion (that never returned)
    assert f"session {sid} set aside" in caplog.text and "YAML aliases expand to more than" in caplog.text
    assert str(path) in caplog.text
    assert path.read_text(encoding="utf-8") == bad
    assert not list((ws / "targets").rglob("state.*")) if (ws / "targets").exists() else True


@pytest.mark.parametrize("where", ["skills/hold.yaml", "trees/hold.yaml", "safety.yaml"])
def test_an_alias_bomb_in_a_skill_tree_or_safety_file_is_refused_with_file_and_line(tmp_path, capsys, where):
    """Skills and trees of the workspace and its ``safety.yaml`` are bounded like goal
    graphs: ``run`` exits 2 naming the file and line, the workspace unchanged, nothing moved."""
    from phyagentos.resources import skills_dir, trees_dir

    ws = tmp_path / "ws"
    Workspace.create(ws)
    path = ws / where
    if where != "safety.yaml":
        path.parent.mkdir(exist_ok=True)
        source = (skills_dir() if where.startswith("skills") else trees_dir()) / "hold.yaml"
        path.write_text(BOMB + "\n" + source.read_text(encoding="utf-8"), encoding="utf-8")
    else:
        path.write_text(BOMB + "\n" + path.read_text(encoding="utf-8"), encoding="utf-8")
    before = {p: p.read_bytes() for p in ws.rglob("*") if p.is_file()}
    started = time.perf_counter()
    assert main(["run", str(HOLD), "--workspace", str(ws)]) == 2
    assert time.perf_counter() - started < 30.0
    err = capsys.readouterr().err
    assert re.search(rf"{re.escape(str(path))}:\d+: .*YAML aliases expand to more than", err), err
    assert "Traceback" not in err
    assert {p: p.read_bytes() for p in ws.rglob("*") if p.is_file()} == before
    assert not (ws / "targets").exists() or not list((ws / "targets").rglob("state.*"))
