"""The behaviour tree as a graph: an SVG drawn from ``tree.json``'s flat node list.

Leaves take consecutive slots in depth-first order and a parent sits centred on its first
and last child. Top-down (one row per depth) for up to 6 leaves; wider trees are laid out
left to right (one column per depth, leaves down the page) so they fit the panel. Each node is a ``<g
class="btn bt-<status>" data-i=<node index>>`` (status colours in view.css); a running
leaf also gets ``active-leaf`` (a thick outline and a ▶), so the leaf the robot is
executing stands out. The browser re-colours the same elements to replay the tree's
history under the timeline cursor (view.js).
"""

from __future__ import annotations

import html
from typing import Any

__all__ = ["MAX_SVG_NODES", "tree_svg"]

#: Larger trees are drawn as the table only (an SVG of thousands of boxes helps nobody).
MAX_SVG_NODES = 400
_W, _H, _DX, _DY, _PAD = 118, 30, 128, 52, 8


def _short(text: str, n: int = 17) -> str:
    return text if len(text) <= n else text[: n - 1] + "…"


def tree_svg(nodes: list[dict[str, Any]]) -> str:
    """SVG markup of the tree whose nodes are ``[{id, parent, name, type, kind, status, message}]``
    (depth-first, ``parent`` an index or None). Empty string for no node or more than
    :data:`MAX_SVG_NODES`."""
    if not nodes or len(nodes) > MAX_SVG_NODES:
        return ""
    children: dict[int, list[int]] = {n["id"]: [] for n in nodes}
    depth: dict[int, int] = {}
    for n in nodes:
        if n["parent"] is not None and n["parent"] in children:
            children[n["parent"]].append(n["id"])
        depth[n["id"]] = 0 if n["parent"] is None else depth.get(n["parent"], -1) + 1
    x: dict[int, float] = {}
    column = 0
    # leaves in depth-first order take columns; parents are placed after their children
    for n in nodes:
        if not children[n["id"]]:
            x[n["id"]] = column
            column += 1
    for n in reversed(nodes):
        kids = children[n["id"]]
        if kids:
            x[n["id"]] = (x[kids[0]] + x[kids[-1]]) / 2
    levels = max(depth.values()) + 1
    # Wide, shallow trees (a sequence of many leaves, as most skills are) read better left to
    # right: depth along x, leaves down the page, so the graph fits the panel's width.
    lr = column > 6
    if lr:
        width = int(levels * (_W + 30) + 2 * _PAD)
        height = int(max(1, column) * (_H + 8) + 2 * _PAD)
    else:
        width = int(max(1, column) * _DX + 2 * _PAD)
        height = int(levels * _DY + 2 * _PAD)
    out = [(f'<svg xmlns="http://www.w3.org/2000/svg" class="bt-graph" width="{width}" height="{height}" '
            f'viewBox="0 0 {width} {height}" role="img" aria-label="behaviour tree">')]
    if lr:
        cx = {i: _PAD + depth[i] * (_W + 30) + _W / 2 for i in depth}
        cy = {i: _PAD + x[i] * (_H + 8) + _H / 2 for i in x}
    else:
        cx = {i: _PAD + x[i] * _DX + _DX / 2 for i in x}
        cy = {i: _PAD + depth[i] * _DY + _H / 2 for i in depth}
    for n in nodes:
        p, c = n["parent"], n["id"]
        if p is None or p not in cx:
            continue
        if lr:
            out.append(f'<line class="bt-edge" x1="{cx[p] + _W / 2:.1f}" y1="{cy[p]:.1f}" x2="{cx[c] - _W / 2:.1f}" '
                       f'y2="{cy[c]:.1f}"/>')
        else:
            out.append(f'<line class="bt-edge" x1="{cx[p]:.1f}" y1="{cy[p] + _H / 2:.1f}" x2="{cx[c]:.1f}" '
                       f'y2="{cy[c] - _H / 2:.1f}"/>')
    for n in nodes:
        i, status = n["id"], html.escape(str(n["status"]))
        active = " active-leaf" if n.get("kind") == "leaf" and n["status"] == "running" else ""
        title = html.escape(f'{n["name"]} ({n["type"]}, {n.get("kind", "")}): {n["status"]}'
                            + (f' · {n["message"]}' if n.get("message") else ""))
        shape = 'rx="12"' if n.get("kind") == "composite" else ('rx="3"' if n.get("kind") == "leaf" else 'rx="7"')
        out.append(f'<g class="btn bt-{status}{active}" data-i="{i}" data-kind="{html.escape(str(n.get("kind", "")))}">'
                   f'<title>{title}</title>'
                   f'<rect x="{cx[i] - _W / 2:.1f}" y="{cy[i] - _H / 2:.1f}" width="{_W}" height="{_H}" {shape}/>'
                   f'<text class="bt-mark" x="{cx[i] - _W / 2 + 4:.1f}" y="{cy[i] + 4:.1f}">▶</text>'
                   f'<text x="{cx[i] + 5:.1f}" y="{cy[i] + 4:.1f}" text-anchor="middle">{html.escape(_short(n["name"]))}</text></g>')
    out.append("</svg>")
    return "".join(out)
