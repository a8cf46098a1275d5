"""``phyagentos`` command line.

    phyagentos run GOAL_GRAPH --workspace DIR [--json] [--seed N] [--target NAME]
    phyagentos validate GOAL_GRAPH [--workspace DIR]
    phyagentos render tree SKILL_OR_TREE [--out FILE.png]

Exit codes: 0 every node succeeded / command succeeded; 1 a node did not succeed;
2 bad input (goal graph, protocol document, arguments).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from rich.console import Console
from rich.logging import RichHandler
from rich.table import Table

from phyagentos.errors import PhyAgentOSError

__all__ = ["main", "build_parser"]

EXIT_OK, EXIT_NOT_SUCCEEDED, EXIT_BAD_INPUT = 0, 1, 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="phyagentos", description="Goal graphs to verified sessions on embodied targets.")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging (-vv for debug)")
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="run a goal graph end to end (Agent and Runtime planes in one process)")
    run.add_argument("goal_graph", type=Path)
    run.add_argument("--workspace", type=Path, required=True, help="workspace directory (created if needed)")
    run.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    run.add_argument("--seed", type=int, default=0, help="base seed of the run's sessions (default 0)")
    run.add_argument("--target", help="run every node on this target instead of the graph's")

    val = sub.add_parser("validate", help="validate a goal graph and print its DAG")
    val.add_argument("goal_graph", type=Path)
    val.add_argument("--workspace", type=Path, help="take valid targets from this workspace's TARGETS.md")

    render = sub.add_parser("render", help="render trees and graphs")
    rsub = render.add_subparsers(dest="what", required=True)
    tree = rsub.add_parser("tree", help="print a skill's behaviour tree (ASCII) and optionally write an image")
    tree.add_argument("name", help="skill name (skills/) or tree name (trees/)")
    tree.add_argument("--out", type=Path, help="write an image (.png or .svg) through Graphviz")
    return parser


def _setup_logging(verbose: int, console: Console) -> None:
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(message)s", handlers=[RichHandler(console=console, show_path=False)])
    # transitions logs every state entry/exit at INFO; our own transition log is enough.
    logging.getLogger("transitions").setLevel(max(level, logging.WARNING))
    logging.getLogger("toppra").setLevel(max(level, logging.WARNING))


def _cmd_run(args, out: Console, err: Console) -> int:
    from phyagentos.orchestrator import run_goal_graph

    progress = None if args.json else (lambda msg: err.print(f"[dim]{msg}[/dim]"))
    report = run_goal_graph(args.goal_graph, args.workspace, seed=args.seed, target=args.target, progress=progress)
    if args.json:
        print(json.dumps(report.to_dict(), ensure_ascii=False))
    else:
        table = Table(title=f"run {report.run_id}  ({report.wall_time_s:.1f} s)")
        for col in ("node", "session", "skill", "status", "verdict", "duration"):
            table.add_column(col, overflow="fold")
        colours = {"succeeded": "green", "failed": "red", "rejected": "red", "timed_out": "red", "replanned": "yellow"}
        for s in report.sessions:
            colour = colours.get(s.status, "white")
            table.add_row(s.node, s.session_id, s.skill, f"[{colour}]{s.status}[/{colour}]", s.verdict or "-",
                          f"{s.duration_s:.2f} s" if s.duration_s is not None else "-")
        out.print(table)
        for s in report.sessions:
            if s.status != "succeeded" and s.reason:
                out.print(f"[bold]{s.session_id}[/bold]: {s.reason}")
        out.print(f"workspace: {report.workspace}  evidence: {report.workspace / 'evidence'}")
        out.print("[green]all nodes succeeded[/green]" if report.succeeded else "[red]not every node succeeded[/red]")
    return EXIT_OK if report.succeeded else EXIT_NOT_SUCCEEDED


def _cmd_validate(args, out: Console, err: Console) -> int:
    from phyagentos.agent.dag import to_digraph, topological_order
    from phyagentos.orchestrator import load_graph_for
    from phyagentos.protocol import Workspace
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime

    runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    if args.workspace:
        graph = load_graph_for(Workspace.open(args.workspace), args.goal_graph, runtime)
    else:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            graph = load_graph_for(Workspace.create(tmp), args.goal_graph, runtime)
    dag = to_digraph(graph)
    out.print(f"{args.goal_graph}: valid, {len(graph.nodes)} node(s)")
    for node_id in topological_order(dag):
        node = graph.get_node(node_id)
        deps = f" after {', '.join(node.depends_on)}" if node.depends_on else ""
        out.print(f"  {node_id}: {node.skill} on {node.target}{deps}")
    return EXIT_OK


def _cmd_render(args, out: Console, err: Console) -> int:
    from phyagentos.resources import skills_dir, trees_dir
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.trees import render_ascii, render_image

    runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    if args.name in runtime.skills:
        manifest = runtime.skills.get(args.name)
        tree_name = manifest.tree
        # required parameters need a value to build; optional ones keep the tree's defaults
        params = {k: d.get("example", f"<{k}>") for k, d in manifest.params.items() if d.get("required") or "example" in d}
    else:
        tree_name = args.name
        params = {k: d.get("default", d.get("example", f"<{k}>")) for k, d in runtime.trees.spec(args.name).params.items()}
    root = runtime.trees.build(tree_name, params)
    print(render_ascii(root))
    if args.out:
        path = render_image(root, args.out)
        err.print(f"wrote {path}")
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``phyagentos`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    out, err = Console(), Console(stderr=True)
    _setup_logging(args.verbose, err)
    handlers = {"run": _cmd_run, "validate": _cmd_validate, "render": _cmd_render}
    try:
        return handlers[args.command](args, out, err)
    except PhyAgentOSError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
