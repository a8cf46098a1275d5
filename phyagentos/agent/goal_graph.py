"""Goal graphs: YAML files describing a DAG of skill invocations with acceptance criteria.

A goal graph names, per node, which skill to run on which target with which
parameters, how success is judged (``accept``) and which nodes must succeed first
(``depends_on``). The schema is the pydantic model
:class:`~phyagentos.agent.goal_graph_schema.GoalGraphSpec`, documented for users in
``docs/goal_graphs.md``.

Parsing is strict: unknown keys, unknown skills or targets, bad ids, dangling or
circular dependencies are all :class:`~phyagentos.errors.GoalGraphError` with the file,
the 1-based line of the offending key and the valid choices. The YAML is composed into
a node tree (``yaml.compose``) rather than loaded, so every value keeps its line: each
schema error's location maps back to its YAML node.

Validation collects every problem and raises the one that comes first in the file, so
fixing errors top to bottom works. Cycles are checked last, once each node is valid on
its own.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from phyagentos.agent.dag import find_dependency_cycle, to_digraph
from phyagentos.agent.goal_graph_schema import (
    DEFAULTS_KEYS,
    NODE_ID_PATTERN,
    NODE_KEYS,
    REQUIRED_NODE_KEYS,
    REQUIRED_TOP_LEVEL_KEYS,
    SCHEDULES,
    SCHEMA_VERSION,
    TOP_LEVEL_KEYS,
    GoalGraphSpec,
)
from phyagentos.agent.goal_graph_source import GraphSource, compose
from phyagentos.errors import GoalGraphError, format_choices

__all__ = [
    "SCHEMA_VERSION",
    "NODE_ID_PATTERN",
    "TOP_LEVEL_KEYS",
    "SCHEDULES",
    "REQUIRED_TOP_LEVEL_KEYS",
    "NODE_KEYS",
    "REQUIRED_NODE_KEYS",
    "DEFAULTS_KEYS",
    "GoalNode",
    "GoalGraph",
    "load_goal_graph",
    "parse_goal_graph",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class GoalNode:
    """One node of a goal graph: run ``skill`` on ``target`` and judge it by ``accept``.

    ``params`` and ``limits`` already include the graph's ``defaults``. ``accept`` is kept
    as written (a mapping, or a list of single-key mappings when a predicate repeats);
    predicate semantics belong to the acceptance-predicate module. ``line`` is the 1-based
    line where the node starts in its file (0 for nodes built in code). Treat the dict
    fields as read-only.
    """

    id: str
    skill: str
    target: str
    params: dict[str, Any] = field(default_factory=dict)
    accept: dict[str, Any] | list[dict[str, Any]] = field(default_factory=dict)
    depends_on: tuple[str, ...] = ()
    limits: dict[str, float] = field(default_factory=dict)
    line: int = 0
    runtime: str = "builtin"  # SkillRuntime (SKILLRUNTIME.md name) the session runs on


@dataclass(frozen=True)
class GoalGraph:
    """A validated, acyclic goal graph; ``nodes`` are in file order.

    ``scene`` is the optional initial scene for the target (objects, regions,
    obstacles), passed through unvalidated for the target to interpret.
    """

    name: str
    description: str
    path: Path | None
    scene: dict[str, Any] | None
    nodes: tuple[GoalNode, ...]
    #: Where the graph came from when a program wrote it (the Goal Planner: ``request``,
    #: ``model_calls`` as ModelCallRecord mappings, which its root sessions' contexts keep).
    provenance: dict[str, Any] | None = None
    #: How ready nodes are submitted (:data:`SCHEDULES`).
    schedule: str = "eager"

    @property
    def node_ids(self) -> tuple[str, ...]:
        """Node ids in file order."""
        return tuple(n.id for n in self.nodes)

    def get_node(self, node_id: str) -> GoalNode:
        """Return the node called ``node_id``; ``KeyError`` listing valid ids otherwise."""
        for node in self.nodes:
            if node.id == node_id:
                return node
        raise KeyError(f"no node {node_id!r} in goal graph {self.name!r}; valid node ids: "
                       f"{format_choices(self.node_ids)}")


def load_goal_graph(
    path: str | Path, *, skills: Collection[str], targets: Collection[str]
) -> GoalGraph:
    """Read and validate the goal graph at ``path``.

    ``skills`` and ``targets`` are the names the runtime offers; a node naming anything
    else is rejected. Raises :class:`GoalGraphError` (with ``path`` and ``line``) for an
    unreadable file or any schema violation.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise GoalGraphError(f"cannot read goal graph: {exc}", path=path) from exc
    return parse_goal_graph(text, path=path, skills=skills, targets=targets)


