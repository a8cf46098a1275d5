"""``phyagentos run GOAL_GRAPH --workspace DIR``: both planes in one command (``--fleet``: the
Agent plane here, the edges elsewhere). ``plan --run`` hands its graph to the same function."""

from __future__ import annotations

import json

__all__ = ["cmd_run"]

EXIT_OK, EXIT_NOT_SUCCEEDED = 0, 1


def cmd_run(args, out, err) -> int:
    """``phyagentos run``: the goal graph through both planes in this command; a summary table
    (or one JSON line with ``--json``). Returns 0 when every node succeeded, 1 otherwise."""
    if getattr(args, "fleet", None):  # [issue 31]
        from phyagentos.cli.fleet import cmd_fleet_run

        return cmd_fleet_run(args, out, err)
    from phyagentos.resources import skill_dirs, tree_dirs
    from phyagentos.runtime.worker import prestart_runner

    prestart_runner(skill_dirs(), tree_dirs())  # cold start: the runtime loads while the Agent plane does
    from phyagentos.app.factories import make_reviser
    from phyagentos.app.orchestrator import run_goal_graph

    progress = None if args.json else (lambda msg: err.print(f"[dim]{msg}[/dim]"))
    report = run_goal_graph(args.goal_graph, args.workspace, seed=args.seed, target=args.target, progress=progress,
                            use_memory=args.memory != "off", consolidate=args.memory == "learn",
                            keep_success_images=args.keep_success_images,
                            reviser=make_reviser(getattr(args, "reviser", "rules"), args.workspace))
    if args.json:
        print(json.dumps(report.to_dict(), ensure_ascii=False))
    else:
        # Session ids are "<run id>-<node>-<generation>": the title carries the run id,
        # rows show the rest, so the table stays readable in 80 columns.
        from rich.table import Table  # noqa: PLC0415

        table = Table(title=f"run {report.run_id}  ({report.wall_time_s:.1f} s)")
        rows = report.sessions
        show_recovery = any(s.cause or s.strategy or s.memory for s in rows)
        columns = ["node", "session", "skill", "status", "verdict"] + (["cause", "strategy"] if show_recovery else []) + ["duration"]
        for col in columns:
            table.add_column(col, overflow="fold", no_wrap=col in ("status", "verdict", "duration"))
        colours = {"succeeded": "green", "failed": "red", "rejected": "red", "timed_out": "red", "replanned": "yellow"}
        for s in rows:
            colour = colours.get(s.status, "white")
            short = s.session_id.removeprefix(f"{report.run_id}-")
            cells = [s.node, short, s.skill, f"[{colour}]{s.status}[/{colour}]", s.verdict or "-"]
            if show_recovery:
                cells += [s.cause or "-", s.strategy or ("memory: " + ", ".join(s.memory) if s.memory else "-")]
            cells.append(f"{s.duration_s:.2f} s" if s.duration_s is not None else "-")
            table.add_row(*cells)
        out.print(table)
        for s in report.sessions:
            if s.status != "succeeded" and s.reason:
                out.print(f"[bold]{s.session_id}[/bold]: {s.reason}")
        out.print(f"workspace: {report.workspace}  evidence: {report.workspace / 'evidence'}")
        out.print("[green]all nodes succeeded[/green]" if report.succeeded else "[red]not every node succeeded[/red]")
    return EXIT_OK if report.succeeded else EXIT_NOT_SUCCEEDED
