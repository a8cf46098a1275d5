"""The CLI commands that run the two planes as processes and talk to them.

    phyagentos watch WORKSPACE [--lease-s S] [--poll-s S] [--no-inotify] [--targets A,B] [--drain-s S]
    phyagentos agent WORKSPACE [--run RUN_ID] [--poll-s S] [--no-inotify]
    phyagentos submit GOAL_GRAPH --workspace WORKSPACE [--seed N] [--target NAME] [--follow] [--json]
    phyagentos status WORKSPACE [--json]
    phyagentos signal WORKSPACE {cancel,pause,resume,estop,clear_estop} [--session ID | --all] [--reason TEXT]

``watch`` and ``agent`` run until SIGINT/SIGTERM: the first one stops them cleanly
(the supervisor lets its in-flight session finish for ``--drain-s`` seconds, then
cancels it; a session not yet actuating goes back to pending), a second one at once.
Both exit 0 after a clean stop.
"""

from __future__ import annotations

import argparse
import json
import signal
from pathlib import Path
from typing import TYPE_CHECKING, Any

from phyagentos.cli.arguments import goal_graph_arg

if TYPE_CHECKING:  # rich is imported where it prints (a quiet command never loads it)
    from rich.console import Console


__all__ = ["add_plane_commands", "PLANE_HANDLERS"]

EXIT_OK, EXIT_NOT_SUCCEEDED, EXIT_BAD_INPUT = 0, 1, 2


