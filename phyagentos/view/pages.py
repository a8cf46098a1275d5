"""HTML of the view: page shells and the fragments the page re-fetches on every change.

Each page is a shell whose panels (``<div data-fragment=URL>``) the browser fills and
re-fills from ``/fragment/...`` whenever the server-sent event stream reports that the
workspace changed. Every string from the workspace is escaped.
"""

from __future__ import annotations

import html
import json
import math
from typing import Any, Iterable

from .changes import FINISHED_STATES
from .data import Panel
from .tree_svg import tree_svg

__all__ = ["page", "error_box", "signals_banner", "overview_fragment", "runs_fragment", "run_fragment", "session_fragment",
           "tree_fragment", "memory_fragment"]

_E = html.escape


def page(title: str, body: str, *, token: str, scope: str) -> str:
    """A full page: header, navigation, ``body`` and the script that keeps it live."""
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8">
<meta name="phyagentos-token" content="{_E(token)}">
<meta name="phyagentos-scope" content="{_E(scope)}">
<title>{_E(title)} · PhyAgentOS</title>
<link rel="stylesheet" href="/static/view.css">
</head><body>
<header><a class="brand" href="/">PhyAgentOS</a>
<nav><a href="/">runs</a> <a href="/memory">memory</a></nav>
<span id="live" class="live" title="live updates">●</span>
</header>
<main>{body}</main>
<script src="/static/view.js"></script>
</body></html>"""


def error_box(message: str) -> str:
    return f'<div class="error" role="alert"><b>cannot read:</b> <pre>{_E(message)}</pre></div>'


def _table(headers: Iterable[str], rows: Iterable[Iterable[str]], *, cls: str = "") -> str:
    head = "".join(f"<th>{_E(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _state(state: str | None) -> str:
    s = state or "-"
    return f'<span class="state state-{_E(s)}">{_E(s)}</span>'


def _session_link(sid: str) -> str:
    return f'<a href="/session/{_E(sid)}">{_E(sid)}</a>'


def _file_link(path: str) -> str:
    """A workspace-relative evidence path as a link to the file (served only inside the workspace)."""
    return f'<a href="/files/{_E(path)}">{_E(path)}</a>'


def signal_buttons(*, session_id: str | None = None) -> str:
    if session_id:
        return (f'<div class="signals"><button class="sig" data-kind="cancel" data-session="{_E(session_id)}">'
                f'cancel session</button> <button class="sig estop" data-kind="estop" '
                f'title="halt all motion now and cancel running sessions">E-STOP</button></div>')
    return ('<div class="signals">'
            '<button class="sig" data-kind="pause" title="supervisors claim no new session; sessions already '
            'running continue (use E-STOP to halt motion)">pause dispatch</button> '
            '<button class="sig" data-kind="resume" title="supervisors claim pending sessions again">resume dispatch'
            '</button> '
            '<button class="sig estop" data-kind="estop" id="estop" title="halt all motion now and cancel running '
            'sessions">E-STOP</button> '
            '<button class="sig" data-kind="clear_estop">clear e-stop</button>'
            '<span class="small muted"> · pause dispatch: no new session starts, running ones finish · '
            'E-STOP: the robot stops now</span></div>')


def signals_banner(sig: dict[str, Any]) -> str:
    """The signals in force (``data.signals_in_force``), as the flags every page shows."""
    flags = []
    if sig["estopped"]:
        flags.append(f'<span class="flag estop-on" data-signal="estop">E-STOP engaged: {_E(sig["estop_reason"] or "")}'
                     f' <small>({_E(sig.get("estop_by", ""))}, {_E(sig.get("estop_at", ""))})</small></span>')
    if sig["paused"]:
        flags.append(f'<span class="flag paused" data-signal="paused">dispatch paused: no new session is claimed; '
                     f'running sessions continue <small>({_E(sig.get("pause_by", ""))}, {_E(sig.get("pause_at", ""))})'
                     f'</small></span>')
    head = " ".join(flags) or '<span class="flag ok" data-signal="none">no pause or e-stop in force</span>'
    return f'<div class="signal-state">{head}</div>'


def _held(state: str, held: str | None) -> str:
    """A session's state, or what holds it (``paused``, ``held_by_estop``) when a signal keeps it from starting."""
    if not held:
        return _state(state)
    label = "paused (dispatch)" if held == "paused" else "held by e-stop"
    return f'<span class="state state-{_E(held)}" title="session {_E(state)}; not claimed while {_E(label)}">{label}</span>'


