"""Goal graphs as networkx DAGs, and the node-state logic behind ``TASK.md``.

A goal graph becomes a :class:`networkx.DiGraph` whose nodes are the goal-node ids
(attribute ``node`` holds the :class:`~phyagentos.agent.goal_graph.GoalNode`) and whose
edges run from a dependency to its dependent. Node insertion order is file order, which
every function here uses to break ties, so results are deterministic.

Node states (``TASK.md``):

- ``waiting``: not started; may still run.
- ``ready`` / ``running``: handed to a session / session in progress.
- ``succeeded``, ``failed``, ``cancelled``: terminal outcomes of the node's session.
- ``blocked``: terminal; an ancestor failed, was blocked or was cancelled, so the node
  will never run.

The functions are pure: they read a ``states`` mapping (node id -> state; missing ids
count as ``waiting``) and return new values, never mutating their inputs.
"""

from __future__ import annotations

import logging
import weakref
from collections.abc import Mapping
from typing import TYPE_CHECKING

import networkx as nx

from phyagentos.errors import GoalGraphError, format_choices

if TYPE_CHECKING:  # import only for annotations: goal_graph imports this module
    from phyagentos.agent.goal_graph import GoalGraph

__all__ = [
    "WAITING",
    "READY",
    "RUNNING",
    "SUCCEEDED",
    "FAILED",
    "BLOCKED",
    "CANCELLED",
    "NODE_STATES",
    "TERMINAL_STATES",
    "BLOCKING_STATES",
    "to_digraph",
    "topological_order",
    "find_dependency_cycle",
    "ready_nodes",
    "blocked_nodes",
    "propagate_blocked",
    "is_complete",
]

logger = logging.getLogger(__name__)

WAITING = "waiting"
READY = "ready"
RUNNING = "running"
SUCCEEDED = "succeeded"
FAILED = "failed"
BLOCKED = "blocked"
CANCELLED = "cancelled"

#: Every valid node state, in lifecycle order.
NODE_STATES: tuple[str, ...] = (WAITING, READY, RUNNING, SUCCEEDED, FAILED, BLOCKED, CANCELLED)
#: States a node never leaves.
TERMINAL_STATES: frozenset[str] = frozenset({SUCCEEDED, FAILED, BLOCKED, CANCELLED})
#: States of an ancestor that prevent a node from ever running.
BLOCKING_STATES: frozenset[str] = frozenset({FAILED, BLOCKED, CANCELLED})

def to_digraph(graph: GoalGraph) -> nx.DiGraph:
    """Return the DAG of ``graph``: nodes keyed by id with attribute ``node``, edges dep -> dependent.

    Nodes are inserted in file order. Raises :class:`GoalGraphError` if a dependency names
    a node that is not in the graph or an id is repeated (only possible for graphs built
    in code; :func:`~phyagentos.agent.goal_graph.load_goal_graph` rejects both). Cycles
    are not rejected here; see :func:`find_dependency_cycle`.
    """
    dag = nx.DiGraph(name=graph.name)
    for node in graph.nodes:
        if node.id in dag:
            raise GoalGraphError(
                f"duplicate node id {node.id!r}", path=graph.path, line=node.line or None
            )
        dag.add_node(node.id, node=node)
    for node in graph.nodes:
        for dep in node.depends_on:
            if dep not in dag:
                raise GoalGraphError(
                    f"node {node.id!r} depends on unknown node {dep!r}; "
                    f"valid node ids: {format_choices(dag.nodes)}",
                    path=graph.path,
                    line=node.line or None,
                )
            dag.add_edge(dep, node.id)
    return dag


def _file_order(dag: nx.DiGraph) -> dict[str, int]:
    return {n: i for i, n in enumerate(dag.nodes)}


#: Topological orders of frozen DAGs (whose structure cannot change), by DAG.
_FROZEN_ORDERS: weakref.WeakKeyDictionary[nx.DiGraph, tuple[str, ...]] = weakref.WeakKeyDictionary()