def add_plane_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``watch``, ``agent``, ``submit``, ``status`` and ``signal`` to the ``phyagentos`` parser."""
    watch = sub.add_parser("watch", help="run the Runtime plane (a WatchdogSupervisor) on a workspace until stopped")
    watch.add_argument("workspace", type=Path)
    watch.add_argument("--lease-s", type=float, default=10.0, help="lease duration, s (default 10)")
    watch.add_argument("--poll-s", type=float, default=1.0, help="longest sleep between checks, s (default 1)")
    watch.add_argument("--no-inotify", action="store_true", help="poll instead of inotify wake-ups")
    watch.add_argument("--targets", help="only claim sessions on these comma-separated targets")
    watch.add_argument("--drain-s", type=float, default=5.0,
                       help="on SIGINT/SIGTERM, let the in-flight session finish this long before cancelling it")
    watch.add_argument("--cancel-grace-s", type=float, default=3.0,
                       help="a runner that has not stopped this long after a cancel is killed (default 3)")
    watch.add_argument("--owner", help="supervisor identity in leases (default host:pid:tag)")

    agent = sub.add_parser("agent", help="run the Agent plane (verify, replan, compile) on every active run")
    agent.add_argument("workspace", type=Path)
    agent.add_argument("--run", help="drive only this run and return when it finished")
    agent.add_argument("--poll-s", type=float, default=1.0, help="longest sleep between steps, s (default 1)")
    agent.add_argument("--no-inotify", action="store_true", help="poll instead of inotify wake-ups")

    submit = sub.add_parser("submit", help="validate a goal graph, register it as a run and compile its ready nodes")
    submit.add_argument("goal_graph", type=goal_graph_arg, help="goal graph file, or a shipped example's name")
    submit.add_argument("--workspace", type=Path, required=True, help="workspace directory (created if needed)")
    submit.add_argument("--seed", type=int, default=0, help="base seed of the run's sessions (default 0)")
    submit.add_argument("--target", help="run every node on this target instead of the graph's")
    submit.add_argument("--follow", action="store_true", help="keep the Agent loop running until the run finished")
    submit.add_argument("--json", action="store_true", help="print one JSON object")

    status = sub.add_parser("status", help="supervisors, signals, active sessions and the DAG states of active runs")
    status.add_argument("workspace", type=Path)
    status.add_argument("--json", action="store_true", help="print one JSON object")

    sig = sub.add_parser("signal", help="send a signal to the runtime through RUNTIME_SIGNAL.md")
    sig.add_argument("workspace", type=Path)
    sig.add_argument("kind", choices=("cancel", "pause", "resume", "estop", "clear_estop"))
    who = sig.add_mutually_exclusive_group()
    who.add_argument("--session", help="the session to cancel")
    who.add_argument("--all", action="store_true", help="cancel every session submitted so far")
    sig.add_argument("--reason", default="", help="why (recorded with the signal)")
    sig.add_argument("--by", help="who sends it (default user@host)")


def _install_stop(stop) -> None:
    """First SIGINT/SIGTERM: stop cleanly; the second: stop at once."""
    count = {"n": 0}

    def handler(signum, frame) -> None:  # noqa: ARG001
        count["n"] += 1
        stop(count["n"] > 1)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def _cmd_watch(args, out: Console, err: Console) -> int:
    # Only the supervisor's own modules: skills, trees and MuJoCo load in its runner process.
    from phyagentos.protocol import Workspace
    from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor

    workspace = Workspace.create(args.workspace)
    config = SupervisorConfig(lease_s=args.lease_s, poll_interval_s=args.poll_s, inotify=not args.no_inotify,
                              drain_s=args.drain_s, cancel_grace_s=args.cancel_grace_s,
                              targets=tuple(t.strip() for t in args.targets.split(",")) if args.targets else None)
    sup = WatchdogSupervisor(workspace, owner=args.owner, config=config)
    _install_stop(lambda immediate: sup.request_stop(immediate=immediate))
    err.print(f"supervisor {sup.owner} watching {args.workspace} ({sup.watcher.mode}); Ctrl-C stops")
    try:
        sup.serve()
    finally:
        sup.close()
    err.print(f"supervisor {sup.owner} stopped: {sup.stats}")
    return EXIT_OK


def _cmd_agent(args, out: Console, err: Console) -> int:
    from phyagentos.app.orchestrator import serve_agent
    from phyagentos.errors import ProtocolError
    from phyagentos.protocol import Workspace

    if args.run is not None:
        ws = Workspace.open(args.workspace)
        if not ws.runs.exists(args.run):
            known = ws.runs.active_ids() + ws.runs.recent_ids()
            raise ProtocolError(f"unknown run {args.run!r} in {args.workspace}; runs: "
                                f"{', '.join(known) or 'none (submit one with phyagentos submit)'}")
        if args.run not in ws.runs.active_ids():
            failure = ws.runs.failure(args.run)
            if failure is not None:
                err.print(f"run {args.run} was set aside (failed): {failure}", markup=False, highlight=False, soft_wrap=True)
                return EXIT_BAD_INPUT
            record = ws.runs.load(args.run)
            err.print(f"run {args.run} already finished: {'succeeded' if record.succeeded else 'not every node succeeded'}",
                      soft_wrap=True)
            return EXIT_OK if record.succeeded else EXIT_NOT_SUCCEEDED

    def started(loop) -> None:
        _install_stop(lambda immediate: loop.request_stop())
        err.print(f"agent on {args.workspace} ({loop.watcher.mode}); Ctrl-C stops")

    loop = serve_agent(args.workspace, run_id=args.run, poll_interval_s=args.poll_s, inotify=not args.no_inotify,
                       on_loop=started)
    for run_id, why in loop.set_aside_runs.items():
        err.print(f"set aside run {run_id} (failed): {why}", markup=False, highlight=False, soft_wrap=True)
    if args.run is not None and args.run in loop.set_aside_runs:
        return EXIT_BAD_INPUT
    if args.run is not None and args.run in loop.finished:
        return EXIT_OK if loop.finished[args.run] else EXIT_NOT_SUCCEEDED
    return EXIT_OK


def _run_view(ws, run_id: str) -> dict[str, Any]:
    from phyagentos.agent.agent_loop import load_run_graph
    from phyagentos.agent.coordinator import AgentCoordinator
    from phyagentos.app.orchestrator import skill_names

    view: dict[str, Any] = {"run_id": run_id}
    try:
        record = ws.runs.load(run_id)
        view.update(state=record.state, succeeded=record.succeeded, goal_graph=record.goal_graph,
                    submitted_at=record.submitted_at)
        graph = load_run_graph(ws, run_id, skills=skill_names())
        coord = AgentCoordinator(ws, graph, run_id=run_id, seed=record.seed)
        sessions = coord.sessions()
        view["nodes"] = coord.node_states(sessions)
        view["sessions"] = {s.session_id: s.state for s in sessions}
    except Exception as exc:  # noqa: BLE001 - status shows what it can
        view["error"] = str(exc)
    return view


def _cmd_submit(args, out: Console, err: Console) -> int:
    from phyagentos.app.orchestrator import serve_agent, submit_goal_graph
    from phyagentos.protocol import Workspace

    run = submit_goal_graph(args.goal_graph, args.workspace, seed=args.seed, target=args.target)
    ws = Workspace.open(args.workspace)
    if not args.follow:
        if args.json:
            print(json.dumps(_run_view(ws, run.run_id), ensure_ascii=False))
        else:
            print(run.run_id)
        _say_who_serves(ws, args.workspace, err)
        _say_queued(ws, run.run_id, err)
        return EXIT_OK
    err.print(f"run {run.run_id} submitted; following (start `phyagentos watch {args.workspace}` to execute it)")
    loop = serve_agent(args.workspace, run_id=run.run_id,
                       on_loop=lambda lp: _install_stop(lambda immediate: lp.request_stop()))
    view = _run_view(ws, run.run_id)
    if args.json:
        print(json.dumps(view, ensure_ascii=False))
    else:
        print(run.run_id)
        for node, state in view.get("nodes", {}).items():
            out.print(f"  {node}: {state}")
    if run.run_id not in loop.finished:
        return EXIT_NOT_SUCCEEDED  # stopped before the run finished
    return EXIT_OK if loop.finished[run.run_id] else EXIT_NOT_SUCCEEDED


def _say_queued(ws, run_id: str, err: Console) -> None:
    """Say when the run waits for another run's target world (one run per target world)."""
    from phyagentos.app.orchestrator import held_worlds

    targets = {ident.target for _, _, ident in ws.active_sessions(run_id=run_id)}
    for target, owner in held_worlds(ws, targets).items():
        if owner != run_id:
            err.print(f"run {run_id} queues: target {target} holds the world of run {owner} until it finishes",
                      markup=False, highlight=False, soft_wrap=True)


