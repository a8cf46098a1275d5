"""Memory of a process that runs one goal graph after another, each in a new workspace.

    .venv/bin/python bench/runner_memory.py [--runs 12] [--graph phyagentos/data/goal_graphs/pick_and_place.yaml]

``phyagentos bench`` episodes, the tests and any program calling
``phyagentos.app.orchestrator.run_goal_graph`` repeatedly reuse one idle runner process
(``runtime/worker.py``) for workspace after workspace. This runs ``--runs`` such runs
(seed = run index) and prints, after each, the resident set size (MiB, from
``/proc/<pid>/statm``) of this process and of each of its descendants (the runner, its
forkserver, the resource tracker). A runner that keeps every workspace's targets grows
by the size of their models, data and camera renderers at every run; one that keeps two
levels off. Writes ``bench/results/runner_memory.json``.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from _harness import parser, write_json

ROOT = Path(__file__).resolve().parents[1]


def _rss_mib(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/statm", encoding="ascii") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:
        return None


def _descendants(pid: int) -> dict[int, str]:
    """Live descendants of ``pid`` with their command lines (from /proc)."""
    parent = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as fh:
                    parent[int(entry)] = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                pass
    found, frontier = {}, [pid]
    while frontier:
        current = frontier.pop()
        for child, par in parent.items():
            if par == current and child not in found:
                try:
                    with open(f"/proc/{child}/cmdline", "rb") as fh:
                        found[child] = fh.read().replace(b"\0", b" ").decode(errors="replace")
                except OSError:
                    continue
                frontier.append(child)
    return found


def _role(pid: int, cmdline: str, runners: set[int]) -> str:
    if pid in runners:
        return "runner"
    if "resource_tracker" in cmdline:
        return "resource_tracker"
    if "forkserver" in cmdline:
        return "forkserver"
    return cmdline[:40]


def main(argv=None) -> int:
    from phyagentos.app.orchestrator import run_goal_graph  # noqa: PLC0415
    from phyagentos.runtime import worker  # noqa: PLC0415

    ap = parser(__doc__, "runner_memory")
    ap.add_argument("--runs", type=int, default=12)
    ap.add_argument("--graph", type=Path, default=ROOT / "phyagentos" / "data" / "goal_graphs" / "pick_and_place.yaml")
    args = ap.parse_args(argv)
    base = Path(tempfile.mkdtemp(prefix="phyagentos-runner-memory-"))
    rows = []
    print(f"{'run':>4} {'ok':>3} {'this process MiB':>17}  descendants MiB")
    for i in range(args.runs):
        report = run_goal_graph(args.graph, base / f"ws{i}", seed=i)
        me = os.getpid()
        kids = {pid: (cmd, _rss_mib(pid)) for pid, cmd in _descendants(me).items()}
        runners = {r.pid for r in worker._IDLE_RUNNERS}  # the runner parked for the next run
        row = {"run": i, "succeeded": report.succeeded, "self_mib": _rss_mib(me),
               "descendants": {str(pid): {"rss_mib": rss, "role": _role(pid, cmd, runners)}
                               for pid, (cmd, rss) in sorted(kids.items()) if rss is not None}}
        rows.append(row)
        print(f"{i:>4} {'yes' if report.succeeded else 'no':>3} {row['self_mib']:>17.0f}  "
              + ", ".join(f"{d['role']} {d['rss_mib']:.0f}" for d in row["descendants"].values()), flush=True)
    write_json(args.out, {"graph": str(args.graph), "runs": rows})
    return 0


if __name__ == "__main__":  # the runner's forkserver imports this module again: run only here
    raise SystemExit(main())