def overview_fragment(p: Panel) -> str:
    if p.error:
        return error_box(p.error)
    d = p.data
    head = signals_banner(d["signals"]).replace('class="signal-state"', 'id="signal-state" class="signal-state"', 1)
    rows = [(_session_link(a["session_id"]), _held(a["state"], a.get("held")), _E(a["node"]), _E(a["skill"]),
             _E(a["target"]), f'<a href="/run/{_E(a["run_id"])}">{_E(a["run_id"])}</a>') for a in d["active"]]
    table = _table(("session", "state", "node", "skill", "target", "run"), rows, cls="active") if rows \
        else "<p class='muted'>no active session</p>"
    return f'{head}<h3>active sessions</h3>{table}'


def runs_fragment(p: Panel) -> str:
    """One page of the run list (``p.data`` from :func:`~phyagentos.view.data.runs_page`) with page links."""
    if p.error:
        return error_box(p.error)
    d = p.data
    if not d["rows"]:
        return "<p class='muted'>no run yet: <code>phyagentos run GRAPH --workspace WS</code></p>"
    rows = []
    for r in d["rows"]:
        outcome = "" if r["succeeded"] is None else ("succeeded" if r["succeeded"] else "failed")
        rows.append((f'<a href="/run/{_E(r["run_id"])}">{_E(r["run_id"])}</a>', _E(r["goal_graph"]),
                     _state(r["state"]) + (" " + _state(outcome) if outcome else ""), _E(r["submitted_at"]),
                     error_box(r["error"]) if r["error"] else ""))
    page, pages = d["page"], d["pages"]
    first = (page - 1) * d["per_page"] + 1
    nav = (f'<p class="pager small" data-page="{page}" data-pages="{pages}">runs {first}-{first + len(rows) - 1} '
           f'of {d["total"]} · page {page} of {pages}'
           + (f' · <a href="/?page={page - 1}" rel="prev">newer</a>' if page > 1 else "")
           + (f' · <a href="/?page={page + 1}" rel="next">older</a>' if page < pages else "") + "</p>")
    return nav + _table(("run", "goal graph", "state", "submitted", ""), rows, cls="runs")


def run_fragment(p: Panel, svg: Panel) -> str:
    if p.error:
        return error_box(p.error)
    g = p.data
    pic = signals_banner(g["signals"]) + (error_box(svg.error) if svg.error else f'<div class="dag">{svg.data}</div>')
    rows = []
    for n in g["nodes"]:
        sessions = " → ".join(_session_link(s["session_id"]) + " " + _state(s["state"]) for s in n["sessions"]) or "-"
        rows.append((_E(n["id"]), _E(n["skill"]), f'<span class="nodestate" data-node="{_E(n["id"])}">'
                     f'{_state(n["state"])}</span>', _E(", ".join(n["depends_on"]) or "-"), sessions))
    legend = " ".join(_state(s) for s in ("waiting", "running", "paused", "succeeded", "failed", "blocked", "cancelled"))
    return (f'{pic}<p class="legend">{legend} · orange arrows: replans · dashed: blocked</p>'
            + _table(("node", "skill", "state", "depends on", "sessions"), rows, cls="nodes"))


def _short(text: str, n: int) -> str:
    return text if len(text) <= n else text[: n - 1] + "…"


def _timeline(transitions: list[dict[str, Any]]) -> str:
    """The statechart path: the first state, then each event (with its time) and the state it led to."""
    if not transitions:
        return "<p class='muted'>no transition yet</p>"
    items = [f"<li>{_state(transitions[0]['source'])}</li>"]
    items += [f'<li><span class="ev" title="{_E(t["event"])}">—{_E(_short(t["event"], 36))} '
              f'<span class="t">{_E(str(t["at"])[11:23])}</span>→</span> {_state(t["dest"])}</li>' for t in transitions]
    return f'<ol class="timeline">{"".join(items)}</ol>'


