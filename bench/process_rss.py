"""Resident memory of a command and of every process it starts, sampled over time.

    .venv/bin/python bench/process_rss.py [--interval 0.2] [--out bench/results/process_rss.json] [-- COMMAND ...]

Without a command it measures one LIBERO episode through the normal bench path, in a fresh
temporary workspace (the looks of the task's categories are measured first, in the bench
process)::

    .venv/bin/phyagentos bench libero_object --tasks 5 --seeds 0 --json \
        --heartbeat-timeout 180 --queue-timeout 3000 --workspace <temporary>

Runs ``COMMAND`` and, every ``--interval`` seconds until it exits, reads ``VmRSS``,
``RssAnon`` and ``RssFile`` (``/proc/<pid>/status``, MiB) of the command's process and of
all its live descendants (the forkserver, each runner, the supervisor, the resource
tracker). Per process (by pid, with its parent, its command line and its role guessed from
them) the JSON holds the peak and the median ("steady") of each figure over the samples the
process lived through, and the whole time series (``t_s`` from the command's start). Prints
one table row per process. The command's own output goes to this terminal; its exit status
is this script's.

A runner is forked from the runtime's forkserver, whose module path starts with the working
directory: run from a checkout, the runners import that checkout's ``phyagentos`` whatever
``PYTHONPATH`` says (to measure another tree, run from outside both).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _harness import parser, print_table, write_json

_FIELDS = ("VmRSS", "RssAnon", "RssFile")


def _status_mib(pid: int) -> dict[str, float] | None:
    """``VmRSS``, ``RssAnon``, ``RssFile`` of ``pid`` in MiB, or None once it is gone."""
    out: dict[str, float] = {}
    try:
        with open(f"/proc/{pid}/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                key, _, rest = line.partition(":")
                if key in _FIELDS:
                    out[key] = int(rest.split()[0]) / 1024.0  # kB -> MiB
    except OSError:
        return None
    return out if len(out) == len(_FIELDS) else None


def _children_map() -> dict[int, list[int]]:
    """Parent pid -> child pids of every live process (from ``/proc/<pid>/stat``)."""
    kids: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as fh:
                ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        kids.setdefault(ppid, []).append(int(entry))
    return kids


def _tree(root: int) -> list[tuple[int, int]]:
    """``(pid, parent pid)`` of ``root`` and of its live descendants."""
    kids = _children_map()
    found, frontier = [(root, 0)], [root]
    while frontier:
        parent = frontier.pop()
        for child in kids.get(parent, []):
            found.append((child, parent))
            frontier.append(child)
    return found


def _cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().replace(b"\0", b" ").decode(errors="replace").strip()
    except OSError:
        return ""


def _role(pid: int, root: int, cmdline: str, parent_cmdline: str) -> str:
    """What the process is, from its command line and its parent's: a runner is forked
    from the forkserver and keeps its command line."""
    if pid == root:
        return "command"
    if "resource_tracker" in cmdline:
        return "resource_tracker"
    if "forkserver import main" in cmdline:
        return "runner" if "forkserver import main" in parent_cmdline else "forkserver"
    if "spawn_main" in cmdline:
        return "spawned child"
    return "child"


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "process_rss")
    ap.add_argument("--interval", type=float, default=0.2, help="seconds between samples (default 0.2)")
    ap.add_argument("command", nargs=argparse.REMAINDER,
                    help="after --: the command to run (default: one libero_object episode, see above)")
    args = ap.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    with tempfile.TemporaryDirectory(prefix="process_rss_") as tmp:
        if not command:
            command = [str(Path(sys.executable).with_name("phyagentos")), "bench", "libero_object", "--tasks", "5",
                       "--seeds", "0", "--json", "--heartbeat-timeout", "180", "--queue-timeout", "3000",
                       "--workspace", str(Path(tmp) / "ws")]
        return _measure(command, args.interval, args.out)


def _measure(command: list[str], interval: float, out: Path) -> int:
    """Run ``command``, sample it every ``interval`` s, write the JSON to ``out``; its exit status."""
    t0 = time.monotonic()
    proc = subprocess.Popen(command)
    procs: dict[int, dict] = {}
    while True:
        done = proc.poll() is not None
        t = round(time.monotonic() - t0, 2)
        for pid, ppid in _tree(proc.pid):
            mib = _status_mib(pid)
            if mib is None:
                continue
            entry = procs.get(pid)
            if entry is None:
                cmd = _cmdline(pid)
                parent = procs[ppid]["cmdline"] if ppid in procs else _cmdline(ppid)
                entry = procs[pid] = {"pid": pid, "ppid": ppid, "cmdline": cmd[:300],
                                      "role": _role(pid, proc.pid, cmd, parent), "samples": []}
            entry["samples"].append([t] + [round(mib[k], 1) for k in _FIELDS])
        if done:
            break
        time.sleep(interval)
    rc = proc.returncode
    rows, summary = [], []
    for entry in procs.values():
        s = entry["samples"]
        stats = {}
        for i, k in enumerate(_FIELDS, start=1):
            col = [row[i] for row in s]
            stats[k] = {"peak_mib": max(col), "median_mib": round(statistics.median(col), 1)}
        summary.append({"pid": entry["pid"], "ppid": entry["ppid"], "role": entry["role"], "cmdline": entry["cmdline"],
                        "first_s": s[0][0], "last_s": s[-1][0], **stats,
                        "series": {"columns": ["t_s", *_FIELDS], "rows": s}})
        rows.append([entry["pid"], entry["role"], f"{s[0][0]:.0f}-{s[-1][0]:.0f}",
                     f"{stats['VmRSS']['peak_mib']:.0f}", f"{stats['VmRSS']['median_mib']:.0f}",
                     f"{stats['RssAnon']['peak_mib']:.0f}", f"{stats['RssFile']['peak_mib']:.0f}"])
    print_table(["pid", "role", "alive s", "peak RSS MiB", "median RSS MiB", "peak anon MiB", "peak file MiB"],
                rows, align=["r", "l", "r", "r", "r", "r", "r"])
    write_json(out, {"command": command, "interval_s": interval, "returncode": rc,
                          "wall_s": round(time.monotonic() - t0, 1), "processes": summary})
    return rc


if __name__ == "__main__":
    sys.exit(main())