def _say_who_serves(ws, workspace: Path, err: Console) -> None:
    """Tell the user when no agent (or no supervisor) serves the workspace: the run
    would otherwise wait silently."""
    from phyagentos.agent.agent_loop import read_agents
    from phyagentos.runtime.supervisor import read_presence

    if not any(a["alive"] for a in read_agents(ws.root)):
        err.print(f"no agent serves {workspace}: the run waits until `phyagentos agent {workspace}` runs "
                  f"(or submit with --follow)", markup=False, highlight=False, soft_wrap=True)
    if not any(s["alive"] for s in read_presence(ws.root)):
        err.print(f"no supervisor watches {workspace}: start `phyagentos watch {workspace}` to execute the "
                  f"sessions", markup=False, highlight=False, soft_wrap=True)


def status_data(workspace: str | Path) -> dict[str, Any]:
    """Everything ``phyagentos status`` shows, as plain data."""
    from phyagentos.protocol import LEASED_STATES, Workspace, fold_signals
    from phyagentos.protocol.leases import remaining_s
    from phyagentos.runtime.supervisor import read_presence

    ws = Workspace.open(workspace)
    signals = ws.read("RUNTIME_SIGNAL").data
    state = fold_signals(signals.signals)
    active = []
    counts: dict[str, int] = {}
    for sid, hinted, ident in ws.active_sessions():
        counts[hinted] = counts.get(hinted, 0) + 1
        row = {"session_id": sid, "state": hinted, "run_id": ident.run_id, "node": ident.node, "skill": ident.skill,
               "target": ident.target}
        if hinted in LEASED_STATES:
            try:
                rec = ws.load_session(sid)
                row["state"] = rec.state
                row["owner"] = rec.lease.owner if rec.lease else None
                row["lease_remaining_s"] = round(remaining_s(rec.lease), 2) if rec.lease else None
            except Exception:  # noqa: BLE001 - it may have moved on meanwhile
                pass
        active.append(row)
    index = ws.read("SESSIONS").data
    recent = [e.model_dump(mode="json") for e in index.sessions if e.state not in counts and e.session_id not in
              {a["session_id"] for a in active}]
    return {
        "workspace": str(ws.root),
        "paused": state.paused,
        "estopped": state.estopped,
        "estop": state.estop.model_dump(mode="json") if state.estop else None,
        "supervisors": read_presence(ws.root),
        "counts": counts,
        "active_sessions": active,
        "recent_sessions": recent,
        "runs": [_run_view(ws, run_id) for run_id in ws.runs.active_ids()],
        "recent_runs": [_finished_view(ws, run_id) for run_id in ws.runs.recent_ids()],
    }