def _criteria(criteria: list[dict[str, Any]]) -> str:
    rows = [(_E(c["name"]), f"<code>{_E(c['predicate'])}</code>", _state(c["status"]), _E(c["reason"]),
             "<br>".join(_file_link(e) for e in c.get("evidence", []))) for c in criteria]
    return _table(("criterion", "predicate", "status", "reason", "evidence"), rows, cls="criteria")


def _kv(d: dict[str, Any] | None) -> str:
    if not d:
        return "-"
    return "<br>".join(f"<code>{_E(str(k))}</code>: {_E(struct_text(v, limit=160))}" for k, v in d.items())


def _attempts(attempts: list[dict[str, Any]]) -> str:
    out = []
    for a in attempts:
        err = f"<br><b>error</b> <code>{_E(a['error']['code'])}</code> {_E(a['error']['message'][:400])}" \
            if a.get("error") else ""
        v = a.get("verdict")
        verdict = ""
        if v:
            verdict = (f"<h4>verdict {_state(v['verdict'])} <small>({_E(v['verifier'])})</small></h4>"
                       f"<p>{_E(v['reason'])}</p>" + _criteria(v.get("criteria", [])))
            if v.get("diagnosis"):
                dg = v["diagnosis"]
                verdict += (f"<h4>diagnosis <code>{_E(dg['cause'])}</code> ({_E(dg['category'])})</h4>"
                            f"<p>{_E(dg['summary'])}</p><p class='small'>{_kv(dg.get('facts'))}</p>")
            if v.get("revision"):
                rv = v["revision"]
                verdict += (f"<h4>revision <code>{_E(rv['strategy'])}</code> (step {rv['step']})</h4>"
                            f"<p>{_E(rv.get('rationale', ''))}</p><p class='small'>{_kv(rv.get('parameters'))}</p>")
        out.append(f'<div class="attempt"><h3>attempt {a["number"]}: {_state(a.get("outcome") or "running")}</h3>'
                   f'<p class="small">{_E(str(a["started_at"]))} → {_E(str(a.get("ended_at") or "…"))} · runner '
                   f'{_E(a.get("runner") or "-")}</p>{err}{verdict}</div>')
    return "".join(out) or "<p class='muted'>no attempt yet</p>"


def _events(p: Panel) -> str:
    if p.error:
        return error_box(p.error)
    events = p.data or []
    if not events:
        return "<p class='muted'>no safety or target event</p>"
    rows = [(f"<code>{_E(str(e.get('code', '?')))}</code>", _E(str(e.get("message", ""))[:300]),
             _E(", ".join(f"{k}={v}" for k, v in e.items() if k not in ("code", "message"))[:200]))
            for e in events if isinstance(e, dict)]
    return _table(("code", "message", "details"), rows, cls="events")


def _perception(p: Panel) -> str:
    if p.error:
        return error_box(p.error)
    d = p.data
    if not d["entities"]:
        return "<p class='muted'>no perception snapshot</p>"
    rows = []
    for e in d["entities"]:
        attrs = e.get("attributes") or {}
        conf = attrs.get("confidence", e.get("confidence"))
        pos = e.get("position") or []
        rows.append((_E(str(e.get("name"))), _E(str(e.get("kind", ""))),
                     _E(", ".join(f"{x:.3f}" for x in pos if isinstance(x, (int, float)))),
                     _E(f"{conf:.2f}" if isinstance(conf, (int, float)) else "-"),
                     _E(", ".join(f"{k}={v}" for k, v in attrs.items() if k != "confidence")[:160])))
    sim = d.get("sim_time_s")
    sim_text = f"{sim:.2f}" if isinstance(sim, (int, float)) else "-"
    return (f"<p class='small'>from <code>{_E(d['source'])}</code>, sim time {sim_text} s</p>"
            + _table(("entity", "kind", "position (m, world)", "confidence", "attributes"), rows, cls="entities"))


