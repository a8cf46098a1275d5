"""Helpers for the supervisor tests: real workspaces, real ``phyagentos`` processes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from phyagentos.protocol import SessionRecord, Workspace, utc_now_iso
from phyagentos.protocol.codec import read_document
from phyagentos.protocol.schemas import DOCUMENTS, RunRecord

CLI = [sys.executable, "-m", "phyagentos.cli"]
ROOT = Path(__file__).resolve().parents[1]


def make_workspace(path: Path, *, targets: int = 1) -> Workspace:
    """A workspace whose TARGETS.md holds ``targets`` copies of the simulated Franka."""
    ws = Workspace.create(path)
    if targets > 1:
        def clone(doc):
            base = doc.targets[0]
            doc.targets = [base.model_copy(update={"name": f"franka_{i}"}) for i in range(targets)]

        ws.update("TARGETS", clone)
    return ws


def target_names(ws: Workspace) -> list[str]:
    return [t.name for t in ws.read("TARGETS").data.targets]


def submit(ws: Workspace, session_id: str, *, skill: str = "noop", target: str | None = None,
           parameters: dict | None = None, run_id: str = "r-test", limits: dict | None = None,
           accept: dict | None = None) -> SessionRecord:
    now = utc_now_iso()
    fields = dict(session_id=session_id, run_id=run_id, node=session_id, skill=skill,
                  target=target or target_names(ws)[0], parameters=parameters or {}, created_at=now, updated_at=now)
    if limits:
        fields["limits"] = limits
    if accept is not None:
        fields["accept"] = accept
    return ws.submit_session(SessionRecord(**fields))


def watch(ws: Workspace | Path, *args: str, log: Path | None = None) -> subprocess.Popen:
    """Start ``phyagentos watch`` as a real process."""
    root = ws.root if isinstance(ws, Workspace) else Path(ws)
    err = open(log, "ab") if log is not None else subprocess.DEVNULL
    return subprocess.Popen([*CLI, "watch", str(root), *args], stdout=subprocess.DEVNULL, stderr=err, cwd=ROOT)


def stop(proc: subprocess.Popen, *, sig: int = signal.SIGTERM, timeout: float = 60.0) -> int:
    """Signal ``proc`` and wait for its exit code."""
    if proc.poll() is None:
        proc.send_signal(sig)
    return proc.wait(timeout=timeout)


def wait_for(predicate: Callable[[], object], *, timeout: float, interval: float = 0.05, what: str = "") -> object:
    """Poll ``predicate`` until it returns something truthy; AssertionError on timeout."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what or predicate}")
        time.sleep(interval)


def state_of(ws: Workspace, session_id: str) -> str:
    return ws.load_session(session_id).state


def presence(ws: Workspace) -> list[dict]:
    out = []
    directory = ws.root / ".supervisors"
    for path in sorted(directory.glob("*.json")) if directory.is_dir() else []:
        try:
            out.append(json.loads(path.read_text()))
        except (OSError, ValueError):
            continue
    return out


def runner_pid(ws: Workspace, supervisor_pid: int, *, timeout: float = 30.0) -> int:
    """The pid of the runner process of the supervisor ``supervisor_pid`` (a child of it)."""
    def find():
        for rec in presence(ws):
            pid = rec.get("runner_pid")
            if rec.get("pid") == supervisor_pid and pid and descends_from(pid, supervisor_pid):
                return pid
        return None

    return wait_for(find, timeout=timeout, what=f"runner of supervisor {supervisor_pid}")


def descends_from(pid: int, ancestor: int, *, depth: int = 3) -> bool:
    """True if ``ancestor`` is a parent, grandparent ... of ``pid`` (runners are forked by a
    forkserver that is itself a child of the supervisor)."""
    for _ in range(depth):
        pid = parent_of(pid)
        if pid is None:
            return False
        if pid == ancestor:
            return True
    return False


def parent_of(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return int(fh.read().rsplit(")", 1)[1].split()[1])
    except (OSError, ValueError, IndexError):
        return None


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    state = _proc_state(pid)
    return state not in (None, "Z")


def _proc_state(pid: int) -> str | None:
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return None


def all_session_records(ws: Workspace) -> dict[str, SessionRecord]:
    """Every session, active and archived, parsed from its file."""
    return {r.session_id: r for r in ws.list_sessions()}


def assert_every_document_parses(ws: Workspace) -> int:
    """Parse every protocol document, session file, run record and evidence YAML; returns how many."""
    import yaml

    count = 0
    for key in DOCUMENTS:
        ws.read(key)
        count += 1
    for path in ws.root.joinpath("sessions").rglob("*.md"):
        read_document(path, SessionRecord)
        count += 1
    for path in ws.root.joinpath("runs").glob("*/RUN.md"):
        read_document(path, RunRecord)
        count += 1
    for path in [*ws.root.joinpath("evidence").rglob("*.yaml"), *ws.root.joinpath("targets").rglob("*.yaml")]:
        yaml.safe_load(path.read_text(encoding="utf-8"))
        count += 1
    return count



#: ``watch`` arguments of the kill drills: short leases, so take-overs come quickly.
DRILL_WATCH_ARGS = ("--lease-s", "1.0", "--poll-s", "0.2", "--cancel-grace-s", "1")


@dataclass
class Drill:
    """A kill drill's processes: one submitted run, its supervisors (``watch``, real
    processes) and an agent (``agent``)."""

    ws: Workspace
    run_id: str
    sups: list[subprocess.Popen]
    agent: subprocess.Popen
    log: Path

    @classmethod
    def start(cls, ws: Workspace, graph: Path, tmp_path: Path, *, supervisors: int) -> Drill:
        """Submit ``graph`` and start ``supervisors`` supervisors and one agent."""
        out = subprocess.run([*CLI, "submit", str(graph), "--workspace", str(ws.root)], capture_output=True,
                             text=True, timeout=120, cwd=ROOT)
        assert out.returncode == 0, out.stderr
        log = tmp_path / "watch.log"
        sups = [watch(ws, *DRILL_WATCH_ARGS, log=log) for _ in range(supervisors)]
        agent = subprocess.Popen([*CLI, "agent", str(ws.root), "--poll-s", "0.2"], stdout=subprocess.DEVNULL,
                                 stderr=open(tmp_path / "agent.log", "ab"), cwd=ROOT)
        return cls(ws, out.stdout.strip(), sups, agent, log)

    def kill_supervisor(self, k: int) -> None:
        """SIGKILL supervisor ``k`` and start a new one in its place."""
        self.sups[k].send_signal(signal.SIGKILL)
        self.sups[k].wait(timeout=30)
        self.sups[k] = watch(self.ws, *DRILL_WATCH_ARGS, log=self.log)

    def stop(self) -> list[int]:
        """Stop the supervisors (their exit codes) and the agent (which must exit 0)."""
        codes = [stop(p) for p in self.sups]
        assert stop(self.agent) == 0
        return codes

def assert_run_ended_whole(ws: Workspace, run_id: str, nodes: set[str]) -> list[SessionRecord]:
    """After a kill drill: no corrupted document, nothing left active, no lost node, every
    session terminal and the run finished. Returns the run's sessions."""
    from phyagentos.protocol import TERMINAL_STATES

    assert assert_every_document_parses(ws) > len(nodes)
    assert ws.active_sessions() == []
    records = ws.list_sessions(run_id=run_id)
    assert {r.node for r in records} == nodes  # no lost node
    assert all(r.state in TERMINAL_STATES for r in records)
    assert ws.runs.load(run_id).state == "finished"
    return records
