"""The fleet (issue 31) measured with real processes on this machine.

    .venv/bin/python bench/fleet.py [--parts handoff,throughput,convergence,drill] [--holds 10]
                                    [--edges 1,4,16] [--partition-s 30] [--drill-faults 8] [--json]

1. **handoff**: a chain of ``--holds`` 0 s ``hold`` sessions, ``phyagentos run`` in one
   process against the same graph with ``run --fleet`` through a router to one edge
   (the edge's runner on another process tree, every message over zenoh/TCP). A hand-off
   is a session's verdict to the next session's first actuation (bench/end_to_end.py).
   Both without cameras (a sensors.yaml without them), alternated ``--runs`` times.
2. **throughput**: sessions per second of one run with 1, 4 and 16 edges (each edge its
   own target, ``--per-edge`` independent 0 s holds on each), from the first session's
   creation to the last verdict; bytes the agent's link sent and received per session.
3. **convergence**: a chain running through one edge; the router is killed while a
   session runs and restarted ``--partition-s`` later; the time from the router being
   up again to the agent's replica equal to the edge's record of that session.
4. **drill**: three edges and a chain per edge; ``--drill-faults`` random faults (SIGKILL
   of an edge, of the agent or of the router, each restarted; a link cut: the router
   SIGSTOPped for 2-4 s), then every session is checked on both sides: lost (an edge and
   the agent disagree, or one lacks it), stuck (not terminal at the end), duplicated (a
   node with two succeeded sessions) and blindly re-run (a session actuated twice).

Prints a table (or ``--json``) and writes ``bench/results/fleet.json``.
"""

from __future__ import annotations

import json
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from _harness import parser, write_json
from end_to_end import NO_CAMERA_SENSORS, handoffs, session_timeline

from phyagentos.fleet.local import LocalFleet
from phyagentos.protocol import Workspace

PHYAGENTOS = [sys.executable, "-m", "phyagentos.cli"]


def _ms(values: list[float], q: float = 0.5) -> float | None:
    if not values:
        return None
    values = sorted(values)
    return round(1e3 * values[min(len(values) - 1, int(q * len(values)))], 1)


def _prepare_ws(path: Path, targets: list[str] | None = None) -> Path:
    """A workspace without cameras whose TARGETS.md lists ``targets`` (copies of franka_tabletop)."""
    ws = Workspace.create(path)
    if targets is not None:
        def apply(doc):
            base = next(t for t in doc.targets if t.name == "franka_tabletop")
            doc.targets = [base.model_copy(update={"name": n}) for n in targets]
        ws.update("TARGETS", apply)
    sensors = {"version": 1, "targets": {n: NO_CAMERA_SENSORS["targets"]["franka_tabletop"]
                                         for n in (targets or ["franka_tabletop"])}}
    (path / "sensors.yaml").write_text(yaml.safe_dump(sensors), encoding="utf-8")
    return path


def _chain(path: Path, n: int, target: str = "franka_tabletop", prefix: str = "h") -> list[dict]:
    return [{"id": f"{prefix}{i:02d}", "skill": "hold", "target": target, "params": {"duration_s": 0.0},
             "accept": {"still": {"max_joint_motion_rad": 0.01}},
             "depends_on": [f"{prefix}{i - 1:02d}"] if i else []} for i in range(n)]


def _graph(path: Path, nodes: list[dict], name: str) -> Path:
    path.write_text(yaml.safe_dump({"version": 1, "name": name, "nodes": nodes}), encoding="utf-8")
    return path


