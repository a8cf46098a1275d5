"""A session's signals on one simulated-time axis, from its evidence bundle (read only).

Sources, all written by the runner (``phyagentos/runtime``):

- ``frames.npz`` (``--record``): simulated time ``t`` (N,) s and ``qpos`` (N, nq) per
  recorded frame: the arm's joint positions (rad) and the finger opening (m per finger);
- ``trace.jsonl``: ``proprio`` entries (``stamp_s`` simulated time; ``opening_m``,
  ``effort_n`` N per finger, ``wrist_force_n`` (3,) N and ``wrist_load_n`` N),
  ``execute_start``/``execute_end`` (``max_tracking_error_rad`` per executed trajectory;
  their simulated time is interpolated from the ``proprio`` entries' wall and simulated
  times), ``slip`` and ``observe`` (``stamp_s``);
- ``events.yaml``: safety and target events (``code``, ``message``; simulated time when
  the event carries one, else the end of the session);
- the session's statechart transitions (wall-clock): placed at the first frame up to
  ``running``, inside the run by the recording's wall clock, after it at the last frame;
- ``frames/*.png``: camera images (initial, per observing leaf, terminal) with their time.

Every series is decimated to at most :data:`MAX_POINTS` points and the trace is read up
to :data:`MAX_TRACE_BYTES`, so a long session never produces an unbounded response.
"""

from __future__ import annotations

import bisect
import logging
import re
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from phyagentos.errors import ViewError
from phyagentos.untrusted import confined
from phyagentos.yamlsource import read_yaml

from .evidence import MAX_TRACE_BYTES, frames_of, read_trace
from .security import evidence_dir

__all__ = ["MAX_POINTS", "MAX_TRACE_BYTES", "session_signals"]

logger = logging.getLogger(__name__)

#: Points kept per plotted line (evenly decimated beyond).
MAX_POINTS = 2000
_IMAGE = re.compile(r"^(initial|terminal|\d+)_(.+)\.png$")


def _decimate(t: list[float], y: list[float | None]) -> tuple[list[float], list[float | None]]:
    if len(t) <= MAX_POINTS:
        return t, y
    idx = np.linspace(0, len(t) - 1, MAX_POINTS).round().astype(int)
    return [t[i] for i in idx], [y[i] for i in idx]


def _line(label: str, t: list[float], y: list[Any], *, step: bool = False) -> dict[str, Any]:
    t, y = _decimate([round(float(x), 4) for x in t],
                     [None if v is None else round(float(v), 5) for v in y])
    return {"label": label, "t": t, "y": y, "step": step}


def _ts(text: str) -> float:
    return datetime.fromisoformat(str(text).replace("Z", "+00:00")).timestamp()


