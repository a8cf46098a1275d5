"""Shared helpers of the supervisor benchmarks (not a benchmark itself: `python -m bench` skips ``_*``)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.protocol import SessionRecord, Workspace, utc_now_iso

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "phyagentos.cli"]


def make_workspace(path: Path, *, targets: int = 1) -> Workspace:
    ws = Workspace.create(path)
    if targets > 1:
        def clone(doc):
            base = doc.targets[0]
            doc.targets = [base.model_copy(update={"name": f"franka_{i}"}) for i in range(targets)]

        ws.update("TARGETS", clone)
    return ws


def submit(ws: Workspace, session_id: str, *, skill: str = "noop", target: str = "franka_tabletop",
           parameters: dict | None = None, run_id: str = "r-bench", **fields) -> SessionRecord:
    now = utc_now_iso()
    return ws.submit_session(SessionRecord(session_id=session_id, run_id=run_id, node=session_id, skill=skill,
                                           target=target, parameters=parameters or {}, created_at=now,
                                           updated_at=now, **fields))


def start_watch(ws: Workspace, *args: str) -> subprocess.Popen:
    proc = subprocess.Popen([*CLI, "watch", str(ws.root), *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, cwd=ROOT)
    deadline = time.monotonic() + 120
    while not list((ws.root / ".supervisors").glob(f"{proc.pid}-*.json")):
        if time.monotonic() > deadline or proc.poll() is not None:
            raise RuntimeError("phyagentos watch did not start")
        time.sleep(0.05)
    return proc


def stop(proc: subprocess.Popen) -> int:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    return proc.wait(timeout=60)


def cpu_seconds(pid: int) -> float:
    """utime + stime of ``pid`` in seconds (Linux /proc)."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def descendants(pid: int) -> list[int]:
    """``pid``'s children, grandchildren ... (the runner and its forkserver)."""
    parents: dict[int, int] = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat", encoding="ascii") as fh:
                    parents[int(name)] = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue
    out, frontier = [], [pid]
    while frontier:
        nxt = [c for c, p in parents.items() if p in frontier]
        out += nxt
        frontier = nxt
    return out
