"""Throughput of no-motion sessions through the full lifecycle, with real fsyncs and real processes.

    .venv/bin/python bench/supervisor_throughput.py [--sessions 200]

Two workloads, each submitted as one goal graph of independent nodes (``phyagentos
submit``) and driven by real ``phyagentos watch`` processes (one per target) plus one
``phyagentos agent`` process; every transition is an fsynced atomic write:

- ``noop``: a skill whose empty TargetToolManifest means the runner never opens the
  target; the lifecycle is claim -> preflight -> run -> evidence -> verdict, and the
  verdict is ``failure`` (no acceptance criteria: a controller return code never
  counts). This is the cost of supervision itself.
- ``hold 0 s``: the cheapest skill that touches the MuJoCo target (acquire, snapshots,
  RGB evidence images, checkpoint), verified ``success`` by the ``still`` predicate.

Reported: sessions per second from submit to the run's last verdict, and per session
the wall time of the supervision path. Writes bench/results/supervisor_throughput.json.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from _harness import parser, write_json
from _supervisor_common import CLI, ROOT, make_workspace, start_watch, stop

from phyagentos.protocol import Workspace

WORKLOADS = {
    "noop": ({"skill": "noop", "params": {"ticks": 1}}, {}),
    "hold 0 s": ({"skill": "hold", "params": {"duration_s": 0.0}}, {"still": {"max_joint_motion_rad": 0.01}}),
}


def run(workload: str, sessions: int, supervisors: int) -> dict:
    node, accept = WORKLOADS[workload]
    with tempfile.TemporaryDirectory() as tmp:
        ws = make_workspace(Path(tmp) / "ws", targets=supervisors)
        targets = [t.name for t in ws.read("TARGETS").data.targets]
        nodes = []
        for i in range(sessions):
            nodes.append({"id": f"n{i:04d}", "target": targets[i % len(targets)], **node, "accept": accept})
        graph = Path(tmp) / "graph.yaml"
        graph.write_text(yaml.safe_dump({"version": 1, "name": "throughput", "nodes": nodes}))
        sups = [start_watch(ws, "--lease-s", "30", "--targets", t) for t in targets]
        agent = subprocess.Popen([*CLI, "agent", str(ws.root)], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, cwd=ROOT)
        t0 = time.perf_counter()
        out = subprocess.run([*CLI, "submit", str(graph), "--workspace", str(ws.root)], capture_output=True, text=True,
                             cwd=ROOT, check=True)
        run_id = out.stdout.strip()
        while run_id in ws.runs.active_ids():
            time.sleep(0.1)
        wall = time.perf_counter() - t0
        for p in sups:
            stop(p)
        stop(agent)
        records = Workspace.open(ws.root).list_sessions(run_id=run_id)
        states = sorted({r.state for r in records})
    return {"sessions": len(records), "supervisors": supervisors, "wall_s": wall,
            "sessions_per_s": len(records) / wall, "ms_per_session": 1e3 * wall / len(records),
            "final_states": states}


def main() -> int:
    ap = parser(__doc__, "supervisor_throughput")
    ap.add_argument("--sessions", type=int, default=200)
    args = ap.parse_args()
    rows = []
    print(f"{'workload':10s} {'supervisors':>11s} {'sessions':>8s} {'wall s':>7s} {'sessions/s':>10s} {'final':>20s}")
    for workload in WORKLOADS:
        for supervisors in (1, 2):
            r = {"workload": workload, **run(workload, args.sessions, supervisors)}
            rows.append(r)
            print(f"{workload:10s} {supervisors:11d} {r['sessions']:8d} {r['wall_s']:7.1f} {r['sessions_per_s']:10.1f} "
                  f"{','.join(r['final_states']):>20s}")
    write_json(args.out, {"rows": rows, "cores": __import__("os").cpu_count()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
