"""Whole-graph validation before any motion (``validate``, ``submit``, ``run``, ``plan``).

A composition root: it asks the Agent plane about the goal graph (schema, predicates,
which node holds what on which arm) and the Runtime plane about the rest (skill
parameters and trees, the scene, reachability), and turns every problem into one
:class:`~phyagentos.errors.GoalGraphError` naming the user's file and line with the
valid choices. Nothing is registered and nothing moves until :func:`check_goal_graph`
has returned.

Checks, in order:

1. the goal-graph schema (:func:`~phyagentos.agent.goal_graph.load_goal_graph`, with
   bounded YAML: an alias bomb fails in milliseconds);
2. per node: the skill's parameters (required, declared) and, for behaviour-tree
   skills, its tree built with those parameters (every primitive and primitive
   parameter), without a target;
3. per node: the acceptance predicates (names and arguments,
   :func:`~phyagentos.agent.criteria.parse_criteria`);
4. the scene for each target's driver (types, sizes, positions as numbers of the
   right length) and every object and region a parameter or predicate names;
5. one arm holds one object (:mod:`phyagentos.agent.gripper_resources`): implicit
   edges where independent nodes would pick on one arm, or a refusal;
6. reachability per target: IK on every pick and place pose the graph implies.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Protocol

from phyagentos.agent.criteria import parse_criteria
from phyagentos.agent.goal_graph import GoalGraph, load_goal_graph
from phyagentos.agent.gripper_resources import GripperEffect, ImplicitEdge, serialise_gripper_use
from phyagentos.errors import GoalGraphError, VerifierError, format_choices
from phyagentos.yamlsource import clip, excerpt, line_of, load_yaml

if TYPE_CHECKING:
    from phyagentos.protocol import Workspace
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime

__all__ = ["GraphCheck", "RuntimeChecks", "check_goal_graph", "OBJECT_PARAMS", "REGION_PARAMS"]

logger = logging.getLogger(__name__)

#: Parameter and predicate-argument names that name a scene object / region.
OBJECT_PARAMS = ("object", "support")
REGION_PARAMS = ("region",)
_MAX_LISTED = 8


@dataclass(frozen=True)
class GraphCheck:
    """A goal graph that passed every check: the graph with its implicit edges added,
    the edges (``validate`` shows them) and how many poses were checked for reach."""

    graph: GoalGraph
    implicit_edges: tuple[ImplicitEdge, ...]
    poses_checked: int


def _raise(path: Path, problems: list[tuple[int | None, str]]) -> None:
    problems = sorted(problems, key=lambda p: (p[0] or 0))
    line, message = problems[0]
    for other_line, other in problems[1:_MAX_LISTED]:
        message += f"\n  also {path}:{other_line}: {other}" if other_line else f"\n  also: {other}"
    if len(problems) > _MAX_LISTED:
        message += f"\n  ... and {len(problems) - _MAX_LISTED} more"
    raise GoalGraphError(message, path=path, line=line)


class RuntimeChecks(Protocol):
    """The steps of the check that need the Runtime plane, in batches of plain data (see
    :func:`phyagentos.runtime.graph_preflight.build_trees`, ``check_scenes`` and
    ``check_reach``). A scene is whatever ``check_scenes`` returned for it, handed back
    to ``check_reach`` unopened."""

    def build_trees(self, items: list[tuple[str, dict]]) -> list[str | None]: ...

    def check_scenes(self, items: list[tuple[Any, str]]) -> list[tuple[Any, list, tuple | None]]: ...

    def check_reach(self, items: list[tuple[str, str, Any, list[tuple], list[tuple]]]) -> list[list]: ...


class _LocalChecks:
    """:class:`RuntimeChecks` in this process (it imports the runtime's scene and motion code)."""

    def __init__(self, runtime: "BuiltinSkillRuntime", root: Path) -> None:
        self.runtime, self.root = runtime, root

    def build_trees(self, items):
        from phyagentos.runtime.graph_preflight import build_trees  # noqa: PLC0415

        return build_trees(self.runtime.trees, items)

    def check_scenes(self, items):
        from phyagentos.runtime.graph_preflight import check_scenes  # noqa: PLC0415

        return check_scenes(items, root=self.root)

    def check_reach(self, items):
        from phyagentos.runtime.graph_preflight import check_reach  # noqa: PLC0415

        return check_reach(items)


def check_goal_graph(path: str | Path, workspace: "Workspace", runtime: "BuiltinSkillRuntime", *,
                     target: str | None = None, reach: bool = True,
                     checks: RuntimeChecks | None = None) -> GraphCheck:
    """Validate the goal graph at ``path`` as a whole, before anything is registered or moves.

    Args:
        path: the user's goal-graph file.
        workspace: supplies TARGETS.md (target names, drivers, default scenes).
        runtime: supplies the skill manifests (``runtime.skills``) and, unless ``checks``
            is given, the tree library.
        target: ``--target`` override applied to every node (checked like the graph's).
        reach: run the IK reachability check (step 6).
        checks: where the runtime's steps run (trees, scenes, reach); default: here.

    Raises:
        GoalGraphError: the first problem by line (with up to seven more listed), naming
            ``path`` and the 1-based line.
    """
    path = Path(path)
    checks = checks if checks is not None else _LocalChecks(runtime, workspace.root)
    specs = {t.name: t for t in workspace.read("TARGETS").data.targets}
    if target is not None and target not in specs:
        raise GoalGraphError(f"unknown target {target!r} for --target; valid targets: {format_choices(specs)}")
    graph = load_goal_graph(path, skills=runtime.skills.names(), targets=list(specs))
    if target is not None:
        graph = replace(graph, nodes=tuple(replace(n, target=target) for n in graph.nodes))
    raw = load_yaml(path.read_text(encoding="utf-8"), path=path, error=GoalGraphError)  # bounded, already parsed once
    raw_nodes = raw.get("nodes") or []
    problems: list[tuple[int | None, str]] = []

    def node_line(i: int, key: str | None = None, sub: str | None = None) -> int | None:
        item = raw_nodes[i] if i < len(raw_nodes) else None
        if key is not None and isinstance(item, Mapping) and key in item:
            value = item[key]
            if sub is not None and isinstance(value, Mapping) and sub in value:
                return line_of(value, sub)
            return line_of(item, key)
        if key == "params" and isinstance(raw.get("defaults"), Mapping) and "params" in raw["defaults"]:
            return line_of(raw["defaults"], "params")
        return line_of(item) if item is not None else graph.nodes[i].line or None

    # 2-3: skills, trees, predicates
    to_build = {i: (manifest.tree, node.params) for i, node in enumerate(graph.nodes)
                for manifest in [runtime.skills.get(node.skill)]
                if manifest.runtime == "builtin" and manifest.tree and not manifest.check_params(node.params)}
    built = dict(zip(to_build, checks.build_trees(list(to_build.values())))) if to_build else {}
    for i, node in enumerate(graph.nodes):
        manifest = runtime.skills.get(node.skill)
        for problem in manifest.check_params(node.params):
            problems.append((node_line(i, "params"), f"node {node.id!r}: skill {node.skill!r}: {problem}"))
        if built.get(i) is not None:
            problems.append((node_line(i, "params"), f"node {node.id!r}: skill {node.skill!r} does not build "
                                                     f"with these parameters: {built[i]}"))
        try:
            parse_criteria(node.accept, where=f"node {node.id!r} accept")
        except VerifierError as exc:
            problems.append((node_line(i, "accept"), clip(str(exc), 400)))

    # 4: scene per target, names
    raw_scene = raw.get("scene")
    target_names = list(dict.fromkeys(n.target for n in graph.nodes))
    checked_scenes = checks.check_scenes([(raw_scene if raw_scene is not None else (specs[name].scene or None),
                                           specs[name].driver) for name in target_names])
    scenes: dict[str, Any] = {}
    names_of: dict[str, Any] = {}
    for name, (scene, scene_problems, names) in zip(target_names, checked_scenes):
        where = "" if raw_scene is not None else f" (the scene of target {name!r} in TARGETS.md)"
        problems += [(line if raw_scene is not None else None, message + where) for line, message in scene_problems]
        scenes[name], names_of[name] = scene, names
    for i, node in enumerate(graph.nodes):
        names = names_of.get(node.target)
        if names is None:
            continue
        objects, regions = names

        def check_ref(value: Any, kind: str, valid: tuple[str, ...], line: int | None, what: str) -> None:
            if isinstance(value, str) and value not in valid:
                problems.append((line, f"node {node.id!r}: {what} names unknown {kind} {excerpt(value)}; "
                                       f"valid {kind}s: {format_choices(valid) or 'none (the scene has none)'}"))

        for key, value in node.params.items():
            if key in OBJECT_PARAMS:
                check_ref(value, "object", objects, node_line(i, "params", key), f"parameter {key!r}")
            elif key in REGION_PARAMS:  # a place target: a region, or an object to stack on
                check_ref(value, "region or object", regions + objects, node_line(i, "params", key),
                          f"parameter {key!r}")
        try:
            criteria = parse_criteria(node.accept)
        except VerifierError:
            criteria = []
        for c in criteria:
            for arg, value in c.args.items():
                if arg in OBJECT_PARAMS:
                    check_ref(value, "object", objects, node_line(i, "accept"), f"predicate {c.name!r}")
                elif arg in REGION_PARAMS:
                    check_ref(value, "region", regions, node_line(i, "accept"), f"predicate {c.name!r}")
    if problems:
        _raise(path, problems)

    # 5: one arm, one object
    effects = {name: GripperEffect(acquires=m.acquires, releases=m.releases)
               for name in runtime.skills.names() for m in [runtime.skills.get(name)]}
    graph, edges = serialise_gripper_use(graph, effects)

    # 6: reachability per target
    checked = 0
    if reach:
        asks, fallbacks = [], []
        for name, scene in scenes.items():
            picks, places = [], []
            for i, node in enumerate(graph.nodes):
                if node.target != name:
                    continue
                eff = effects.get(node.skill, GripperEffect())
                obj = node.params.get(eff.acquires) if eff.acquires else None
                height = node.params.get("approach_height_m", 0.10)
                height = float(height) if isinstance(height, (int, float)) and not isinstance(height, bool) else 0.10
                if isinstance(obj, str):
                    picks.append((node.id, obj, node_line(i, "params", eff.acquires), height))
                held = node.params.get(eff.releases) if eff.releases else None
                region = node.params.get("region")
                if isinstance(held, str) and isinstance(region, str):
                    places.append((node.id, held, region, node_line(i, "params", "region"), height))
            if names_of[name] is not None:
                checked += 2 * (len(picks) + len(places))
            first = next((node_line(i) for i, n in enumerate(graph.nodes) if n.target == name), None)
            fallbacks.append(line_of(raw, "scene") if raw_scene is not None else first)
            asks.append((specs[name].driver, name, scene, picks, places))
        for fallback, found in zip(fallbacks, checks.check_reach(asks) if asks else []):
            problems += [(line if line is not None else fallback, message) for line, message in found]
        if problems:
            _raise(path, problems)
    for edge in edges:
        logger.info("%s: implicit edge %s -> %s", path, edge.before, edge.after)
    return GraphCheck(graph=graph, implicit_edges=edges, poses_checked=checked)