def session_fragment(p: Panel) -> str:
    if p.error:
        return error_box(p.error)
    d = p.data
    r = d["record"]
    files_url = f"/files/{d['evidence_dir']}"
    res = r.get("result") or {}
    finished = "true" if r["state"] in FINISHED_STATES else "false"
    head = (signals_banner(d["signals"])
            + f'<p><span id="session-state" class="session-state" data-state="{_E(r["state"])}" data-finished="{finished}" '
            f'data-held="{_E(d.get("held") or "")}">{_held(r["state"], d.get("held"))}</span> '
            f'node <b>{_E(r["node"])}</b> · skill <b>{_E(r["skill"])}</b> ({_E(r["skill_runtime"])}) · target '
            f'<b>{_E(r["target"])}</b> · run <a href="/run/{_E(r["run_id"])}">{_E(r["run_id"])}</a>'
            + (f" · parent {_session_link(r['parent_session_id'])} (<a class='compare-link' href='/compare?a="
               f"{_E(r['parent_session_id'])}&amp;b={_E(r['session_id'])}'>compare</a>)" if r.get("parent_session_id") else "")
            + "".join(f" · child {_session_link(c)} (<a class='compare-link' href='/compare?a={_E(r['session_id'])}"
                      f"&amp;b={_E(c)}'>compare</a>)" for c in r.get("child_session_ids", [])) + "</p>")
    if res:
        err = res.get("error") or {}
        head += (f"<p>result {_state(res.get('status'))} {_E(res.get('reason', ''))}"
                 + (f" <code>{_E(err.get('code', ''))}</code>" if err else "") + "</p>")
    if r.get("recovery"):
        head += f"<p>replanned with <code>{_E(r['recovery']['strategy'])}</code>: {_kv(r['recovery'].get('parameters'))}</p>"
    images = "".join(f'<figure><img src="{files_url}/{_E(f)}" alt="{_E(f)}"><figcaption>{_E(f)}</figcaption></figure>'
                     for f in d["files"] if f.endswith(".png"))
    video = (f'<video controls muted src="{files_url}/video.mp4" width="320"></video>'
             if "video.mp4" in d["files"] else "<p class='muted'>no recording (run with <code>--record</code>)</p>")
    files = " ".join(f'<a href="{files_url}/{_E(f)}">{_E(f)}</a>' for f in d["files"])
    bundle = d["bundle"]
    bundle_html = error_box(bundle.error) if bundle.error else (
        f"<p class='small'>outcome {_kv((bundle.data or {}).get('outcome'))}</p>" if bundle.data else "")
    return (head + "<h3>statechart transitions</h3>" + _timeline(r.get("transitions", []))
            + "<h3>attempts, verdict, diagnosis, revision</h3>" + _attempts(r.get("attempts", []))
            + "<h3>safety and target events</h3>" + _events(d["events"])
            + "<h3>perception snapshot</h3>" + _perception(d["perception"])
            + f"<h3>evidence</h3><div class='images'>{images or '<p class=muted>no image</p>'}{video}</div>"
            + f"<p class='small'>files: {files or '-'}</p>{bundle_html}")


def timeline_section(session_id: str) -> str:
    """The session's signals on one timeline (filled by view.js from ``/api/signals``): one cursor
    moves the plots, the 3D scene, the camera images, the video, the transitions and the tree."""
    return (f'<section class="timeline" data-session="{_E(session_id)}"><h2>signals on one timeline</h2>'
            '<p class="small tl-head"><span class="tl-info muted">loading…</span> · click or drag on a plot to move '
            'the cursor; the 3D slider, the video and the tree history move it too</p>'
            '<div class="tl-plots"></div><div class="tl-images"></div></section>')