def _finished_view(ws, run_id: str) -> dict[str, Any]:
    """A finished (or set-aside) run: its outcome, without reading its sessions."""
    view: dict[str, Any] = {"run_id": run_id}
    try:
        record = ws.runs.load(run_id)
        view.update(goal_graph=record.goal_graph, submitted_at=record.submitted_at, finished_at=record.finished_at,
                    succeeded=record.succeeded)
    except Exception as exc:  # noqa: BLE001 - a bad RUN.md is shown, never fatal
        view["error"] = str(exc)
    failure = ws.runs.failure(run_id)
    if failure is not None:
        view["error"] = failure
    view["outcome"] = ("failed: set aside" if failure is not None else "succeeded" if view.get("succeeded")
                       else "unreadable" if "error" in view else "not every node succeeded")
    return view


def _cmd_status(args, out: Console, err: Console) -> int:
    data = status_data(args.workspace)
    if args.json:
        print(json.dumps(data, ensure_ascii=False))
        return EXIT_BAD_INPUT if any("error" in run for run in data["runs"]) else EXIT_OK
    flags = [f for f, on in (("[red]E-STOP[/red]", data["estopped"]), ("[yellow]paused[/yellow]", data["paused"])) if on]
    out.print(f"[bold]{data['workspace']}[/bold]  {' '.join(flags) or 'no pause or e-stop in force'}")
    sups = data["supervisors"]
    for s in sups:
        out.print(f"  supervisor {s['owner']} pid {s['pid']} {'alive' if s['alive'] else '[red]gone[/red]'}"
                  f"{' (session ' + s['session'] + ')' if s.get('session') else ''}")
    if not sups:
        out.print("  no supervisor is watching this workspace (start `phyagentos watch`)")
    out.print("  active: " + (", ".join(f"{k} {v}" for k, v in sorted(data["counts"].items())) or "none"))
    if data["active_sessions"]:
        from rich.table import Table  # noqa: PLC0415 - rich loads where it prints

        table = Table(title="active sessions")
        for col in ("session", "state", "node", "target", "owner", "lease"):
            table.add_column(col, overflow="fold")
        for row in data["active_sessions"][:50]:
            lease = row.get("lease_remaining_s")
            table.add_row(row["session_id"], row["state"], row["node"], row["target"], row.get("owner") or "-",
                          f"{lease:.1f} s" if lease is not None else "-")
        out.print(table)
    for run in data["runs"]:
        nodes = ", ".join(f"{n}={s}" for n, s in run.get("nodes", {}).items())
        out.print(f"  run {run['run_id']}: {nodes or 'error: ' + run.get('error', '')}", markup=False, highlight=False, soft_wrap=True)
    if data["recent_runs"]:
        out.print("  recent finished runs:")
        for run in data["recent_runs"]:
            detail = f" ({run['error']})" if run.get("error") else ""
            out.print(f"    {run['run_id']}: {run['outcome']}{detail}", markup=False, highlight=False, soft_wrap=True)
    # a stored run that no longer validates is bad input, reported with its file and line
    return EXIT_BAD_INPUT if any("error" in run for run in data["runs"]) else EXIT_OK


def _cmd_signal(args, out: Console, err: Console) -> int:
    from phyagentos.protocol import Workspace

    ws = Workspace.open(args.workspace)
    sig = ws.send_signal(args.kind, session_id=args.session, all_sessions=args.all, reason=args.reason,
                         issued_by=args.by)
    print(sig.id)
    return EXIT_OK


PLANE_HANDLERS = {"watch": _cmd_watch, "agent": _cmd_agent, "submit": _cmd_submit, "status": _cmd_status,
                  "signal": _cmd_signal}
