"""A run's goal DAG as clickable SVG, laid out server-side by Graphviz ``dot``.

One cluster per goal node (filled by its state: waiting, ready, running, succeeded,
failed, blocked, cancelled), its sessions inside in creation order (each a link to the
session page, coloured by lifecycle state), an orange arrow from a session to the child
its replan created (labelled with the recovery strategy), and a bold arrow per
dependency. Blocked nodes are drawn dashed, so a blocked subgraph stands out.
"""

from __future__ import annotations

import functools
import re
import shutil
import subprocess
from typing import Any

from phyagentos.errors import RenderError

__all__ = ["STATE_COLOURS", "to_dot", "to_svg"]

#: (fill, border) per node or session state.
STATE_COLOURS = {
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
_ACTIVE = ("#fff59d", "#f9a825")  # claimed ... verifying


def _q(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')


def _ident(prefix: str, text: str) -> str:
    return prefix + re.sub(r"[^A-Za-z0-9_]", "_", text)


def to_dot(graph: dict[str, Any], *, link_prefix: str = "/session/") -> str:
    """DOT text of ``graph`` (as :func:`phyagentos.view.data.run_graph` returns it)."""
    run_id = graph["run_id"]
    out = ["digraph run {", "  compound=true; rankdir=LR; fontname=Helvetica; bgcolor=transparent;",
           '  node [shape=box, style="rounded,filled", fontname=Helvetica, fontsize=10];',
           "  edge [fontname=Helvetica];"]
    anchors: dict[str, tuple[str, str]] = {}
    for node in graph["nodes"]:
        fill, stroke = STATE_COLOURS.get(node["state"], _ACTIVE)
        style = "rounded,filled,dashed" if node["state"] == "blocked" else "rounded,filled"
        cid = _ident("cluster_", node["id"])
        out.append(f"  subgraph {cid} {{")
        out.append(f'    label="{_q(node["id"])} ({_q(node["skill"])}): {_q(node["state"])}"; style="{style}"; '
                   f'fillcolor="{fill}"; color="{stroke}"; penwidth=2; id="{_q("node-" + node["id"])}"; '
                   f'class="dagnode state-{_q(node["state"])}";')
        items = []
        if not node["sessions"]:
            pid = _ident("p_", node["id"])
            out.append(f'    {pid} [label="no session yet", fillcolor="white", color="#bdbdbd"];')
            items.append(pid)
        for s in node["sessions"]:
            sfill, sstroke = STATE_COLOURS.get(s["state"], _ACTIVE)
            short = s["session_id"][len(run_id) + 1:] if s["session_id"].startswith(run_id + "-") else s["session_id"]
            lines = [short, s["state"] + (f" · {s['verdict']}" if s["verdict"] else "")]
            if s["cause"]:
                lines.append(f"cause: {s['cause']}")
            label = "\\n".join(_q(x) for x in lines)
            sid = _ident("s_", s["session_id"])
            out.append(f'    {sid} [label="{label}", fillcolor="{sfill}", color="{sstroke}", '
                       f'URL="{_q(link_prefix + s["session_id"])}", target="_top", '
                       f'id="{_q("session-" + s["session_id"])}", class="dagsession state-{_q(s["state"])}"];')
            items.append(sid)
        for s in node["sessions"]:
            if s["parent"]:
                edge = f"replan: {s['strategy']}" if s["strategy"] else "replan"
                out.append(f'    {_ident("s_", s["parent"])} -> {_ident("s_", s["session_id"])} '
                           f'[label="{_q(edge)}", fontsize=9, color="#ef6c00", fontcolor="#ef6c00", penwidth=2];')
        out.append("  }")
        anchors[node["id"]] = (items[0], items[-1])
    for node in graph["nodes"]:
        for dep in node["depends_on"]:
            if dep in anchors:
                out.append(f"  {anchors[dep][1]} -> {anchors[node['id']][0]} "
                           f"[ltail={_ident('cluster_', dep)}, lhead={_ident('cluster_', node['id'])}, penwidth=2];")
    out.append("}")
    return "\n".join(out) + "\n"


@functools.lru_cache(maxsize=64)
def _render(dot_text: str) -> str:
    exe = shutil.which("dot")
    if exe is None:
        raise RenderError("drawing the DAG needs Graphviz 'dot' (apt-get install graphviz)")
    result = subprocess.run([exe, "-Tsvg"], input=dot_text.encode(), capture_output=True, timeout=30, check=False)
    if result.returncode != 0:
        raise RenderError(f"dot failed: {result.stderr.decode(errors='replace').strip()}")
    svg = result.stdout.decode("utf-8")
    return svg[svg.find("<svg"):]  # drop the XML prolog and DOCTYPE so it inlines in HTML


def to_svg(graph: dict[str, Any]) -> str:
    """Inline SVG of ``graph`` (cached by content: an unchanged run is laid out once).

    Raises:
        RenderError: Graphviz is missing or fails.
    """
    return _render(to_dot(graph))
