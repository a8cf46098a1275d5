#!/usr/bin/env python3
"""Where the test suite's CPU goes: CPU-seconds per test file, per test and per kind of process.

On this project's 2-core CI machine the suite is CPU-bound (its four workers and their
``phyagentos`` processes keep both cores busy), so its wall time is the CPU its tests spend
over two; ``--durations`` gives wall time per test, which on a busy machine mostly measures
waiting. This runs pytest with the arguments given, samples every process's CPU time under
``/proc`` every ``--interval`` seconds, and charges each sampled increment to the test the
owning pytest worker was running at that moment (a process is owned by the nearest pytest
process among its ancestors: session runners forked from a forkserver, ``phyagentos run``
subprocesses, browsers and render processes are charged to the test that started them).

Usage::

    .venv/bin/python scripts/suite_cpu.py --out /tmp/suite_cpu.json -- -q -n 4 --dist loadfile --no-loadscope-reorder

Prints the files and tests that spent the most CPU and the kinds of process it went to, and
writes the whole table as JSON (``--out``). Limits: a process that lives less than one
interval may be missed, and one that left its test's process tree (a daemon that detached
itself) is counted as ``<unattributed>``; ``coverage`` compares what was charged with the
machine's own CPU count over the run (``/proc/stat``), which also includes everything else
the machine ran. Linux only.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_MARKS_ENV = "SUITE_CPU_MARKS"
_HZ = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


# -- pytest plugin (loaded in each pytest process with ``-p suite_cpu``) ---------------------

def _mark(kind: str, nodeid: str) -> None:
    directory = os.environ.get(_MARKS_ENV)
    if directory:
        with open(Path(directory) / f"{os.getpid()}.marks", "a", encoding="utf-8") as f:
            f.write(f"{kind} {time.time():.3f} {nodeid}\n")


def pytest_runtest_logstart(nodeid, location):  # noqa: ARG001 - pytest's hook signature
    _mark("S", nodeid)


def pytest_runtest_logfinish(nodeid, location):  # noqa: ARG001 - pytest's hook signature
    _mark("E", nodeid)


# -- sampling -------------------------------------------------------------------------------

def _machine_cpu_s() -> float:
    """CPU-seconds the whole machine has spent busy since boot (``/proc/stat``: user, nice,
    system, irq, softirq, steal)."""
    fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
    user, nice, system, _idle, _iowait, irq, softirq, steal = (int(x) for x in fields[:8])
    return (user + nice + system + irq + softirq + steal) / _HZ


class _Sampler(threading.Thread):
    """Every ``interval`` s: each live process's (pid, start time) -> parent, CPU-seconds,
    and its command line (the first one seen after its last ``exec``)."""

    def __init__(self, interval: float) -> None:
        super().__init__(name="suite-cpu-sampler", daemon=True)
        self.interval = interval
        self.stop = threading.Event()
        self.samples: list[tuple[float, list[tuple[tuple[int, int], int, float]]]] = []
        self.command: dict[tuple[int, int], str] = {}

    def run(self) -> None:
        while not self.stop.is_set():
            t = time.time()
            rows = []
            for name in os.listdir("/proc"):
                if not name.isdigit():
                    continue
                try:
                    stat = Path(f"/proc/{name}/stat").read_text()
                    comm = stat[stat.index("(") + 1:stat.rindex(")")]
                    rest = stat[stat.rindex(")") + 2:].split()
                    key = (int(name), int(rest[19]))
                    cpu = (int(rest[11]) + int(rest[12])) / _HZ
                    cmd = Path(f"/proc/{name}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
                except (OSError, ValueError, IndexError):
                    continue  # it exited between the listing and the read
                self.command[key] = cmd[:300] or f"[{comm}]"
                rows.append((key, int(rest[1]), cpu))
            self.samples.append((t, rows))
            self.stop.wait(max(0.0, self.interval - (time.time() - t)))


def kind_of(command: str) -> str:
    """A short name for the kind of process ``command`` is (its command line)."""
    c = command
    if "exec(eval(sys.stdin.readline()))" in c:  # how pytest-xdist (execnet) starts a worker
        return "pytest worker"
    if "-m pytest" in c or "/bin/pytest" in c:
        return "pytest"
    if "multiprocessing.forkserver" in c:
        return "forkserver and runners"
    if "multiprocessing.spawn" in c or "multiprocessing.resource_tracker" in c:
        return "multiprocessing child"
    if "phyagentos.cli" in c or "/bin/phyagentos" in c:
        verb = c.split("phyagentos.cli" if "phyagentos.cli" in c else "/bin/phyagentos", 1)[1].split()
        return f"phyagentos {verb[0]}" if verb else "phyagentos"
    if "-m phyagentos." in c:
        return "python -m " + c.split("-m ", 1)[1].split()[0]
    for word in ("chrom", "ray", "zenoh", "ffmpeg"):
        if word in c.lower():
            return word
    head = c.split()
    return " ".join(Path(head[0]).name if i == 0 else w for i, w in enumerate(head[:2])) if head else "?"


def charge(samples, command: dict, marks: dict[int, list[tuple[float, str, str]]], *, skip: set) -> dict:
    """Charge each sampled CPU increment to a test file, a test and a kind of process.

    ``marks``: per pytest process id, its ``(time, "S" | "E", nodeid)`` events in order;
    ``skip``: process keys not to count (those alive before the run began)."""
    last: dict = {}
    parent_of: dict = {}
    by_pid: dict[int, list] = defaultdict(list)
    per_file: dict[str, Counter] = defaultdict(Counter)
    per_test: Counter = Counter()
    per_kind: Counter = Counter()
    cursor = {pid: 0 for pid in marks}
    running: dict[int, str | None] = {pid: None for pid in marks}

    owners: dict = {}

    def owner(key) -> int | None:
        if key in owners:
            return owners[key]
        start, seen = key, 0
        while key is not None and seen < 64:
            if key[0] in marks:
                owners[start] = key[0]
                return key[0]
            ppid = parent_of.get(key)
            if ppid is None:
                break
            candidates = [k for k in by_pid.get(ppid, ()) if k[1] <= key[1]]
            key = max(candidates, key=lambda k: k[1]) if candidates else None
            seen += 1
        owners[start] = None
        return None

    for t, rows in samples:
        for pid, events in marks.items():  # what each worker was running at t
            i = cursor[pid]
            while i < len(events) and events[i][0] <= t:
                running[pid] = events[i][2] if events[i][1] == "S" else None
                i += 1
            cursor[pid] = i
        for key, ppid, cpu in rows:
            if key not in parent_of:
                parent_of[key] = ppid
                by_pid[key[0]].append(key)
            delta, last[key] = cpu - last.get(key, 0.0), cpu
            if delta <= 0 or key in skip or ppid == 2:  # kernel threads are children of kthreadd
                continue
            kind = kind_of(command.get(key, "?"))
            per_kind[kind] += delta
            who = owner(key)
            if who is None:
                test = "<unattributed>"
            else:
                test = running.get(who) or "<between tests>"
            per_file[test.split("::")[0]][kind] += delta
            per_test[test] += delta
    return {"per_file": per_file, "per_test": per_test, "per_kind": per_kind}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     usage="suite_cpu.py [--out F] [--interval S] [--top N] -- PYTEST_ARGS...")
    parser.add_argument("--out", type=Path, help="where to write the JSON table")
    parser.add_argument("--interval", type=float, default=0.5, help="seconds between samples (default 0.5)")
    parser.add_argument("--top", type=int, default=30, help="rows of each printed table (default 30)")
    parser.add_argument("pytest_args", nargs=argparse.REMAINDER)
    args = parser.parse_args(argv)
    if not Path("/proc/stat").is_file():
        parser.error("needs Linux's /proc")
    if args.interval <= 0:
        parser.error(f"--interval must be > 0 s, got {args.interval}")
    pytest_args = args.pytest_args[1:] if args.pytest_args[:1] == ["--"] else args.pytest_args
    with tempfile.TemporaryDirectory(prefix="suite_cpu_") as marks_dir:
        env = {**os.environ, _MARKS_ENV: marks_dir,
               "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).parent), os.environ.get("PYTHONPATH")]))}
        sampler = _Sampler(args.interval)
        machine0, wall0 = _machine_cpu_s(), time.time()
        sampler.start()
        while not sampler.samples:
            time.sleep(0.01)
        skip = {key for key, _, _ in sampler.samples[0][1]}
        code = subprocess.call([sys.executable, "-m", "pytest", "-p", "suite_cpu", *pytest_args], cwd=ROOT, env=env)
        sampler.stop.set()
        sampler.join()
        wall, machine = time.time() - wall0, _machine_cpu_s() - machine0
        marks: dict[int, list[tuple[float, str, str]]] = {}
        for f in Path(marks_dir).glob("*.marks"):
            events = []
            for line in f.read_text(encoding="utf-8").splitlines():
                kind, t, nodeid = line.split(" ", 2)
                events.append((float(t), kind, nodeid))
            marks[int(f.stem)] = events
    got = charge(sampler.samples, sampler.command, marks, skip=skip)
    charged = sum(got["per_kind"].values())
    files = sorted(got["per_file"].items(), key=lambda kv: -sum(kv[1].values()))
    table = {
        "pytest_exit_code": code, "wall_s": round(wall, 1), "machine_cpu_s": round(machine, 1),
        "charged_cpu_s": round(charged, 1), "coverage": round(charged / machine, 3) if machine else None,
        "per_kind": {k: round(v, 1) for k, v in got["per_kind"].most_common()},
        "per_file": {f: {"cpu_s": round(sum(c.values()), 1), **{k: round(v, 1) for k, v in c.most_common()}}
                     for f, c in files},
        "per_test": {n: round(v, 1) for n, v in got["per_test"].most_common()},
    }
    print(f"\nwall {wall:.0f} s; machine CPU {machine:.0f} s; charged to tests' processes {charged:.0f} s")
    print("\nCPU-s  kind of process")
    for k, v in list(table["per_kind"].items())[:args.top]:
        print(f"{v:7.1f}  {k}")
    print("\nCPU-s  test file (its largest kinds)")
    for f, row in files[:args.top]:
        print(f"{sum(row.values()):7.1f}  {f}  ({', '.join(f'{k} {v:.0f}' for k, v in row.most_common(3))})")
    print("\nCPU-s  test")
    for n, v in list(table["per_test"].items())[:args.top]:
        print(f"{v:7.1f}  {n}")
    if args.out:
        args.out.write_text(json.dumps(table, indent=1) + "\n", encoding="utf-8")
        print(f"\nwrote {args.out}")
    return code


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
