"""The fleet's CLI commands (issue 31, docs/fleet.md).

    phyagentos router --listen tcp/0.0.0.0:7447 [--config fleet.yaml]
    phyagentos edge --workspace WS --connect tcp/HOST:7447 --name arm1 [--config fleet.yaml] [--link-loss P]
    phyagentos run GRAPH --fleet tcp/HOST:7447 --workspace WS [--config fleet.yaml] [--name agent]
                   [--link-loss finish|halt_and_hold] [--wait-edges-s S] [--resume RUN_ID]
    phyagentos fleet-signal {estop,clear_estop,pause,resume,cancel} --fleet tcp/HOST:7447 [--edge NAME]

``router`` and ``edge`` run until SIGINT/SIGTERM. The fleet file (``--config``, else
``$PHYAGENTOS_FLEET``, else ``WS/fleet.yaml``) carries the authentication; flags override
its other fields.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import socket
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["FLEET_HANDLERS", "add_fleet_commands", "cmd_fleet_run"]

log = logging.getLogger(__name__)
EXIT_OK, EXIT_NOT_SUCCEEDED, EXIT_BAD_INPUT = 0, 1, 2


def add_fleet_commands(sub: argparse._SubParsersAction, run: argparse.ArgumentParser) -> None:
    """Add ``router`` and ``edge``, and ``--fleet`` (with its options) to ``run``."""
    router = sub.add_parser("router", help="run a zenoh router for a fleet until stopped")
    router.add_argument("--listen", action="append", help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    router.add_argument("--config", type=Path, help="fleet file (auth: user, password_file, users_file)")

    edge = sub.add_parser("edge", help="run the Runtime plane of one robot as an edge of a fleet until stopped")
    edge.add_argument("--workspace", type=Path, required=True, help="the edge's workspace (created if needed)")
    edge.add_argument("--connect", action="append", help="router endpoint, e.g. tcp/HOST:7447 (repeatable)")
    edge.add_argument("--name", help="the edge's name in the fleet")
    edge.add_argument("--config", type=Path, help="fleet file (default $PHYAGENTOS_FLEET or WORKSPACE/fleet.yaml)")
    edge.add_argument("--link-loss", choices=("finish", "halt_and_hold"),
                      help="default link-loss policy of sessions whose submit names none")
    edge.add_argument("--targets", help="comma-separated targets this edge owns (default: fleet.yaml's, else every "
                                        "enabled target of its TARGETS.md)")
    edge.add_argument("--lease-s", type=float, default=10.0, help="supervisor lease duration, s (default 10)")
    edge.add_argument("--drain-s", type=float, default=5.0, help="on SIGINT/SIGTERM, let a session finish this long")

    fsig = sub.add_parser("fleet-signal", help="send a runtime signal to the edges of a fleet (remote; each edge's "
                                               "own `phyagentos signal` works without a network)")
    fsig.add_argument("kind", choices=("estop", "clear_estop", "pause", "resume", "cancel"))
    fsig.add_argument("--fleet", metavar="ENDPOINT", required=True, help="router endpoint, e.g. tcp/HOST:7447")
    fsig.add_argument("--edge", action="append", help="only this edge (repeatable; default: every edge present)")
    fsig.add_argument("--session", help="the session a cancel addresses")
    fsig.add_argument("--reason", default="", help="why (recorded with the signal)")
    fsig.add_argument("--config", type=Path, help="fleet file (default $PHYAGENTOS_FLEET)")
    fsig.add_argument("--name", help="who sends it (default operator-HOST-PID)")

    run.add_argument("--fleet", metavar="ENDPOINT", help="run on a fleet through this router (tcp/HOST:7447): the "
                                                         "Agent plane here, each target's sessions on its edge")
    run.add_argument("--config", type=Path, help="with --fleet: the fleet file (default $PHYAGENTOS_FLEET or "
                                                 "WORKSPACE/fleet.yaml)")
    run.add_argument("--name", help="with --fleet: this agent's name (default agent-HOST-PID)")
    run.add_argument("--link-loss", choices=("finish", "halt_and_hold"),
                     help="with --fleet: what a running session does if its edge loses this agent (default: "
                          "the fleet file's, else finish)")
    run.add_argument("--resume", metavar="RUN_ID",
                     help="with --fleet: go on with this active run of the workspace (after this agent was stopped or "
                          "killed) instead of submitting the graph again")
    run.add_argument("--wait-edges-s", type=float, default=30.0,
                     help="with --fleet: how long to wait for edges owning the graph's targets (default 30)")


def _install_stop(stop) -> None:
    count = {"n": 0}

    def handler(signum, frame) -> None:
        count["n"] += 1
        stop(count["n"] > 1)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def _cmd_router(args, out: Console, err: Console) -> int:
    from phyagentos.fleet.config import find_fleet_config
    from phyagentos.fleet.router import run_router

    config = find_fleet_config(args.config, None).with_overrides(listen=args.listen)
    stop = threading.Event()
    _install_stop(lambda immediate: stop.set())
    run_router(config, stop=stop, on_ready=lambda: print(
        f"router listening on {', '.join(config.listen)} ({'authenticated' if config.secured() else 'OPEN: no auth'})",
        flush=True))
    return EXIT_OK


def _cmd_edge(args, out: Console, err: Console) -> int:
    from phyagentos.fleet.config import find_fleet_config
    from phyagentos.fleet.edge import FleetEdge
    from phyagentos.runtime.supervisor import SupervisorConfig

    targets = [t.strip() for t in args.targets.split(",")] if args.targets else None
    config = find_fleet_config(args.config, args.workspace).with_overrides(
        connect=args.connect, name=args.name, link_loss=args.link_loss, targets=targets)
    edge = FleetEdge(args.workspace, config, supervisor_config=SupervisorConfig(lease_s=args.lease_s,
                                                                                 drain_s=args.drain_s))
    _install_stop(lambda immediate: edge.request_stop(immediate=immediate))
    # one parseable line: scripts and tests wait for it
    print(f"edge {edge.name} serving {args.workspace} targets {','.join(edge.targets)}", flush=True)
    try:
        edge.serve()
    finally:
        edge.close()
    return EXIT_OK


def _graph_targets(path: Path, override: str | None) -> set[str]:
    from phyagentos.errors import GoalGraphError
    from phyagentos.yamlsource import load_yaml

    if override:
        return {override}
    doc = load_yaml(Path(path).read_text(encoding="utf-8"), path=path, error=GoalGraphError)
    default = (doc.get("defaults") or {}).get("target") if isinstance(doc, dict) else None
    return {str(t) for n in (doc.get("nodes") or []) if isinstance(n, dict) and (t := n.get("target") or default)}


def cmd_fleet_run(args, out: Console, err: Console) -> int:
    """``run GRAPH --fleet ENDPOINT``: the Agent plane here, sessions on the edges."""
    from phyagentos.app.orchestrator import skill_names, submit_goal_graph
    from phyagentos.fleet.agent_side import FleetAgentBridge
    from phyagentos.fleet.config import find_fleet_config
    from phyagentos.fleet.link import FleetLink
    from phyagentos.protocol import Workspace

    started = time.perf_counter()
    ws = Workspace.create(args.workspace)
    name = args.name or f"agent-{socket.gethostname()}-{os.getpid()}"
    config = find_fleet_config(args.config, args.workspace).with_overrides(connect=[args.fleet], name=name)
    link = FleetLink(config, mode="client")
    bridge = FleetAgentBridge(ws, link, name=name, link_loss=args.link_loss or config.link_loss)
    progress = None if args.json else (lambda msg: err.print(f"[dim]{msg}[/dim]"))
    try:
        bridge.wait_for_targets(_graph_targets(args.goal_graph, args.target), args.wait_edges_s)
        if progress:
            progress(f"fleet: targets {bridge.targets.as_dict()}")
        if args.resume:
            from phyagentos.errors import FleetError

            if args.resume not in ws.runs.active_ids():
                raise FleetError(f"run {args.resume!r} is not active in {args.workspace}; active: "
                                 f"{', '.join(ws.runs.active_ids()) or 'none'}")
            run = ws.runs.load(args.resume)
        else:
            run = submit_goal_graph(args.goal_graph, args.workspace, seed=args.seed, target=args.target,
                                    submitted_by=name)
        from phyagentos.agent.agent_loop import AgentLoop

        loop = AgentLoop(Workspace.open(args.workspace), skills=skill_names(), run_id=run.run_id, poll_interval_s=0.2)
        loop.workspace.on_session_write = bridge.kick  # the agent's submits and verdicts leave at once
        bridge.on_installed = loop.watcher.notify  # and the edges' transitions wake it at once
        _install_stop(lambda immediate: loop.request_stop())
        try:
            loop.serve()
        finally:
            loop.close()
        # the last verdicts go back to their edges before this agent leaves the fleet
        deadline = time.monotonic() + 5.0
        while bridge._unconfirmed_agent_writes() and time.monotonic() < deadline:
            bridge._watcher.notify()
            time.sleep(0.05)
        stats = dict(bridge.stats)
    finally:
        bridge.close()
        link.close()
    from phyagentos.agent.agent_loop import load_run_graph
    from phyagentos.agent.coordinator import AgentCoordinator
    graph = load_run_graph(ws, run.run_id, skills=skill_names())
    coord = AgentCoordinator(ws, graph, run_id=run.run_id, seed=args.seed)
    states = coord.node_states()
    succeeded = run.run_id in loop.finished and loop.finished[run.run_id]
    sessions = [{"session_id": s.session_id, "node": s.node, "target": s.target, "state": s.state}
                for s in coord.sessions()]
    report = {"run_id": run.run_id, "workspace": str(ws.root), "fleet": args.fleet, "succeeded": succeeded,
              "wall_time_s": round(time.perf_counter() - started, 3), "nodes": states, "sessions": sessions,
              "targets": bridge.targets.as_dict(), "replication": stats,
              "bytes": {"out": link.bytes_out, "in": link.bytes_in}}
    if args.json:
        print(json.dumps(report, ensure_ascii=False))
    else:
        for s in sessions:
            out.print(f"{s['node']:<20} {s['target']:<18} edge {bridge.targets.get(s['target'])!s:<10} {s['state']}",
                      highlight=False, markup=False)
        out.print("all nodes succeeded" if succeeded else "not every node succeeded", highlight=False, markup=False)
    return EXIT_OK if succeeded else EXIT_NOT_SUCCEEDED


def _cmd_fleet_signal(args, out: Console, err: Console) -> int:
    from phyagentos.errors import FleetError
    from phyagentos.fleet.config import find_fleet_config
    from phyagentos.fleet.link import FleetLink

    name = args.name or f"operator-{socket.gethostname()}-{os.getpid()}"
    config = find_fleet_config(args.config, None).with_overrides(connect=[args.fleet])
    link = FleetLink(config, mode="client")
    try:
        present = sorted(k.split("/")[-2] for k in link.alive(link.keys.edge_alive("*")))
        edges = args.edge or present
        missing = sorted(set(edges) - set(present))
        confirmed = []
        for edge in sorted(set(edges) & set(present)):
            reply = link.query_one(link.keys.edge_q(edge, "signal"), {"kind": args.kind, "session_id": args.session,
                                                                     "reason": args.reason, "by": name}, timeout_s=3.0)
            if reply is not None and reply.get("status") == "sent":
                confirmed.append(edge)
            else:
                err.print(f"edge {edge}: {reply.get('error') if reply else 'no answer'}", markup=False, highlight=False)
    finally:
        link.close()
    print(json.dumps({"signal": args.kind, "confirmed": confirmed, "not_present": missing}))
    if not confirmed or missing or len(confirmed) < len(edges):
        if not edges:
            raise FleetError(f"no edge present at {args.fleet}")
        return EXIT_NOT_SUCCEEDED
    return EXIT_OK


FLEET_HANDLERS = {"router": _cmd_router, "edge": _cmd_edge, "fleet-signal": _cmd_fleet_signal}
