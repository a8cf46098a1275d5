"""``phyagentos plan`` and ``phyagentos mcp``: the thinking half of the Agent plane on the command line.

    phyagentos plan "REQUEST" --workspace WS [--scene SCENE.yaml] [--target NAME] [--run] [--json]
    phyagentos plan "get a stone pickaxe" --workspace WS --library crafter_tech_tree [--run]
    phyagentos mcp --workspace WS [--http] [--port N]

``plan`` prints the goal graph the Goal Planner compiled (YAML and its DAG), validated,
and writes it with the plan's record (model calls, injected context, selector reasons)
under ``WS/plans/<plan id>/``; with ``--run`` the graph then runs like ``phyagentos run``.
Without ``--scene`` it plans on the tabletop scene of ``phyagentos/data/goal_graphs/pick_and_place.yaml``.
A refusal prints its reason and exits 1 (a request that asks that nothing moves, "leave the
blocks where they are", plans nothing and exits 0); a plan still invalid after the repair round is
an error (exit 2), and so is a plan the whole-graph check of ``validate`` refuses
(:func:`phyagentos.app.graph_check.check_goal_graph`: the scene, trees, names, one object
per arm, reachability per target), before anything runs. The model comes from
``llm.yaml`` / ``PHYAGENTOS_LLM_*`` (offline SmolLM2 by default).
"""

from __future__ import annotations

import argparse
import json
from datetime import datetime, timezone
from pathlib import Path

from phyagentos.app.factories import (
    default_scene,
    load_scene,
    make_library_planner,
    make_planner,
    perceived_entities,
)
from phyagentos.cli.arguments import goal_graph_arg

__all__ = ["add_agent_commands", "AGENT_HANDLERS"]

EXIT_OK, EXIT_NOT_SUCCEEDED = 0, 1


def add_agent_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``plan`` and ``mcp`` to the ``phyagentos`` sub-commands."""
    plan = sub.add_parser("plan", help="plan a natural-language request into a validated goal graph (Goal Planner)")
    plan.add_argument("request", help="the instruction, e.g. \"put the cube in the goal region\"")
    plan.add_argument("--workspace", type=Path, required=True, help="workspace directory (created if needed)")
    plan.add_argument("--scene", type=goal_graph_arg, help="scene YAML or a goal graph with a scene, or a shipped example's "
                                                           "name (default: the tabletop scene of pick_and_place)")
    plan.add_argument("--target", help="prefer this target when it fits (the selector decides otherwise)")
    plan.add_argument("--library", type=goal_graph_arg, help="plan as one goal of this goal graph and what it depends on "
                                                   "(a task library, e.g. crafter_tech_tree: a shipped example)")
    plan.add_argument("--run", action="store_true", help="run the planned graph like `phyagentos run`")
    plan.add_argument("--json", action="store_true", help="print one JSON object")
    plan.add_argument("--seed", type=int, default=0, help="base seed of the run's sessions (with --run)")
    plan.add_argument("--reviser", choices=("rules", "model"), default="rules",
                      help="with --run: diagnosis and revision by the rule ladder (default) or the model")
    mcp = sub.add_parser("mcp", help="serve the ToolRegistry as an MCP server (stdio; --http for localhost)")
    mcp.add_argument("--workspace", type=Path, required=True, help="workspace directory (created if needed)")
    mcp.add_argument("--http", action="store_true", help="streamable HTTP on 127.0.0.1 instead of stdio")
    mcp.add_argument("--port", type=int, default=8765, help="HTTP port (default 8765)")
    mcp.add_argument("--no-planner", action="store_true", help="do not offer plan_request (no model is loaded)")


def _cmd_plan(args, out, err) -> int:
    from phyagentos.agent.dag import to_digraph, topological_order  # noqa: PLC0415
    from phyagentos.agent.planner import write_plan  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415

    workspace = Workspace.create(args.workspace)
    if args.library is not None:  # a goal of a task library (agent/library_planner.py)
        planner = make_library_planner(workspace)
        result = planner.plan(args.request, library=args.library)
    else:
        scene = load_scene(args.scene) if args.scene else default_scene()
        planner = make_planner(workspace)
        result = planner.plan(args.request, scene=scene, environment=perceived_entities(workspace),
                              prefer_target=args.target)
    plan_id = datetime.now(timezone.utc).strftime("plan-%Y%m%dT%H%M%S%fZ")
    paths = write_plan(result, workspace.root / "plans" / plan_id)
    poses = None
    if result.status == "planned":
        # the same whole-graph check as validate, submit and run, before anything is printed
        # as valid or runs (a GoalGraphError names the plan's goal_graph.yaml and line: exit 2)
        from phyagentos.app.graph_check import check_goal_graph  # noqa: PLC0415
        from phyagentos.resources import skill_dirs, tree_dirs  # noqa: PLC0415
        from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: PLC0415

        runtime = BuiltinSkillRuntime.from_dirs(skill_dirs(workspace.root), tree_dirs(workspace.root))
        poses = check_goal_graph(paths["goal_graph"], workspace, runtime).poses_checked
    if args.json and not args.run:
        print(json.dumps({**result.to_dict(), "plan_id": plan_id, "goal_graph": str(paths.get("goal_graph", "")),
                          "goal_graph_yaml": result.graph_yaml}, ensure_ascii=False))
    elif not args.json:
        calls = ", ".join(f"{c.purpose} {c.prompt_tokens}+{c.completion_tokens} tok {c.latency_s:.2f} s"
                          for c in result.calls)
        err.print(f"[dim]{planner.client.provider} {planner.client.model}: {calls or 'no model call'}[/dim]")
        if result.status == "nothing_to_do":
            out.print(f"nothing to do: {result.reason}")
        elif result.status != "planned":
            out.print(f"[red]refused ({result.refusal}, by {result.refused_by})[/red]: {result.reason}")
        else:
            print(result.graph_yaml, end="")
            dag = to_digraph(result.graph)
            out.print(f"goal graph: valid, {len(result.graph.nodes)} node(s), {poses} pose(s) reachable")
            for node_id in topological_order(dag):
                node = result.graph.get_node(node_id)
                deps = f" after {', '.join(node.depends_on)}" if node.depends_on else ""
                out.print(f"  {node_id}: {node.skill} on {node.target}{deps}")
        out.print(f"plan: {paths['record'].parent}")
    if result.status != "planned":
        if args.json and args.run:
            print(json.dumps({**result.to_dict(), "plan_id": plan_id}, ensure_ascii=False))
        # a request that asks that nothing moves is met by doing nothing (exit 0); a refusal is not
        return EXIT_OK if result.status == "nothing_to_do" else EXIT_NOT_SUCCEEDED
    if not args.run:
        return EXIT_OK
    from phyagentos.cli.run import cmd_run  # noqa: PLC0415

    run_args = argparse.Namespace(goal_graph=paths["goal_graph"], workspace=args.workspace, json=args.json,
                                  seed=args.seed, target=None, memory="learn", keep_success_images=False,
                                  reviser=args.reviser)
    return cmd_run(run_args, out, err)


def _cmd_mcp(args, out, err) -> int:
    from phyagentos.app.mcp_server import serve  # noqa: PLC0415

    serve(args.workspace, http=args.http, port=args.port, with_planner=not args.no_planner)
    return EXIT_OK


AGENT_HANDLERS = {"plan": _cmd_plan, "mcp": _cmd_mcp}
