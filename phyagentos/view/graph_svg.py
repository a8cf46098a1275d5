"""A run's goal DAG as clickable SVG, laid out server-side by Graphviz ``dot`` from the
project's one DOT renderer (:func:`phyagentos.agent.render.to_dot`).

One cluster per goal node (filled by its state: waiting, ready, running, succeeded,
failed, blocked, cancelled), its sessions inside in creation order (each a link to the
session page, coloured by lifecycle state), an orange arrow from a session to the child
its replan created (labelled with the recovery strategy), and a bold arrow per
dependency. Blocked nodes are drawn dashed, so a blocked subgraph stands out.
"""

from __future__ import annotations

import functools
import shutil
import subprocess
from typing import Any

from phyagentos.agent.render import STATE_COLOURS, NodeBox, RunGraph, SessionBox
from phyagentos.agent.render import to_dot as render_dot
from phyagentos.errors import RenderError

__all__ = ["STATE_COLOURS", "to_dot", "to_svg"]


def _run_graph(graph: dict[str, Any]) -> RunGraph:
    """The :class:`~phyagentos.agent.render.RunGraph` of the view's graph data."""
    return RunGraph(run_id=graph["run_id"], nodes=tuple(
        NodeBox(id=n["id"], skill=n["skill"], state=n["state"], depends_on=tuple(n["depends_on"]),
                sessions=tuple(SessionBox(session_id=s["session_id"], state=s["state"], verdict=s["verdict"],
                                          cause=s["cause"], strategy=s["strategy"], parent=s["parent"])
                               for s in n["sessions"]))
        for n in graph["nodes"]))


def to_dot(graph: dict[str, Any], *, link_prefix: str = "/session/") -> str:
    """DOT text of ``graph`` (as :func:`phyagentos.view.data.run_graph` returns it): the
    one DOT renderer (:func:`phyagentos.agent.render.to_dot`) with session links."""
    return render_dot(_run_graph(graph), link_prefix=link_prefix)


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