def tree_fragment(p: Panel) -> str:
    """The live behaviour tree (indented by depth) and the blackboard values it uses."""
    if p.error:
        return error_box(p.error)
    t = p.data
    if not t:
        return "<p class='muted'>no tree status yet (published by the runner while the session runs)</p>"
    nodes = t["nodes"]
    depth: dict[int, int] = {}
    rows = []
    for n in nodes:
        depth[n["id"]] = 0 if n["parent"] is None else depth[n["parent"]] + 1
        pad = depth[n["id"]] * 18
        keys = ", ".join(n["reads"] + [k + "←" for k in n["writes"] if k not in n["reads"]])
        rows.append(f'<tr class="bt bt-{_E(n["status"])}" data-status="{_E(n["status"])}">'
                    f'<td style="padding-left:{pad + 4}px"><span class="dot"></span>{_E(n["name"])}</td>'
                    f'<td><code>{_E(n["type"])}</code></td><td>{_state(n["status"])}</td>'
                    f'<td class="small">{_E(keys)}</td><td class="small">{_E(n["message"])}</td></tr>')
    board = "".join(f"<tr><td><code>{_E(k)}</code></td><td class='small'>{_E(struct_text(v, limit=300))}</td></tr>"
                    for k, v in t.get("blackboard", {}).items())
    status = "final" if t.get("final") else "live"
    running = [n["name"] for n in nodes if n.get("kind") == "leaf" and n["status"] == "running"]
    graph = tree_svg(nodes)
    return (f'<p class="small" id="tree-meta" data-tick="{t["tick"]}" data-final="{str(bool(t.get("final"))).lower()}">'
            f'{status} · tick {t["tick"]} · {len(nodes)} nodes'
            + (f' · running leaf: <b class="running-leaf">{_E(", ".join(running))}</b>' if running else "")
            + '<span class="tree-replay"></span></p>'
            + (f'<div class="tree-graph">{graph}</div>' if graph else "")
            + '<details class="tree-table"><summary class="small">as a table (types, blackboard keys, feedback)'
            '</summary>'
            '<table class="tree"><thead><tr><th>node</th><th>type</th><th>status</th><th>blackboard keys</th>'
            f'<th>feedback</th></tr></thead><tbody>{"".join(rows)}</tbody></table></details>'
            f'<h4>blackboard</h4><table class="board"><tbody>{board or "<tr><td>-</td></tr>"}</tbody></table>')


# -- structured, bounded text (memory entries, blackboard values) -------------------------

def _is_pose(v: Any) -> bool:
    """A 4x4 homogeneous transform as nested lists (last row 0 0 0 1)."""
    return (isinstance(v, list) and len(v) == 4 and all(isinstance(r, list) and len(r) == 4 for r in v)
            and all(isinstance(x, (int, float)) for r in v for x in r)
            and all(abs(a - b) < 1e-6 for a, b in zip(v[3], (0, 0, 0, 1))))


def pose_text(m: list[list[float]]) -> str:
    """A 4x4 transform as ``p = (x, y, z) m · rpy = (r, p, y) deg · q = (w, x, y, z)``.

    ``rpy``: roll, pitch, yaw (extrinsic x-y-z, i.e. R = Rz(yaw) Ry(pitch) Rx(roll)), degrees;
    ``q``: unit quaternion, scalar first.
    """
    r = [row[:3] for row in m[:3]]
    pitch = math.asin(max(-1.0, min(1.0, -r[2][0])))
    if abs(r[2][0]) < 0.999999:
        roll, yaw = math.atan2(r[2][1], r[2][2]), math.atan2(r[1][0], r[0][0])
    else:  # gimbal lock: yaw absorbs the roll
        roll, yaw = 0.0, math.atan2(-r[0][1], r[1][1])
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0:
        k = math.sqrt(tr + 1.0) * 2
        q = (0.25 * k, (r[2][1] - r[1][2]) / k, (r[0][2] - r[2][0]) / k, (r[1][0] - r[0][1]) / k)
    elif r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        k = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        q = ((r[2][1] - r[1][2]) / k, 0.25 * k, (r[0][1] + r[1][0]) / k, (r[0][2] + r[2][0]) / k)
    elif r[1][1] > r[2][2]:
        k = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        q = ((r[0][2] - r[2][0]) / k, (r[0][1] + r[1][0]) / k, 0.25 * k, (r[1][2] + r[2][1]) / k)
    else:
        k = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
        q = ((r[1][0] - r[0][1]) / k, (r[0][2] + r[2][0]) / k, (r[1][2] + r[2][1]) / k, 0.25 * k)
    if q[0] < 0:
        q = tuple(-x for x in q)
    p = ", ".join(f"{m[i][3]:.3f}" for i in range(3))
    rpy = ", ".join(f"{math.degrees(a):.1f}" for a in (roll, pitch, yaw))
    return f"p = ({p}) m · rpy = ({rpy})° · q(wxyz) = ({', '.join(f'{x:.3f}' for x in q)})"


