"""``phyagentos render graph``: a run's goal DAG with node states and session lineage.

Each goal node is a box (cluster) labelled with its skill and TASK.md state; inside it,
the node's sessions in creation order, each with its lifecycle state, verdict,
diagnosed cause, and an arrow to the child a replan created (labelled with the
recovery strategy). Dependency edges join the nodes. :func:`plan_graph_of` gives the same
picture for a compiled goal graph before any session. One renderer per format:

- Mermaid flowchart text (:func:`to_mermaid`), which renders inside Markdown
  (GitHub, GitLab, most editors);
- Graphviz DOT (:func:`to_dot`) rendered to PNG or SVG by the ``dot`` executable
  (:func:`render_image`; ``apt-get install graphviz``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import networkx as nx

from phyagentos.errors import RenderError
from phyagentos.protocol import SessionRecord, Workspace

from . import dag as dagmod
from .coordinator import node_state_of

__all__ = ["SessionBox", "NodeBox", "RunGraph", "STATE_COLOURS", "run_graph_of", "plan_graph_of", "to_mermaid",
           "to_dot", "render_image"]

#: (fill, border) per state: nodes by their TASK.md state (plus ``paused`` and
#: ``held_by_estop``, which the live view shows for a node a signal holds), sessions by
#: their lifecycle state; any other active state is drawn as ``running``.
STATE_COLOURS: dict[str, tuple[str, str]] = {
    "succeeded": ("#c8e6c9", "#2e7d32"),
    "failed": ("#ffcdd2", "#c62828"),
    "rejected": ("#ffcdd2", "#c62828"),
    "timed_out": ("#ffcdd2", "#c62828"),
    "blocked": ("#eeeeee", "#757575"),
    "cancelled": ("#e0e0e0", "#424242"),
    "replanned": ("#ffe0b2", "#ef6c00"),
    "waiting": ("#ffffff", "#9e9e9e"),
    "pending": ("#ffffff", "#9e9e9e"),
    "ready": ("#e3f2fd", "#1565c0"),
    "running": ("#fff59d", "#f9a825"),
    "paused": ("#ffe082", "#8d6e00"),
    "held_by_estop": ("#ef9a9a", "#8e0000"),
}
_ACTIVE = STATE_COLOURS["running"]  # claimed ... verifying


@dataclass(frozen=True)
class SessionBox:
    """One session as drawn: id, short label parts, and its parent."""

    session_id: str
    state: str
    verdict: str | None
    cause: str | None
    strategy: str | None
    parent: str | None


@dataclass(frozen=True)
class NodeBox:
    """One goal node: id, skill, state, dependencies and its sessions in creation order."""

    id: str
    skill: str
    state: str
    depends_on: tuple[str, ...]
    sessions: tuple[SessionBox, ...] = field(default_factory=tuple)


@dataclass(frozen=True)
class RunGraph:
    """A run's goal DAG with sessions (what the renderers draw)."""

    run_id: str
    nodes: tuple[NodeBox, ...]


def _box(rec: SessionRecord) -> SessionBox:
    verdict = rec.attempts[-1].verdict if rec.attempts else None
    return SessionBox(session_id=rec.session_id, state=rec.state, verdict=verdict.verdict if verdict else None,
                      cause=verdict.diagnosis.cause if verdict and verdict.diagnosis else None,
                      strategy=rec.recovery.strategy if rec.recovery else None, parent=rec.parent_session_id)


def run_graph_of(workspace: Workspace, run_id: str | None = None) -> RunGraph:
    """The graph of ``run_id`` (default: the run in TASK.md, else the newest run).

    Node states come from TASK.md when it describes that run, else from each node's
    latest session (blocked nodes propagated along dependencies).

    Raises:
        RenderError: the workspace has no sessions, or none of ``run_id`` (the
            message lists the runs it has).
    """
    sessions = workspace.list_sessions()
    runs = list(dict.fromkeys(s.run_id for s in sessions))
    task = workspace.read("TASK").data
    run = run_id or task.run_id or (runs[-1] if runs else None)
    mine = [s for s in sessions if s.run_id == run]
    task_nodes = {n.id: n for n in task.nodes} if task.run_id == run else {}
    if not mine and not task_nodes:
        raise RenderError(f"no sessions of run {run!r} in {workspace.root}; runs: {', '.join(runs) or 'none'}")
    by_node: dict[str, list[SessionRecord]] = {}
    for s in mine:
        by_node.setdefault(s.node, []).append(s)
    order = list(task_nodes) or list(by_node)
    for node in by_node:
        if node not in order:
            order.append(node)
    deps = {n: tuple(task_nodes[n].depends_on) if n in task_nodes else tuple(by_node[n][0].depends_on) for n in order}
    if task_nodes:
        states = {n: task_nodes[n].state if n in task_nodes else dagmod.WAITING for n in order}
    else:
        graph = nx.DiGraph()
        graph.add_nodes_from(order)
        graph.add_edges_from((d, n) for n in order for d in deps[n] if d in order)
        raw = {n: node_state_of(by_node[n][-1].state) if n in by_node else dagmod.WAITING for n in order}
        states = dagmod.propagate_blocked(graph, raw)
    nodes = tuple(
        NodeBox(id=n, skill=task_nodes[n].skill if n in task_nodes else by_node[n][0].skill, state=states[n],
                depends_on=deps[n], sessions=tuple(_box(s) for s in by_node.get(n, [])))
        for n in order
    )
    return RunGraph(run_id=str(run), nodes=nodes)


