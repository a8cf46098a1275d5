"""A session as a rerun recording (``.rrd``) next to its evidence, for the rerun viewer.

    phyagentos view WORKSPACE --export-rrd SESSION_ID [--rrd-out PATH]

writes ``evidence/<session>/recording.rrd`` (or ``PATH``) from the same evidence the
view's timeline plots (:func:`phyagentos.view.signals.session_signals`), on one timeline
``sim_time`` (simulated seconds):

==========================  ==========================================================
``joints/<name>``           joint position, rad (``Scalars``)
``gripper/opening_mm/...``  finger opening, mm per finger (recorded, sensed)
``gripper/effort_n``        finger effort, N per finger
``wrist/force_n/<axis>``    wrist force fx, fy, fz and the load, N
``tracking/error_mrad``     max tracking error per executed trajectory, mrad
``world/tcp``               the tool centre point, m, world frame (``Points3D``) and its
                            path (``LineStrips3D``, static)
``events``                  slips, safety and target events (``TextLog``, WARN)
``transitions``             the session's statechart transitions (``TextLog``)
``tree``                    each change of the behaviour tree: the running leaves
``camera/<name>``           the evidence images (``EncodedImage``)
==========================  ==========================================================

Why rerun: it is what robotics people open for exactly this (a time-series and 3D
viewer that runs locally, served from the wheel; nothing is fetched at run time); the
view keeps what rerun has no place for (goal graph, verdicts, diagnosis, memory).
``rerun-sdk`` is optional (``pip install 'phyagentos[rerun]'``): without it
:func:`export_rrd` raises :class:`~phyagentos.errors.ViewError` saying so.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from phyagentos.errors import ViewError
from phyagentos.protocol import Workspace

from .evidence import read_trace
from .signals import session_signals

__all__ = ["RRD_FILE", "export_rrd"]

logger = logging.getLogger(__name__)

#: File name of the export inside the session's evidence directory.
RRD_FILE = "recording.rrd"


def _rerun():
    try:
        import rerun as rr  # noqa: PLC0415 - the optional rerun extra
    except ImportError as exc:
        raise ViewError("exporting a .rrd needs rerun-sdk: pip install 'rerun-sdk>=0.41,<0.42' "
                        "(or the 'rerun' extra of phyagentos)") from exc
    return rr


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in text).strip("_") or "x"


def export_rrd(workspace: str | Path, session_id: str, *, out: str | Path | None = None,
               layout: dict[str, Any] | None = None) -> Path:
    """Write ``session_id``'s signals, events, transitions, tree changes and images as a ``.rrd``.

    Args:
        workspace: the workspace root.
        session_id: the session (its evidence directory must exist).
        out: the file to write (default ``evidence/<session>/recording.rrd``).
        layout: joint layout of the session's model (see ``SceneRenderer.joint_layout``);
            None labels the arm joints ``q1..q7``.

    Returns:
        The path written.

    Raises:
        ViewError: rerun-sdk is not installed, or the session has no evidence.
        ProtocolError: unknown session.
    """
    rr = _rerun()
    ws = Workspace.open(workspace)
    record = ws.load_session(session_id).model_dump(mode="json")
    sig = session_signals(ws.root, record, layout=layout)
    directory = ws.root / "evidence" / session_id
    path = Path(out) if out is not None else directory / RRD_FILE
    rec = rr.RecordingStream("phyagentos", recording_id=session_id)
    rec.save(str(path))
    try:
        for plot in sig["plots"]:
            group = {"joint positions": "joints", "gripper opening": "gripper/opening_mm",
                     "finger effort": "gripper", "wrist force": "wrist/force_n",
                     "tracking error": "tracking"}.get(plot["name"], _slug(plot["name"]))
            for line in plot["lines"]:
                name = {"effort": "effort_n", "max |q_ref - q|": "error_mrad"}.get(line["label"], _slug(line["label"].split(" (")[0]))
                entity = f"{group}/{name}"
                for t, y in zip(line["t"], line["y"]):
                    if y is None:
                        continue
                    rec.set_time("sim_time", duration=float(t))
                    rec.log(entity, rr.Scalars(float(y)))
        trace, _ = read_trace(directory / "trace.jsonl")
        tcp = [(float(r["stamp_s"]), r["tcp_position_m"]) for r in trace
               if r.get("kind") == "proprio" and isinstance(r.get("stamp_s"), (int, float))
               and isinstance(r.get("tcp_position_m"), list) and len(r["tcp_position_m"]) == 3]
        for t, p in tcp:
            rec.set_time("sim_time", duration=t)
            rec.log("world/tcp", rr.Points3D([p], radii=0.006))
        if len(tcp) > 1:
            rec.log("world/tcp_path", rr.LineStrips3D([[p for _, p in tcp]]), static=True)
        for e in sig["events"]:
            rec.set_time("sim_time", duration=float(e["t"]))
            rec.log("events", rr.TextLog(f"{e['code']}: {e['message']}", level="WARN"))
        for x in sig["transitions"]:
            rec.set_time("sim_time", duration=float(x["t"]))
            rec.log("transitions", rr.TextLog(f"→ {x['dest']} ({x['event'][:120]})", level="INFO"))
        hist_path = directory / "tree_history.json"
        if hist_path.is_file():
            hist = json.loads(hist_path.read_text(encoding="utf-8"))
            nodes = hist.get("nodes", [])
            for tick, t, codes in hist.get("entries", []):
                if t is None:
                    continue
                running = [n["name"] for n, c in zip(nodes, codes) if c == "R" and n.get("kind") == "leaf"]
                rec.set_time("sim_time", duration=float(t))
                rec.log("tree", rr.TextLog(f"tick {tick}: running {', '.join(running) or '-'}", level="DEBUG"))
        for im in sig["images"]:
            cam = im["name"].removesuffix(".png").split("_")[-1]
            rec.set_time("sim_time", duration=float(im["t"]))
            rec.log(f"camera/{_slug(cam)}", rr.EncodedImage(path=directory / "frames" / im["name"]))
    finally:
        rec.disconnect()
    logger.info("wrote %s", path)
    return path