def _scalar(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, str):
        return v
    return json.dumps(v, default=str)


def struct_text(v: Any, *, limit: int = 240, depth: int = 0) -> str:
    """``v`` (JSON data) as readable text of at most about ``limit`` characters.

    Mappings become ``key: value`` items, lists of numbers ``[a, b, c]`` (floats to 4
    significant digits), 4x4 transforms :func:`pose_text`; what does not fit is cut at an
    item boundary with a count (``… 3 more``), never in the middle of a token.
    """
    if _is_pose(v):
        return pose_text(v)
    if isinstance(v, dict):
        if not v:
            return "{}"
        parts, used = [], 0
        for i, (k, x) in enumerate(v.items()):
            item = f"{k}: {struct_text(x, limit=max(40, limit // 2), depth=depth + 1)}"
            if parts and used + len(item) > limit:
                parts.append(f"… {len(v) - i} more")
                break
            parts.append(item)
            used += len(item) + 2
        return ("{" + "; ".join(parts) + "}") if depth else "; ".join(parts)
    if isinstance(v, list):
        if not v:
            return "[]"
        parts, used = [], 0
        for i, x in enumerate(v):
            item = struct_text(x, limit=max(40, limit // 2), depth=depth + 1)
            if parts and used + len(item) > limit:
                parts.append(f"… {len(v) - i} more")
                break
            parts.append(item)
            used += len(item) + 2
        return "[" + ", ".join(parts) + "]"
    text = _scalar(v)
    if len(text) > limit:  # one long string: cut at a word boundary
        cut = text[:limit].rsplit(" ", 1)[0] or text[:limit]
        return f"{cut} … ({len(text) - len(cut)} more characters)"
    return text


def _provenance(ids: Iterable[str]) -> str:
    return " ".join(_session_link(i) for i in dict.fromkeys(ids)) or "-"


def memory_fragment(panels: dict[str, Panel]) -> str:
    out = []
    lessons = panels["lessons"]
    out.append("<h2>LESSONS.md</h2>")
    if lessons.error:
        out.append(error_box(lessons.error))
    else:
        for title, key in (("verified lessons", "lessons"), ("candidates", "candidates")):
            rows = [(_E(x["id"]), _E(x["objective"]), f"<code>{_E(x['cause'])}</code>", _E(x["correction"]),
                     f"{x.get('confirmations', 0)} / {x.get('refutations', 0)}", _E(struct_text(x.get("scope", {}), limit=160)),
                     _provenance([*x.get("provenance", []), *x.get("verified_by", [])]))
                    for x in lessons.data.get(key, [])]
            out.append(f"<h3>{title}</h3>" + (_table(("id", "objective", "cause", "correction", "confirmed / refuted",
                                                      "scope", "sessions"), rows, cls="memory")
                                              if rows else "<p class='muted'>none</p>"))
    for title, key, field, cols in (
            ("KNOWLEDGE.md", "knowledge", "entries", ("id", "pattern", "conditions", "success", "parameters", "sessions")),
            ("SKILL.md", "skills", "procedures", ("name", "base skill", "conditions", "success", "parameters", "sessions"))):
        p = panels[key]
        out.append(f"<h2>{title}</h2>")
        if p.error:
            out.append(error_box(p.error))
            continue
        rows = [(_E(x.get("id") or x.get("name")), _E(x.get("pattern") or x.get("base_skill", "")),
                 _E(struct_text(x.get("conditions", {}), limit=200)), f"{x.get('successes', 0)} / {x.get('attempts', 0)}",
                 _E(struct_text(x.get("parameters", {}), limit=200)), _provenance(x.get("provenance", [])))
                for x in p.data.get(field, [])]
        out.append(_table(cols, rows, cls="memory") if rows else "<p class='muted'>none</p>")
    return "".join(out)