def plan_graph_of(dag: nx.DiGraph, states: Mapping[str, str] | None = None, *, run_id: str = "plan") -> RunGraph:
    """The graph of a compiled goal graph before (or without) its sessions, for the same renderers.

    Args:
        dag: a goal DAG from :func:`phyagentos.agent.dag.to_digraph` (attribute ``node``
            holds the goal node; edges run dependency -> dependent).
        states: node id -> state (``TASK.md`` states); missing ids are ``waiting`` and
            blocked nodes are propagated along dependencies. Default: all ``waiting``.
        run_id: the title the pictures carry.

    Raises:
        GoalGraphError: ``states`` names an unknown node or state (the message lists the
            valid ones).
    """
    full = dagmod.propagate_blocked(dag, states or {})
    nodes = []
    for n in dag.nodes:
        goal_node = dag.nodes[n].get("node")
        nodes.append(NodeBox(id=n, skill=goal_node.skill if goal_node is not None else "?", state=full[n],
                             depends_on=tuple(dag.predecessors(n))))
    return RunGraph(run_id=run_id, nodes=tuple(nodes))


def _short(session_id: str, run_id: str) -> str:
    return session_id[len(run_id) + 1:] if session_id.startswith(run_id + "-") else session_id


def _ident(prefix: str, text: str) -> str:
    return prefix + re.sub(r"[^A-Za-z0-9_]", "_", text)


def _mermaid_text(text: str) -> str:
    return text.replace('"', "#quot;")


def _session_lines(s: SessionBox) -> list[str]:
    lines = [s.state + (f" · {s.verdict}" if s.verdict else "")]
    if s.strategy:
        lines.append(f"strategy: {s.strategy}")
    if s.cause:
        lines.append(f"cause: {s.cause}")
    return lines


def to_mermaid(graph: RunGraph) -> str:
    """Mermaid ``flowchart`` text of ``graph`` (paste into a ```` ```mermaid ```` block)."""
    out = ["flowchart LR"]
    classes: dict[str, list[str]] = {}
    for node in graph.nodes:
        nid = _ident("n_", node.id)
        out.append(f'  subgraph {nid}["{_mermaid_text(f"{node.id} · {node.skill} · {node.state}")}"]')
        out.append("    direction TB")
        if not node.sessions:
            pid = _ident("p_", node.id)
            out.append(f'    {pid}["{_mermaid_text("no session yet")}"]')
            classes.setdefault(node.state, []).append(pid)
        for s in node.sessions:
            sid = _ident("s_", s.session_id)
            label = "<br/>".join(_mermaid_text(x) for x in [_short(s.session_id, graph.run_id), *_session_lines(s)])
            out.append(f'    {sid}["{label}"]')
            classes.setdefault(s.state if s.state in STATE_COLOURS else "running", []).append(sid)
        for s in node.sessions:
            if s.parent:
                edge = f"replan: {s.strategy}" if s.strategy else "replan"
                out.append(f'    {_ident("s_", s.parent)} -- "{_mermaid_text(edge)}" --> {_ident("s_", s.session_id)}')
        out.append("  end")
        classes.setdefault("node_" + node.state, []).append(nid)
    for node in graph.nodes:
        for dep in node.depends_on:
            out.append(f"  {_ident('n_', dep)} --> {_ident('n_', node.id)}")
    for name, members in classes.items():
        fill, stroke = STATE_COLOURS.get(name.removeprefix("node_"), _ACTIVE)
        out.append(f"  classDef {name} fill:{fill},stroke:{stroke}")
        out.append(f"  class {','.join(members)} {name}")
    return "\n".join(out) + "\n"