def session_signals(root: Path, record: dict[str, Any], *, layout: dict[str, Any] | None) -> dict[str, Any]:
    """The plots of one session (see the module docstring).

    Args:
        root: the workspace root.
        record: the session record as JSON data (``SessionRecord.model_dump(mode="json")``).
        layout: ``{"arm": [(name, qpos index)...], "fingers": [qpos index...]}`` of the
            session's model (:meth:`SceneRenderer.joint_layout`), or None when unknown.

    Returns:
        ``{"t0", "t1", "frames": [t...], "plots": [{name, unit, lines: [{label, t, y, step}]}],
        "events": [{t, code, message}], "transitions": [{t, dest, event}], "images":
        [{t, name, url}], "notes": [...]}``; times are simulated seconds.

    Raises:
        ViewError: the session has no evidence directory.
    """
    sid = record["session_id"]
    directory = evidence_dir(root, sid)  # ViewError: a link out of the workspace
    if not directory.is_dir():
        raise ViewError(f"session {sid} has no evidence directory yet")
    notes: list[str] = []
    try:
        frames = frames_of(directory, root=root)
    except (OSError, ValueError) as exc:
        frames = None
        notes.append(f"frames.npz not read: {exc}")
    trace, cut = read_trace(directory / "trace.jsonl", root=root)
    if cut:
        notes.append(f"trace.jsonl read up to {MAX_TRACE_BYTES // (1024 * 1024)} MiB")
    proprio = [r for r in trace if r.get("kind") == "proprio" and isinstance(r.get("stamp_s"), (int, float))]
    ft = [float(x) for x in frames["t"]] if frames is not None else []
    times = ft + [float(r["stamp_s"]) for r in proprio]
    t0, t1 = (min(times), max(times)) if times else (0.0, 0.0)
    plots: list[dict[str, Any]] = []

    # joint positions and finger opening from the recording
    if frames is not None and len(ft) and frames["qpos"].ndim == 2 and frames["qpos"].shape[1]:
        q = frames["qpos"]
        arm = (layout or {}).get("arm") or [(f"q{i + 1}", i) for i in range(min(7, q.shape[1]))]
        plots.append({"name": "joint positions", "unit": "rad",
                      "lines": [_line(name, ft, q[:, i].tolist()) for name, i in arm if i < q.shape[1]]})
        fingers = [i for i in (layout or {}).get("fingers", []) if i < q.shape[1]]
        opening_lines = [_line("recorded (mean of fingers)", ft, (q[:, fingers].mean(axis=1) * 1000).tolist())] \
            if fingers else []
    else:
        notes.append("no recording (frames.npz): joint positions need --record")
        opening_lines = []
    pt = [float(r["stamp_s"]) for r in proprio]
    if proprio:
        opening_lines.append(_line("sensed (proprio)", pt, [r.get("opening_m", 0) * 1000 for r in proprio]))
    if opening_lines:
        plots.append({"name": "gripper opening", "unit": "mm per finger", "lines": opening_lines})
    if proprio:
        plots.append({"name": "finger effort", "unit": "N per finger",
                      "lines": [_line("effort", pt, [r.get("effort_n") for r in proprio])]})
        wf = [r.get("wrist_force_n") if isinstance(r.get("wrist_force_n"), list) else [None] * 3 for r in proprio]
        plots.append({"name": "wrist force", "unit": "N", "lines": [
            *[_line(f"f{axis}", pt, [w[k] if len(w) > k else None for w in wf]) for k, axis in enumerate("xyz")],
            _line("load", pt, [r.get("wrist_load_n") for r in proprio])]})

    # tracking error per executed trajectory, at simulated times interpolated from proprio entries
    wall = [float(r["t_wall_s"]) for r in proprio if isinstance(r.get("t_wall_s"), (int, float))]
    sim = [float(r["stamp_s"]) for r in proprio if isinstance(r.get("t_wall_s"), (int, float))]

    def at_sim(w: float) -> float:
        if len(wall) < 2:
            return t0
        return float(np.interp(w, wall, sim))

    te_t, te_y, start = [], [], None
    for r in trace:
        if r.get("kind") == "execute_start":
            start = at_sim(float(r.get("t_wall_s", 0.0)))
        elif r.get("kind") == "execute_end" and isinstance(r.get("max_tracking_error_rad"), (int, float)):
            end = at_sim(float(r.get("t_wall_s", 0.0)))
            err = float(r["max_tracking_error_rad"]) * 1000
            te_t += [start if start is not None else end, end]
            te_y += [err, err]
            start = None
    if te_t:
        plots.append({"name": "tracking error", "unit": "mrad (max per executed trajectory)",
                      "lines": [_line("max |q_ref - q|", te_t, te_y, step=True)]})

    # safety and target events, slips and observations
    events: list[dict[str, Any]] = []
    for r in trace:
        if r.get("kind") == "slip" and isinstance(r.get("stamp_s"), (int, float)):
            events.append({"t": float(r["stamp_s"]), "code": "grasp.slip",
                           "message": f"{r.get('object')} slipped ({r.get('leaf')})"})
    try:
        raw = read_yaml(directory / "events.yaml", error=ViewError, root=root) \
            if (directory / "events.yaml").is_file() else []
    except (ViewError, OSError) as exc:
        raw, _ = [], notes.append(str(exc))
    for e in raw if isinstance(raw, list) else []:
        if not isinstance(e, dict):
            continue
        when = next((e[k] for k in ("sim_time_s", "stamp_s", "t_s", "t") if isinstance(e.get(k), (int, float))), t1)
        events.append({"t": float(when), "code": str(e.get("code", "?")), "message": str(e.get("message", ""))[:200]})
    events.sort(key=lambda e: e["t"])

    # statechart transitions on the simulated axis
    transitions = []
    trs = record.get("transitions") or []
    run_at = next((_ts(x["at"]) for x in trs if x.get("dest") == "running"), None)
    end_at = next((_ts(x["at"]) for x in trs if x.get("source") == "running"), None)
    fw = [float(x) for x in frames["wall"]] if frames is not None and "wall" in frames else []
    for x in trs:
        at = _ts(x["at"])
        if run_at is None or at <= run_at:
            t = t0
        elif end_at is not None and at >= end_at:
            t = t1
        elif fw and len(fw) == len(ft):
            t = float(np.interp(at - run_at, fw, ft))
        else:
            t = t0
        transitions.append({"t": round(t, 4), "dest": x.get("dest"), "event": x.get("event", "")})

    # camera images: initial, one per observing leaf (in trace order), terminal
    images = []
    observe_t = [float(r["stamp_s"]) for r in trace if r.get("kind") == "observe" and isinstance(r.get("stamp_s"),
                                                                                                   (int, float))]
    fdir = directory / "frames"
    if fdir.is_dir():
        for p in sorted(fdir.iterdir()):
            m = _IMAGE.match(p.name)
            if not m or not p.is_file() or not _inside(root, p):
                continue
            kind = m[1]
            if kind == "initial":
                t = t0
            elif kind == "terminal":
                t = t1
            else:
                n = int(kind) - 1
                t = observe_t[n] if 0 <= n < len(observe_t) else t0
            images.append({"t": round(t, 4), "name": p.name, "url": f"/files/evidence/{sid}/frames/{p.name}"})
    images.sort(key=lambda i: (i["t"], i["name"]))
    return {"t0": t0, "t1": t1, "frames": [round(x, 4) for x in ft], "plots": plots, "events": events,
            "transitions": transitions, "images": images, "notes": notes}


def _inside(root: Path, path: Path) -> bool:
    try:
        confined(root, path)
        return True
    except OSError:
        return False


def nearest_frame(frames: list[float], t: float) -> int:
    """Index of the recorded frame nearest to simulated time ``t`` (frames sorted)."""
    i = bisect.bisect_left(frames, t)
    if i <= 0:
        return 0
    if i >= len(frames):
        return len(frames) - 1
    return i if frames[i] - t < t - frames[i - 1] else i - 1
