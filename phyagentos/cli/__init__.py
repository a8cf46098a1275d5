"""``phyagentos`` command line.

    phyagentos run GOAL_GRAPH --workspace DIR [--json] [--seed N] [--target NAME]
    phyagentos examples [--json]   (the shipped example goal graphs: GOAL_GRAPH may be one's name)
    phyagentos watch WORKSPACE | agent WORKSPACE | submit GOAL_GRAPH --workspace DIR [--follow]
    phyagentos status WORKSPACE [--json] | signal WORKSPACE KIND [--session ID]   (cli/planes.py)
    phyagentos bench SUITE --workspace DIR [--episodes N] [--seeds ...] [--workers K] [--memory off|frozen|learn] [--json]
    phyagentos validate GOAL_GRAPH [--workspace DIR] [--target NAME]
    (GOAL_GRAPH: a file, or a shipped example's name, e.g. pick_and_place)
    phyagentos skills list|show NAME [--workspace DIR] | primitives [--json|--markdown]   (cli/skills.py)
    phyagentos --skills-path DIR ...   (a folder with skills/ and trees/, searched after the workspace's)
    phyagentos render tree SKILL_OR_TREE [--out FILE.png]
    phyagentos render graph WORKSPACE [--run RUN_ID] [--out FILE.png|.svg] [--mermaid FILE.md]
    phyagentos policy serve [--host H] [--port N] [--rate-hz F] [--horizon K] [--stall-after N]
    phyagentos bus-twin so101 | calibrate --port P | doctor --target so101_real --port P   (cli/real.py)

Exit codes: 0 every node succeeded / command succeeded; 1 a node did not succeed;
2 bad input (goal graph, protocol document, arguments).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from phyagentos.cli.arguments import goal_graph_arg
from phyagentos.errors import PhyAgentOSError

if TYPE_CHECKING:  # rich is imported where it prints: this module is re-imported as the main module
    from rich.console import Console  # of every process forked from the runner's forkserver (issue 12)

__all__ = ["main", "build_parser"]

EXIT_OK, EXIT_NOT_SUCCEEDED, EXIT_BAD_INPUT = 0, 1, 2



def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="phyagentos", description="Goal graphs to verified sessions on embodied targets.")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging (-vv for debug)")
    parser.add_argument("--skills-path", action="append", default=[], metavar="DIR",
                        help="a folder with skills/ and trees/ searched after the workspace's own and before the "
                             "shipped ones (repeatable; first wins)")
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="run a goal graph end to end (Agent and Runtime planes in one process)")
    run.add_argument("goal_graph", type=goal_graph_arg, help="goal graph file, or a shipped example's name "
                                                              "(phyagentos examples)")
    run.add_argument("--workspace", type=Path, required=True, help="workspace directory (created if needed)")
    run.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    run.add_argument("--seed", type=int, default=0, help="base seed of the run's sessions (default 0)")
    run.add_argument("--target", help="run every node on this target instead of the graph's")
    run.add_argument("--memory", choices=("learn", "frozen", "off"), default="learn",
                     help="learn: use and consolidate LESSONS/KNOWLEDGE/SKILL.md (default); frozen: use, never "
                          "write; off: neither")
    run.add_argument("--reviser", choices=("rules", "model"), default="rules",
                     help="who proposes revisions on replan: the rule ladder (default) or the model (llm.yaml)")
    run.add_argument("--keep-success-images", action="store_true",
                     help="keep the evidence images of successful sessions (failures always keep theirs)")

    from phyagentos.cli.fleet import add_fleet_commands  # [issue 31] router, edge, run --fleet

    add_fleet_commands(sub, run)
    from phyagentos.cli.planes import add_plane_commands

    add_plane_commands(sub)
    from phyagentos.cli.skills import add_skill_commands

    add_skill_commands(sub)
    from phyagentos.cli.agent import add_agent_commands

    add_agent_commands(sub)

    bench = sub.add_parser("bench", help="run a benchmark suite: availability gate, sessions per (task, seed), report")
    bench.add_argument("suite", help="suite name (phyagentos/bench/suites/), a LIBERO suite (libero_spatial, libero_object, "
                                      "libero_goal, libero_10, or LIBERO-PRO's: libero_object_swap, _object, _lan, _task, "
                                      "_with_mug, libero_object_temp_x0.1 ...: --tasks are LIBERO task indices, --seeds its "
                                      "init states) or path of a suite YAML")
    bench.add_argument("--workspace", type=Path, required=True, help="bench workspace (created if needed)")
    bench.add_argument("--episodes", type=int, help="episodes per task (default: the suite's)")
    bench.add_argument("--seeds", help="explicit seeds per task, e.g. 0-49 or 0,3,7 (overrides --episodes)")
    bench.add_argument("--split", choices=("measurement", "heldout"), default="measurement",
                       help="seed split: measurement (0..) or the suite's held-out seeds")
    bench.add_argument("--tasks", help="comma-separated task ids (default: every task of the suite)")
    bench.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    bench.add_argument("--memory", choices=("off", "frozen", "learn"), default="frozen",
                       help="frozen = measurement (default), learn = adaptation, off = no memory")
    bench.add_argument("--executor", choices=("local", "ray"), default="local", help="local process pool or Ray")
    bench.add_argument("--json", action="store_true", help="print the report summary as one JSON object")
    bench.add_argument("--heartbeat-timeout", type=float, default=None, metavar="S",
                       help="runner heartbeat timeout of every session, s (default: the graphs' own, 10 s); raise it "
                            "on a loaded machine, the timeouts left are counted apart in the report")
    bench.add_argument("--queue-timeout", type=float, default=None, metavar="S",
                       help="how long every session may wait pending, s (default: the graphs' own, 600 s); raise it "
                            "for runs longer than that (every episode is compiled up front)")
    bench.add_argument("--skill-defaults", type=Path, default=None, metavar="FILE",
                       help="LIBERO suites: YAML {skill: {parameter: value}} of strategy parameters written into every "
                            "planned pick and place node (default: the LIBERO bench's, chosen on LIBERO-90; a file "
                            "holding {} runs the trees' own defaults)")
    bench.add_argument("--generated", action="store_true",
                       help="LIBERO suites: episodes are scenes of LIBERO's placement sampler seeded with --seeds, not "
                            "its init states (a development split: same tasks and checker, never a LIBERO score)")
    bench.add_argument("--measure-looks", action="store_true",
                       help="LIBERO suites: measure each world's object and fixture looks on generated scenes in this "
                            "workspace instead of taking the looks shipped with the package (measured the same way "
                            "once; another renderer or asset version may want its own)")

    val = sub.add_parser("validate", help="validate a goal graph and print its DAG")
    val.add_argument("goal_graph", type=goal_graph_arg, help="goal graph file, or a shipped example's name")
    val.add_argument("--workspace", type=Path, help="take valid targets from this workspace's TARGETS.md")
    val.add_argument("--target", help="check every node on this target instead of the graph's")

    examples = sub.add_parser("examples", help="list the shipped example goal graphs (names usable as GOAL_GRAPH)")
    examples.add_argument("--json", action="store_true", help="print one JSON object {name: path}")

    render = sub.add_parser("render", help="render trees and graphs")
    rsub = render.add_subparsers(dest="what", required=True)
    tree = rsub.add_parser("tree", help="print a skill's behaviour tree (ASCII) and optionally write an image")
    tree.add_argument("name", help="skill name (skills/) or tree name (trees/)")
    tree.add_argument("--out", type=Path, help="write an image (.png or .svg) through Graphviz")
    graph = rsub.add_parser("graph", help="draw a run's DAG with node states and parent/child sessions "
                                          "(Mermaid on stdout, optionally an image)")
    graph.add_argument("workspace", type=Path)
    graph.add_argument("--run", help="run id (default: the run in TASK.md)")
    graph.add_argument("--out", type=Path, help="write an image (.png or .svg) through Graphviz")
    graph.add_argument("--mermaid", type=Path, help="write a Markdown file with the Mermaid diagram")

    policy = sub.add_parser("policy", help="policy servers (openpi websocket protocol)")
    psub = policy.add_subparsers(dest="what", required=True)
    serve = psub.add_parser("serve", help="serve the mink reach-and-grasp controller as a policy until stopped")
    serve.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=8000, help="TCP port; 0 picks a free one (default 8000)")
    serve.add_argument("--rate-hz", type=float, default=20.0, help="action rate of the chunks, Hz (default 20)")
    serve.add_argument("--horizon", type=int, default=10, help="actions per chunk (default 10)")
    serve.add_argument("--stall-after", type=int, help="fault injection: stop answering after N inferences")
    from phyagentos.cli.view import add_view_commands  # [issue 13] view, run/bench --record
    add_view_commands(sub)
    from phyagentos.cli.real import add_real_commands  # [issue 32] bus-twin, calibrate, doctor, run --port
    add_real_commands(sub)
    return parser


class _LazyConsole:
    """A ``rich.console.Console`` made (and rich imported, ~40 ms) when first used: a
    command that prints nothing through it (``run --json``) never loads rich."""

    def __init__(self, **kwargs) -> None:
        self._kwargs = kwargs
        self._console: Console | None = None

    @property
    def console(self) -> Console:
        if self._console is None:
            from rich.console import Console  # noqa: PLC0415

            self._console = Console(**self._kwargs)
        return self._console

    def __getattr__(self, name: str):
        return getattr(self.console, name)


def _rich_console(console) -> Console:
    """The ``rich.console.Console`` behind ``console``, for rich's own classes (``Progress``,
    ``Live``), which use it as more than an object with methods (e.g. a context manager)."""
    return console.console if isinstance(console, _LazyConsole) else console


class _RichLogHandler(logging.Handler):
    """Log records rendered by rich's ``RichHandler`` on ``console``, which is built at the
    first record that reaches it (a quiet run imports no rich)."""

    def __init__(self, console: _LazyConsole) -> None:
        super().__init__()
        self._lazy = console
        self._rich: logging.Handler | None = None

    def emit(self, record: logging.LogRecord) -> None:
        if self._rich is None:
            from rich.logging import RichHandler  # noqa: PLC0415

            self._rich = RichHandler(console=self._lazy.console, show_path=False)
            self._rich.setFormatter(self.formatter)
        self._rich.emit(record)


def _setup_logging(verbose: int, console: _LazyConsole) -> None:
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    from phyagentos.untrusted import RedactingFilter  # noqa: PLC0415

    handler = _RichLogHandler(console)
    handler.addFilter(RedactingFilter())  # no credential reaches the terminal (issue 33)
    logging.basicConfig(level=level, format="%(message)s", handlers=[handler])
    # transitions logs every state entry/exit at INFO; our own transition log is enough.
    logging.getLogger("transitions").setLevel(max(level, logging.WARNING))
    logging.getLogger("toppra").setLevel(max(level, logging.WARNING))


def _cmd_bench(args, out: Console, err: Console) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from phyagentos.bench import parse_seeds, run_bench
    from phyagentos.errors import BenchError

    seeds = parse_seeds(args.seeds) if args.seeds else None
    tasks = tuple(t.strip() for t in args.tasks.split(",")) if args.tasks else None
    suite = args.suite
    from phyagentos.bench.libero import is_libero_suite, load_skill_defaults, prepare_libero_suite  # noqa: PLC0415

    for flag, given in (("--skill-defaults", args.skill_defaults is not None), ("--generated", args.generated),
                        ("--measure-looks", args.measure_looks)):
        if given and not is_libero_suite(suite):
            err.print(f"[red]{flag} applies to LIBERO suites only, not {suite!r}[/red]")
            return EXIT_BAD_INPUT
    if is_libero_suite(suite):  # LIBERO's own suite names, task indices and init states (docs/libero.md)
        try:
            fixed = load_skill_defaults(args.skill_defaults) if args.skill_defaults is not None else None
            suite, tasks, seeds = prepare_libero_suite(suite, args.workspace, tasks=tasks, seeds=seeds,
                                                       skill_defaults=fixed, generated=args.generated,
                                                       measure_looks=args.measure_looks)
        except BenchError as exc:
            err.print(f"[red]{str(exc).splitlines()[0]}[/red]")
            for line in exc.problems:
                err.print(f"  [red]-[/red] {line}")
            return EXIT_BAD_INPUT
    progress = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                        TextColumn("{task.fields[status]}"), TimeElapsedColumn(), console=_rich_console(err),
                        disable=args.json)
    bar = {}
    tally = {"ok": 0, "failed": 0, "error": 0}

    def compiled(n: int) -> None:
        bar["id"] = progress.add_task("episodes", total=n, status="")

    def episode_done(outcome) -> None:
        tally["error" if outcome.status != "completed" else "ok"] += 1
        progress.update(bar["id"], advance=1, status=f"last {outcome.episode_id} ({outcome.wall_time_s:.1f} s)")

    try:
        with progress:
            result = run_bench(suite, args.workspace, episodes=args.episodes, seeds=seeds,
                               split="generated" if args.generated else args.split,
                               tasks=tasks, workers=args.workers, memory=args.memory, executor=args.executor,
                               on_compiled=compiled, on_episode=episode_done,
                               heartbeat_timeout_s=args.heartbeat_timeout, queue_timeout_s=args.queue_timeout)
    except BenchError as exc:
        if exc.problems:
            err.print(f"[red]{str(exc).splitlines()[0]}[/red]")
            for line in exc.problems:
                err.print(f"  [red]-[/red] {line}")
            return EXIT_BAD_INPUT
        raise
    rep = result.report
    if args.json:
        keys = ("bench_id", "suite", "protocol", "memory", "split", "seeds", "workers", "executor", "wall_time_s",
                "episodes_per_minute", "overall", "per_task", "error_taxonomy", "ground_truth", "harness_errors")
        extra = {"crafter": {k: v for k, v in rep["crafter"].items() if k != "per_episode"}} if "crafter" in rep else {}
        print(json.dumps({**{k: rep[k] for k in keys}, **extra, "report": str(result.run_dir / "report.md")},
                         ensure_ascii=False))
    else:
        from rich.table import Table  # noqa: PLC0415

        table = Table(title=f"bench {rep['suite']} {rep['bench_id']}  ({rep['protocol']}, {rep['split']} seeds, "
                            f"{rep['episodes_per_minute']:.1f} episodes/min)")
        for col in ("task", "episodes", "First", "Final", "gain", "rescued"):
            table.add_column(col, justify="right" if col != "task" else "left")
        for name, s in [*rep["per_task"].items(), ("overall", rep["overall"])]:
            table.add_row(name, str(s["episodes"]), f"{s['first_rate_pct']:.1f}%", f"{s['final_rate_pct']:.1f}%",
                          f"{s['gain_points']:+.1f}", str(s["rescued"]))
        out.print(table)
        cats = {c: t["count"] for c, t in rep["error_taxonomy"].items() if t["count"]}
        if cats:
            out.print("errors: " + ", ".join(f"{c} {n}" for c, n in cats.items()))
        if rep["ground_truth"]["sessions"]:
            g = rep["ground_truth"]
            out.print(f"environment's own success signal: agrees with the verifier on {g['agreements']}/{g['sessions']} sessions")
            for name, pt in g["per_task"].items():
                if pt["episodes"]:
                    out.print(f"  {name}: environment First {pt['first_successes']}/{pt['episodes']}, "
                              f"Final {pt['final_successes']}/{pt['episodes']}")
        if "crafter" in rep:
            c = rep["crafter"]
            out.print(f"Crafter score {c['score_percent']:.1f} % over {c['episodes']} worlds, "
                      f"{c['achievements_per_episode']:.1f} achievements per episode, mean length {c['length_mean']} "
                      f"steps; deaths: {c['death_causes']} ({result.run_dir / 'crafter.md'})")
        out.print(f"report: {result.run_dir / 'report.md'}")
    if result.harness_errors:
        err.print(f"[red]{result.harness_errors} episode(s) hit a harness error; see the report[/red]")
        return EXIT_NOT_SUCCEEDED
    return EXIT_OK


def _cmd_validate(args, out: Console, err: Console) -> int:
    from phyagentos.agent.dag import to_digraph, topological_order
    from phyagentos.app.graph_check import check_goal_graph
    from phyagentos.protocol import Workspace
    from phyagentos.resources import skill_dirs, tree_dirs
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime

    runtime = BuiltinSkillRuntime.from_dirs(skill_dirs(), tree_dirs())
    if args.workspace:
        check = check_goal_graph(args.goal_graph, Workspace.open(args.workspace), runtime, target=args.target)
    else:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            check = check_goal_graph(args.goal_graph, Workspace.create(tmp), runtime, target=args.target)
    graph = check.graph
    dag = to_digraph(graph)
    implicit = {(e.before, e.after): e for e in check.implicit_edges}
    out.print(f"{args.goal_graph}: valid, {len(graph.nodes)} node(s), {check.poses_checked} pose(s) reachable",
              highlight=False, markup=False, soft_wrap=True)
    for node_id in topological_order(dag):
        node = graph.get_node(node_id)
        deps = [d + (" (implicit: one arm holds one object)" if (d, node_id) in implicit else "") for d in node.depends_on]
        out.print(f"  {node_id}: {node.skill} on {node.target}" + (f" after {', '.join(deps)}" if deps else ""),
                  highlight=False, markup=False, soft_wrap=True)
    for edge in check.implicit_edges:
        out.print(f"implicit edge {edge.before} -> {edge.after}: {edge.reason}", highlight=False, markup=False,
                  soft_wrap=True)
    return EXIT_OK


def _cmd_examples(args, out: Console, err: Console) -> int:
    from phyagentos.resources import example_graphs  # noqa: PLC0415

    graphs = example_graphs()
    if args.json:
        print(json.dumps({name: str(path) for name, path in graphs.items()}))
    else:
        width = max(map(len, graphs), default=0)
        for name, path in graphs.items():
            print(f"{name:<{width}}  {path}")
    return EXIT_OK


def _cmd_render(args, out: Console, err: Console) -> int:
    if args.what == "graph":
        return _cmd_render_graph(args, out, err)
    from phyagentos.resources import skill_dirs, tree_dirs
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
    from phyagentos.runtime.trees import render_ascii, render_image

    runtime = BuiltinSkillRuntime.from_dirs(skill_dirs(), tree_dirs())
    if args.name in runtime.skills:
        manifest = runtime.skills.get(args.name)
        if manifest.tree is None:
            from phyagentos.errors import SkillError

            raise SkillError(f"skill {args.name!r} runs on the {manifest.runtime!r} runtime and has no behaviour tree",
                             path=manifest.path)
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


def _cmd_policy(args, out: Console, err: Console) -> int:
    from phyagentos.policy.grasp_policy import GraspPolicy
    from phyagentos.policy.server import PolicyServer

    server = PolicyServer(GraspPolicy(rate_hz=args.rate_hz, horizon=args.horizon), host=args.host, port=args.port,
                          stall_after=args.stall_after)

    def announce() -> None:
        server.wait_ready()
        # One parseable line on stdout: scripts and tests read the bound port from it.
        print(f"serving policy on {server.uri}", flush=True)

    import threading

    threading.Thread(target=announce, daemon=True).start()
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    return EXIT_OK


def _cmd_render_graph(args, out: Console, err: Console) -> int:
    from phyagentos.agent.render import render_image, run_graph_of, to_mermaid
    from phyagentos.protocol import Workspace

    graph = run_graph_of(Workspace.open(args.workspace), args.run)
    mermaid = to_mermaid(graph)
    print(mermaid, end="")
    if args.mermaid:
        args.mermaid.parent.mkdir(parents=True, exist_ok=True)
        args.mermaid.write_text(f"# Run {graph.run_id}\n\n```mermaid\n{mermaid}```\n", encoding="utf-8")
        err.print(f"wrote {args.mermaid}")
    if args.out:
        err.print(f"wrote {render_image(graph, args.out)}")
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``phyagentos`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    out, err = _LazyConsole(), _LazyConsole(stderr=True)
    _setup_logging(args.verbose, err)
    from phyagentos.cli.agent import AGENT_HANDLERS
    from phyagentos.cli.fleet import FLEET_HANDLERS  # [issue 31]
    from phyagentos.cli.planes import PLANE_HANDLERS
    from phyagentos.cli.run import cmd_run
    from phyagentos.cli.skills import SKILL_HANDLERS

    handlers = {**PLANE_HANDLERS, **SKILL_HANDLERS, **AGENT_HANDLERS, "run": cmd_run, "bench": _cmd_bench,
                "validate": _cmd_validate, "examples": _cmd_examples, "render": _cmd_render,
                "policy": _cmd_policy, **FLEET_HANDLERS}
    from phyagentos.cli.skills import skill_search_env
    from phyagentos.cli.view import with_view  # [issue 13]
    handlers = with_view(handlers)
    from phyagentos.cli.real import with_real  # [issue 32]
    handlers = with_real(handlers)
    try:
        with skill_search_env(args, err):
            code = handlers[args.command](args, out, err)
    except PhyAgentOSError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if argv is None and args.command == "run":
        _exit_without_teardown(code)
    return code


def _exit_without_teardown(code: int) -> None:
    """End the ``run`` process now: exit handlers run (runners closed, logs flushed),
    but the interpreter's module teardown (a second or so with the Agent plane loaded
    on a busy machine) is skipped. Only for the console script, never in-process."""
    import atexit  # noqa: PLC0415
    import os  # noqa: PLC0415

    atexit._run_exitfuncs()  # noqa: SLF001 - CPython's own exit sequence, minus the teardown
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    sys.exit(main())