def _dot_text(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')


def to_dot(graph: RunGraph, *, link_prefix: str | None = None) -> str:
    """Graphviz DOT text of ``graph``: one cluster per goal node (filled by its state,
    dashed when blocked), its sessions inside in creation order, an orange arrow from a
    session to the child its replan created (labelled with the strategy), a bold arrow per
    dependency.

    Args:
        graph: what to draw.
        link_prefix: for a page (the live view): each session links to
            ``link_prefix + session_id``, nodes and sessions carry ``id`` and ``class``
            attributes (``dagnode``/``dagsession`` and ``state-<state>``) for the page's
            script, the background is transparent and there is no title. ``None``
            (default): a standalone picture titled with the run id.
    """
    page = link_prefix is not None
    out = ["digraph run {",
           "  compound=true; rankdir=LR; fontname=Helvetica;" + (" bgcolor=transparent;" if page else ""),
           '  node [shape=box, style="rounded,filled", fontname=Helvetica, fontsize=10];',
           "  edge [fontname=Helvetica];"]
    if not page:
        out.append(f'  label="run {_dot_text(graph.run_id)}"; labelloc=t;')
    anchors: dict[str, tuple[str, str]] = {}  # node id -> (first, last) drawn item
    for node in graph.nodes:
        fill, stroke = STATE_COLOURS.get(node.state, _ACTIVE)
        style = "rounded,filled,dashed" if node.state == "blocked" else "rounded,filled"
        cid = _ident("cluster_", node.id)
        out.append(f"  subgraph {cid} {{")
        attrs = (f'    label="{_dot_text(f"{node.id} ({node.skill}): {node.state}")}"; style="{style}"; '
                 f'fillcolor="{fill}"; color="{stroke}"; penwidth=2;')
        if page:
            attrs += f' id="{_dot_text("node-" + node.id)}"; class="dagnode state-{_dot_text(node.state)}";'
        out.append(attrs)
        items = []
        if not node.sessions:
            pid = _ident("p_", node.id)
            out.append(f'    {pid} [label="no session yet", fillcolor="white", color="#bdbdbd"];')
            items.append(pid)
        for s in node.sessions:
            sfill, sstroke = STATE_COLOURS.get(s.state, _ACTIVE)
            sid = _ident("s_", s.session_id)
            label = "\\n".join(_dot_text(x) for x in [_short(s.session_id, graph.run_id), *_session_lines(s)])
            link = (f', URL="{_dot_text(link_prefix + s.session_id)}", target="_top", '
                    f'id="{_dot_text("session-" + s.session_id)}", class="dagsession state-{_dot_text(s.state)}"'
                    if page else "")
            out.append(f'    {sid} [label="{label}", fillcolor="{sfill}", color="{sstroke}"{link}];')
            items.append(sid)
        for s in node.sessions:
            if s.parent:
                edge = f"replan: {s.strategy}" if s.strategy else "replan"
                out.append(f'    {_ident("s_", s.parent)} -> {_ident("s_", s.session_id)} '
                           f'[label="{_dot_text(edge)}", fontsize=9, color="#ef6c00", fontcolor="#ef6c00", penwidth=2];')
        out.append("  }")
        anchors[node.id] = (items[0], items[-1])
    for node in graph.nodes:
        for dep in node.depends_on:
            if dep in anchors:
                out.append(f"  {anchors[dep][1]} -> {anchors[node.id][0]} "
                           f"[ltail={_ident('cluster_', dep)}, lhead={_ident('cluster_', node.id)}, penwidth=2];")
    out.append("}")
    return "\n".join(out) + "\n"


def render_image(graph: RunGraph, path: str | Path) -> Path:
    """Render ``graph`` to ``path`` (``.png`` or ``.svg``) with Graphviz ``dot``.

    Raises:
        RenderError: ``dot`` is not installed, fails, or the suffix is not png/svg.
    """
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    if fmt not in ("png", "svg"):
        raise RenderError(f"unsupported image format {path.suffix!r}; valid: '.png', '.svg'")
    exe = shutil.which("dot")
    if exe is None:
        raise RenderError("rendering a graph image needs Graphviz 'dot' (apt-get install graphviz)")
    result = subprocess.run([exe, f"-T{fmt}"], input=to_dot(graph).encode(), capture_output=True, timeout=60, check=False)
    if result.returncode != 0:
        raise RenderError(f"dot failed: {result.stderr.decode(errors='replace').strip()}")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(result.stdout)
    return path
