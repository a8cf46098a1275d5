"""Targets as resources: one arm holds one thing, so an arm never picks while holding.

A skill declares what it does to its target's gripper (``acquires`` / ``releases`` in
``skills/<name>.yaml``, each naming the parameter that holds the object). From those
declarations every acquiring node of a goal graph has a *holding span* on its target:
from the node that acquires the object to the node that releases it (the same node
for ``pick_and_place``; open-ended when nothing releases it).

Two spans on one target must not overlap. When the user's ``depends_on`` leaves two
spans unordered (two independent picks on one arm), :func:`serialise_gripper_use`
adds an *implicit edge*: the later span (in file order) starts only after the earlier
one released its object, or the other way round when that order would make a cycle.
When neither order is possible (an object that is never released, a release ordered
before its acquire), the graph is refused with the file and line of the node that
would pick while holding. Nodes on different targets never get an edge: multi-arm
graphs keep their parallelism.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Mapping

import networkx as nx

from phyagentos.agent.dag import to_digraph
from phyagentos.agent.goal_graph import GoalGraph, GoalNode
from phyagentos.errors import GoalGraphError

__all__ = ["GripperEffect", "ImplicitEdge", "HoldingSpan", "holding_spans", "serialise_gripper_use", "gripper_effects"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class GripperEffect:
    """What a skill does to its target's gripper: the parameters naming the object it
    ``acquires`` (holds afterwards) and ``releases`` (lets go of); ``None`` for neither."""

    acquires: str | None = None
    releases: str | None = None


@dataclass(frozen=True)
class ImplicitEdge:
    """``after`` waits for ``before``: added so one arm does not hold two objects."""

    before: str
    after: str
    target: str
    reason: str


@dataclass(frozen=True)
class HoldingSpan:
    """Node ``start`` leaves ``obj`` in ``target``'s gripper until node ``end`` releases it
    (``end == start`` for a skill that does both; ``None`` when nothing releases it)."""

    target: str
    obj: str
    start: str
    end: str | None


def gripper_effects(catalog: Mapping[str, object] | None = None) -> dict[str, GripperEffect]:
    """Skill name -> :class:`GripperEffect` from the skill manifests' ``acquires`` /
    ``releases`` (``catalog``: :func:`~phyagentos.agent.skill_catalog.skill_catalog` output)."""
    if catalog is None:
        from phyagentos.agent.skill_catalog import skill_catalog  # noqa: PLC0415

        catalog = skill_catalog()
    return {name: GripperEffect(acquires=getattr(info, "acquires", None), releases=getattr(info, "releases", None))
            for name, info in catalog.items()}


def _param(node: GoalNode, name: str | None) -> str | None:
    value = node.params.get(name) if name else None
    return value if isinstance(value, str) else None


def holding_spans(graph: GoalGraph, effects: Mapping[str, GripperEffect]) -> list[HoldingSpan]:
    """Holding spans of ``graph`` in file order (see the module docstring).

    Raises:
        GoalGraphError: a node releases an object on a target before (in dependency
            order) the node that acquires it.
    """
    dag = to_digraph(graph)
    spans = []
    for node in graph.nodes:
        eff = effects.get(node.skill, GripperEffect())
        obj = _param(node, eff.acquires)
        if obj is None:
            continue
        if _param(node, eff.releases) == obj:
            spans.append(HoldingSpan(node.target, obj, node.id, node.id))
            continue
        releasers = [n for n in graph.nodes if n.id != node.id and n.target == node.target
                     and _param(n, effects.get(n.skill, GripperEffect()).releases) == obj
                     and _param(n, effects.get(n.skill, GripperEffect()).acquires) != obj]
        after = [n for n in releasers if nx.has_path(dag, node.id, n.id)]
        unordered = [n for n in releasers if n not in after and not nx.has_path(dag, n.id, node.id)]
        if after:
            # the first release downstream of the acquire ends the span
            end = min(after, key=lambda n: len(nx.shortest_path(dag, node.id, n.id)))
            spans.append(HoldingSpan(node.target, obj, node.id, end.id))
        elif unordered:
            raise GoalGraphError(
                f"node {unordered[0].id!r} releases {obj!r} on {node.target!r} but does not depend on node "
                f"{node.id!r}, which picks it up; add {node.id!r} to its depends_on",
                path=graph.path, line=unordered[0].line or None)
        else:
            spans.append(HoldingSpan(node.target, obj, node.id, None))
    return spans


def serialise_gripper_use(graph: GoalGraph, effects: Mapping[str, GripperEffect]
                          ) -> tuple[GoalGraph, tuple[ImplicitEdge, ...]]:
    """Order every pair of holding spans on one target; returns the graph with the
    implicit edges added to ``depends_on`` and the edges themselves.

    Args:
        graph: a validated goal graph.
        effects: skill name -> :class:`GripperEffect` (skills not listed have none).

    Raises:
        GoalGraphError: with the file and line of a node that would pick while its arm
            holds another object and no order of the two can avoid it.
    """
    spans = holding_spans(graph, effects)
    dag = to_digraph(graph)
    added: list[ImplicitEdge] = []
    by_id = {n.id: n for n in graph.nodes}

    def done_before(span: HoldingSpan, other: HoldingSpan) -> bool:
        """``span`` has released its object before ``other`` starts."""
        return span.end is not None and (span.end == other.start or nx.has_path(dag, span.end, other.start))

    for i, first in enumerate(spans):
        for second in spans[i + 1:]:
            if first.target != second.target or first.start == second.start:
                continue
            if done_before(first, second) or done_before(second, first):
                continue
            placed = False
            for a, b in ((first, second), (second, first)):
                if a.end is None or nx.has_path(dag, b.start, a.end):
                    continue  # b must start after a's release, which would be a cycle
                dag.add_edge(a.end, b.start)
                added.append(ImplicitEdge(before=a.end, after=b.start, target=a.target,
                                          reason=f"{a.target!r} holds {a.obj!r} from {a.start!r} until {a.end!r}; "
                                                 f"{b.start!r} picks {b.obj!r}"))
                placed = True
                break
            if not placed:
                holder = first if first.end is None else second
                other = second if holder is first else first
                node = by_id[other.start] if holder.end is None else by_id[second.start]
                why = (f"{holder.start!r} picks {holder.obj!r} and nothing releases it" if holder.end is None
                       else f"{first.start!r}..{first.end!r} and {second.start!r}..{second.end!r} depend on each other")
                raise GoalGraphError(
                    f"node {node.id!r} would pick {other.obj!r} on {other.target!r} while the gripper holds "
                    f"another object ({why}); one arm holds one object: release it first (a node with a "
                    f"releasing skill such as 'place') or run the pick on another target",
                    path=graph.path, line=node.line or None)
    if not added:
        return graph, ()
    extra: dict[str, list[str]] = {}
    for edge in added:
        extra.setdefault(edge.after, []).append(edge.before)
        logger.info("implicit edge %s -> %s: %s", edge.before, edge.after, edge.reason)
    nodes = tuple(replace(n, depends_on=n.depends_on + tuple(d for d in extra.get(n.id, ()) if d not in n.depends_on))
                  for n in graph.nodes)
    return replace(graph, nodes=nodes), tuple(added)