def _run(args: list[str], timeout: float) -> dict:
    proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout, check=False)
    if proc.returncode not in (0, 1):
        raise RuntimeError(f"{' '.join(args[:6])} exited {proc.returncode}: {proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


# -- 1. hand-off -------------------------------------------------------------------------


def part_handoff(tmp: Path, holds: int, runs: int) -> dict:
    graph = _graph(tmp / "chain.yaml", _chain(tmp, holds), "fleet_chain")
    fleet = LocalFleet(tmp / "hf", peers=["arm1"])
    local, remote, bytes_per = [], [], []
    try:
        fleet.start_router()
        fleet.start_edge("arm1", ["franka_tabletop"], workspace=_prepare_ws(tmp / "hf" / "ws_arm1"))
        for i in range(runs):
            for side in (("local", "fleet") if i % 2 == 0 else ("fleet", "local")):
                ws = _prepare_ws(tmp / f"hand_{side}_{i}")
                if side == "local":
                    rep = _run([*PHYAGENTOS, "run", str(graph), "--workspace", str(ws), "--json"], 300)
                    local += handoffs(session_timeline(ws))
                else:
                    rep = _run(fleet.run_args(graph, ws), 300)
                    remote += handoffs(session_timeline(ws))
                    bytes_per.append((rep["bytes"]["in"] + rep["bytes"]["out"]) / max(1, len(rep["sessions"])))
                assert rep["succeeded"], rep
    finally:
        fleet.close()
    return {"holds": holds, "runs": runs, "one_process_p50_ms": _ms(local), "one_process_p90_ms": _ms(local, 0.9),
            "fleet_p50_ms": _ms(remote), "fleet_p90_ms": _ms(remote, 0.9), "handoffs": [len(local), len(remote)],
            "bytes_per_session": round(statistics.median(bytes_per)) if bytes_per else None}


# -- 2. throughput ------------------------------------------------------------------------


def part_throughput(tmp: Path, edge_counts: list[int], per_edge: int) -> list[dict]:
    out = []
    for n in edge_counts:
        names = [f"e{i:02d}" for i in range(n)]
        fleet = LocalFleet(tmp / f"tp{n}", peers=names)
        try:
            fleet.start_router()
            t0 = time.monotonic()
            procs = [fleet.start_edge(e, [f"arm_{e}"], workspace=_prepare_ws(tmp / f"tp{n}" / f"ws_{e}", [f"arm_{e}"]),
                                      wait_ready=False) for e in names]
            del procs
            for e in names:  # every edge up
                fleet._spawn_wait(e, f"edge {e} serving", 300)
            startup = time.monotonic() - t0
            nodes = [{"id": f"{e}_h{j}", "skill": "hold", "target": f"arm_{e}", "params": {"duration_s": 0.0},
                      "accept": {"still": {"max_joint_motion_rad": 0.01}}} for e in names for j in range(per_edge)]
            graph = _graph(tmp / f"tp{n}.yaml", nodes, f"fleet_tp{n}")
            ws = tmp / f"tp{n}_agent"
            rep = _run(fleet.run_args(graph, ws, "--wait-edges-s", "120"), 900)
            assert rep["succeeded"], rep
            rows = session_timeline(ws)
            span = max(r["verdict"] for r in rows) - min(r["created"] for r in rows)
            out.append({"edges": n, "sessions": len(rows), "span_s": round(span, 2),
                        "sessions_per_s": round(len(rows) / span, 2), "edge_startup_s": round(startup, 1),
                        "bytes_per_session": round((rep["bytes"]["in"] + rep["bytes"]["out"]) / len(rows)),
                        "resynced": rep["replication"].get("resynced", 0)})
        finally:
            fleet.close()
    return out


# -- 3. convergence ----------------------------------------------------------------------


def _same(edge_ws: Path, agent_ws: Path, sid: str) -> bool:
    try:
        a = Workspace.open(agent_ws).load_session(sid)
        e = Workspace.open(edge_ws).load_session(sid)
    except Exception:  # noqa: BLE001 - not there yet
        return False
    return a.transitions[:len(e.transitions)] == e.transitions


def _running(ws: Path) -> str | None:
    index = ws / "sessions" / ".index"
    for p in index.iterdir() if index.is_dir() else ():
        if p.name.endswith("~running"):
            return p.name.rsplit("~", 1)[0]
    return None


def _port_open(port: int, timeout_s: float = 60.0) -> float:
    import socket

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return time.monotonic()
        time.sleep(0.002)
    raise RuntimeError(f"router not listening on {port} after {timeout_s} s")


def part_convergence(tmp: Path, partition_s: float) -> dict:
    nodes = _chain(tmp, 3)
    nodes[1]["params"]["duration_s"] = 1.0
    graph = _graph(tmp / "conv.yaml", nodes, "fleet_conv")
    fleet = LocalFleet(tmp / "cv", peers=["arm1"])
    agent_ws = _prepare_ws(tmp / "cv_agent")
    try:
        fleet.start_router()
        edge_ws = _prepare_ws(tmp / "cv" / "ws_arm1")
        fleet.start_edge("arm1", ["franka_tabletop"], workspace=edge_ws)
        proc = subprocess.Popen(fleet.run_args(graph, agent_ws), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        deadline = time.monotonic() + 120
        sid = None
        while sid is None and time.monotonic() < deadline:
            sid = _running(edge_ws) if "h01" in (_running(edge_ws) or "") else None
            time.sleep(0.01)
        fleet.kill("router")
        time.sleep(partition_s)
        edge_state = Workspace.open(edge_ws).load_session(sid).state
        fleet._spawn("router", ["router", "--listen", fleet.endpoint, "--config", str(fleet.config_file("router"))],
                     ready="", timeout_s=0)
        t_up = _port_open(fleet.port)  # the router accepts connections from here on
        while not _same(edge_ws, agent_ws, sid) and time.monotonic() < t_up + 60:
            time.sleep(0.005)
        converged = time.monotonic() - t_up
        out, _ = proc.communicate(timeout=120)
        rep = json.loads(out.strip().splitlines()[-1])
    finally:
        fleet.close()
    return {"partition_s": partition_s, "edge_state_at_reconnect": edge_state, "convergence_s": round(converged, 3),
            "run_succeeded": rep["succeeded"]}


# -- 4. kill drill -----------------------------------------------------------------------


def part_drill(tmp: Path, faults: int, seed: int, per_edge: int) -> dict:
    rng = random.Random(seed)
    edges = ["d1", "d2", "d3"]
    fleet = LocalFleet(tmp / "drill", peers=edges, extra={"link_timeout_s": 2.0})
    nodes = [n for e in edges for n in _chain(tmp, per_edge, target=f"arm_{e}", prefix=f"{e}_")]
    for n in nodes:
        n["params"]["duration_s"] = 1.0  # long enough for faults to land while sessions run
    graph = _graph(tmp / "drill.yaml", nodes, "fleet_drill")
    agent_ws = _prepare_ws(tmp / "drill_agent", [f"arm_{e}" for e in edges])
    counts = {"edge_kill": 0, "agent_kill": 0, "router_kill": 0, "link_cut": 0}
    agent: subprocess.Popen | None = None
    run_id = None
    try:
        fleet.start_router()
        for e in edges:
            fleet.start_edge(e, [f"arm_{e}"], workspace=_prepare_ws(tmp / "drill" / f"ws_{e}", [f"arm_{e}"]),
                             more=("--lease-s", "3"))

        def start_agent(resume: str | None):
            more = ["--wait-edges-s", "120"] + (["--resume", resume] if resume else [])
            return subprocess.Popen(fleet.run_args(graph, agent_ws, *more), stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True, start_new_session=True)

        agent = start_agent(None)
        # every kind of fault, in a random order (edges twice as often: there are three)
        kinds = ["edge_kill", "edge_kill", "agent_kill", "router_kill", "link_cut"]
        plan = [kinds[i % len(kinds)] for i in range(faults)]
        rng.shuffle(plan)
        t_end = time.monotonic() + 600
        done = 0
        while done < faults and time.monotonic() < t_end:
            time.sleep(rng.uniform(1.0, 3.0))
            if agent.poll() is not None:
                break  # the run finished before every fault was made
            if run_id is None:
                ids = Workspace.open(agent_ws).runs.active_ids()
                run_id = ids[0] if ids else None
            kind = plan[done]
            if kind == "agent_kill" and run_id is None:
                kind = "link_cut"
            if kind == "edge_kill":
                e = rng.choice(edges)
                fleet.kill(e)
                fleet.start_edge(e, [f"arm_{e}"], workspace=tmp / "drill" / f"ws_{e}", more=("--lease-s", "3"))
            elif kind == "agent_kill":
                import os

                os.killpg(agent.pid, signal.SIGKILL)
                agent.wait()
                agent = start_agent(run_id)
            elif kind == "router_kill":
                fleet.kill("router")
                time.sleep(rng.uniform(0.5, 2.0))
                fleet.start_router()
            else:
                fleet.kill("router", signal.SIGSTOP)
                time.sleep(rng.uniform(2.0, 4.0))
                fleet.kill("router", signal.SIGCONT)
            counts[kind] += 1
            done += 1
        out, err = agent.communicate(timeout=600)
        rep = json.loads(out.strip().splitlines()[-1]) if out.strip() else {"succeeded": False, "error": err[-2000:]}
        time.sleep(1.0)  # the last verdicts reach their edges
        a = {r.session_id: r for r in Workspace.open(agent_ws).list_sessions()}
        lost, stuck, rerun, dup, diverged = [], [], [], [], []
        by_node: dict[str, int] = {}
        for e in edges:
            ews = Workspace.open(tmp / "drill" / f"ws_{e}")
            edge = {r.session_id: r for r in ews.list_sessions() if r.run_id in {x.run_id for x in a.values()}}
            for sid, rec in edge.items():
                if sid not in a:
                    lost.append(sid)
                    continue
                if rec.transitions != a[sid].transitions:
                    diverged.append(sid)
                if sum(t.event.startswith("start") for t in rec.transitions) > 1:
                    rerun.append(sid)
                if rec.state == "succeeded":
                    by_node[rec.node] = by_node.get(rec.node, 0) + 1
            for sid, rec in a.items():
                if rec.target == f"arm_{e}" and sid not in edge:
                    lost.append(sid)
        stuck = [sid for sid, rec in a.items() if not rec.is_terminal]
        dup = [n for n, c in by_node.items() if c > 1]
    finally:
        if agent is not None and agent.poll() is None:
            import os

            os.killpg(agent.pid, signal.SIGKILL)
            agent.wait()
        fleet.close()
    return {"faults": counts, "sessions": len(a), "run_succeeded": rep.get("succeeded"),
            "nodes_succeeded": sum(1 for r in a.values() if r.state == "succeeded"), "nodes": len(nodes),
            "lost": len(lost), "stuck": len(stuck), "duplicated": len(dup), "blindly_rerun": len(rerun),
            "diverged": len(diverged), "detail": {"lost": lost, "stuck": stuck, "duplicated": dup,
                                                  "rerun": rerun, "diverged": diverged}}


def main() -> int:
    ap = parser(__doc__, "fleet")
    ap.add_argument("--parts", default="handoff,throughput,convergence,drill")
    ap.add_argument("--holds", type=int, default=10)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--edges", default="1,4,16")
    ap.add_argument("--per-edge", type=int, default=4)
    ap.add_argument("--partition-s", type=float, default=30.0)
    ap.add_argument("--drill-faults", type=int, default=8)
    ap.add_argument("--drill-per-edge", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    parts = [p.strip() for p in args.parts.split(",")]
    result: dict = {"machine": {"cpus": __import__("os").cpu_count()}}
    with tempfile.TemporaryDirectory(prefix="fleet-bench-") as tmpdir:
        tmp = Path(tmpdir)
        if "handoff" in parts:
            result["handoff"] = part_handoff(tmp, args.holds, args.runs)
        if "throughput" in parts:
            result["throughput"] = part_throughput(tmp, [int(x) for x in args.edges.split(",")], args.per_edge)
        if "convergence" in parts:
            result["convergence"] = part_convergence(tmp, args.partition_s)
        if "drill" in parts:
            result["drill"] = part_drill(tmp, args.drill_faults, args.seed, args.drill_per_edge)
    write_json(args.out, result, indent=1, say=not args.json)
    if args.json:
        print(json.dumps(result))
        return 0
    from rich.console import Console
    from rich.table import Table

    table = Table(title="fleet (bench/fleet.py)")
    table.add_column("measure")
    table.add_column("value", justify="right")
    if "handoff" in result:
        h = result["handoff"]
        table.add_row("hand-off p50, one process", f"{h['one_process_p50_ms']} ms")
        table.add_row("hand-off p50, fleet (router + edge)", f"{h['fleet_p50_ms']} ms")
        table.add_row("hand-off p90, one process / fleet", f"{h['one_process_p90_ms']} / {h['fleet_p90_ms']} ms")
        table.add_row("bytes replicated per session (chain)", f"{h['bytes_per_session']}")
    for t in result.get("throughput", []):
        table.add_row(f"sessions/s, {t['edges']} edge(s), {t['sessions']} holds", f"{t['sessions_per_s']}")
    if "convergence" in result:
        c = result["convergence"]
        table.add_row(f"convergence after a {c['partition_s']:.0f} s partition", f"{c['convergence_s']} s")
    if "drill" in result:
        d = result["drill"]
        table.add_row("drill faults", ", ".join(f"{k} {v}" for k, v in d["faults"].items()))
        table.add_row("drill lost/stuck/duplicated/re-run/diverged",
                      f"{d['lost']}/{d['stuck']}/{d['duplicated']}/{d['blindly_rerun']}/{d['diverged']}")
    Console().print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