def topological_order(dag: nx.DiGraph) -> list[str]:
    """Return node ids in dependency order, ties broken by file order.

    The order of a frozen DAG (:func:`networkx.freeze`: no node or edge can be added or
    removed; the AgentCoordinator freezes its own) is computed once: the coordinator
    asks for it several times per step, and sorting again cost O(n log n) each time.

    Raises :class:`GoalGraphError` if ``dag`` has a cycle.
    """
    frozen = nx.is_frozen(dag)
    if frozen and (kept := _FROZEN_ORDERS.get(dag)) is not None:
        return list(kept)
    order = _file_order(dag)
    try:
        result = list(nx.lexicographical_topological_sort(dag, key=order.__getitem__))
    except nx.NetworkXUnfeasible as exc:
        cycle = find_dependency_cycle(dag)
        shown = " -> ".join((*cycle, cycle[0])) if cycle else "?"
        raise GoalGraphError(f"goal graph has a dependency cycle: {shown}") from exc
    if frozen:
        _FROZEN_ORDERS[dag] = tuple(result)
    return result


def find_dependency_cycle(dag: nx.DiGraph) -> tuple[str, ...] | None:
    """Return one dependency cycle as node ids ``(a, b, ..., z)`` or ``None`` if acyclic.

    Consecutive ids are edges (``a -> b`` means ``b`` depends on ``a``) and ``z -> a``
    closes the cycle. The cycle is rotated to start at its earliest node in file order,
    so the same file always yields the same message.
    """
    try:
        edges = nx.find_cycle(dag)
    except nx.NetworkXNoCycle:
        return None
    cycle = [u for u, _v in edges]
    order = _file_order(dag)
    start = min(range(len(cycle)), key=lambda i: order[cycle[i]])
    return tuple(cycle[start:] + cycle[:start])


def _checked_states(dag: nx.DiGraph, states: Mapping[str, str]) -> dict[str, str]:
    """Return a full id -> state dict (missing ids are ``waiting``), rejecting bad input."""
    unknown_ids = [n for n in states if n not in dag]
    if unknown_ids:
        raise GoalGraphError(
            f"states name unknown node(s) {format_choices(unknown_ids)}; "
            f"valid node ids: {format_choices(dag.nodes)}"
        )
    full = {n: states.get(n, WAITING) for n in dag.nodes}
    for node_id, state in full.items():
        if state not in NODE_STATES:
            raise GoalGraphError(
                f"node {node_id!r} has unknown state {state!r}; "
                f"valid states: {format_choices(NODE_STATES)}"
            )
    return full


def ready_nodes(dag: nx.DiGraph, states: Mapping[str, str]) -> list[str]:
    """Return the ``waiting`` nodes whose predecessors all ``succeeded``, in topological order.

    Roots (no dependencies) that are waiting are always ready. Ties are broken by file
    order, so the first element is the node a sequential scheduler should start next.
    """
    full = _checked_states(dag, states)
    return [
        n
        for n in topological_order(dag)
        if full[n] == WAITING and all(full[p] == SUCCEEDED for p in dag.predecessors(n))
    ]


def blocked_nodes(dag: nx.DiGraph, states: Mapping[str, str]) -> list[str]:
    """Return the ``waiting`` nodes with any ancestor failed, blocked or cancelled.

    Such nodes can never run. Nodes on independent branches are not affected. Returned
    in topological order.
    """
    full = _checked_states(dag, states)
    # One pass in topological order: a node is doomed if any predecessor is in a
    # blocking state or is itself doomed, which covers every ancestor transitively.
    doomed: dict[str, bool] = {}
    result = []
    for n in topological_order(dag):
        doomed[n] = any(full[p] in BLOCKING_STATES or doomed[p] for p in dag.predecessors(n))
        if doomed[n] and full[n] == WAITING:
            result.append(n)
    return result


def propagate_blocked(dag: nx.DiGraph, states: Mapping[str, str]) -> dict[str, str]:
    """Return a new id -> state dict for every node with :func:`blocked_nodes` set to ``blocked``.

    Missing ids appear as ``waiting``; ``states`` itself is not modified.
    """
    full = _checked_states(dag, states)
    newly_blocked = blocked_nodes(dag, full)
    for n in newly_blocked:
        full[n] = BLOCKED
    if newly_blocked:
        logger.debug("blocked %s after upstream failure", ", ".join(newly_blocked))
    return full


def is_complete(dag: nx.DiGraph, states: Mapping[str, str]) -> bool:
    """Return whether every node is terminal (succeeded, failed, blocked or cancelled)."""
    full = _checked_states(dag, states)
    return all(state in TERMINAL_STATES for state in full.values())