def parse_goal_graph(
    text: str,
    *,
    path: str | Path | None = None,
    skills: Collection[str],
    targets: Collection[str],
) -> GoalGraph:
    """Validate goal-graph YAML ``text``; ``path`` is only used in messages and the result.

    See :func:`load_goal_graph`.
    """
    source = GraphSource(compose(text, path))
    problems = list(source.problems)  # duplicate keys, values YAML cannot construct
    spec = None
    try:
        spec = GoalGraphSpec.model_validate(source.data, context={"skills": skills, "targets": targets})
    except ValidationError as exc:
        problems += source.locate_all(exc)
    if problems or spec is None:
        line, _column, message = min(problems, key=lambda p: (p[0], p[1]))  # the first in the file
        raise GoalGraphError(message, path=path, line=line)
    graph = _build(spec, source, path)
    _reject_cycles(graph, source, path)
    logger.debug("loaded goal graph %r (%d nodes) from %s", graph.name, len(graph.nodes),
                 path or "<text>")
    return graph


def _build(spec: GoalGraphSpec, source: GraphSource, path: str | Path | None) -> GoalGraph:
    """The :class:`GoalGraph` of a valid ``spec``: ``defaults`` applied, each node's line."""
    defaults = spec.defaults
    nodes = []
    for i, node in enumerate(spec.nodes):
        nodes.append(GoalNode(
            id=node.id,
            skill=node.skill or defaults.skill or "",
            target=node.target or defaults.target or "",
            # Node params and limits override defaults key by key rather than replacing them.
            params={**copy.deepcopy(defaults.params or {}), **node.params},
            accept=node.accept,
            depends_on=node.depends_on,
            limits={**copy.deepcopy(defaults.limits or {}), **node.limits},
            line=source.line(("nodes", i)),
            runtime=node.runtime or defaults.runtime or "builtin",
        ))
    return GoalGraph(name=spec.name, description=spec.description,
                     path=Path(path) if path is not None else None, scene=spec.scene,
                     nodes=tuple(nodes), provenance=spec.provenance, schedule=spec.schedule)


def _reject_cycles(graph: GoalGraph, source: GraphSource, path: str | Path | None) -> None:
    cycle = find_dependency_cycle(to_digraph(graph))
    if cycle is None:
        return
    index = {node.id: i for i, node in enumerate(graph.nodes)}

    def line(dependent: str, dependency: str) -> int:
        """Line of ``dependency`` in the depends_on of ``dependent``."""
        k = graph.nodes[index[dependent]].depends_on.index(dependency)
        return source.line(("nodes", index[dependent], "depends_on", k))

    closing = [(cycle[i - 1], cycle[i]) for i in range(len(cycle))]
    # Report at the depends_on entry of the cycle's earliest node; list every edge so
    # the user can choose which dependency to drop.
    edges = ", ".join(f"{v!r} depends_on {u!r} (line {line(v, u)})"
                      for u, v in closing[1:] + closing[:1])
    shown = " -> ".join((*cycle, cycle[0]))
    raise GoalGraphError(
        f"dependency cycle {shown} (x -> y means y depends on x); a goal graph must be "
        f"acyclic, remove one of: {edges}",
        path=path, line=line(cycle[0], cycle[-1]),
    )
