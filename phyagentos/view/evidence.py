"""Reading a session's evidence files for the view (read only, bounded).

Both the timeline (:mod:`phyagentos.view.signals`) and the 3D scene
(:mod:`phyagentos.view.scene3d`) read the same two files of ``evidence/<session>/``, so
they read them here and neither imports the other:

- ``trace.jsonl`` (:func:`read_trace`): one JSON object per line, written by the runner;
  read up to :data:`MAX_TRACE_BYTES`;
- ``frames.npz`` (:func:`frames_of`): the recording's state per frame (``--record``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["MAX_TRACE_BYTES", "frames_of", "read_trace"]

#: Bytes of trace.jsonl read (the rest is left out, and said so).
MAX_TRACE_BYTES = 32 * 1024 * 1024


def read_trace(path: Path) -> tuple[list[dict[str, Any]], bool]:
    """The records of a ``trace.jsonl`` and whether the file was cut.

    Reads at most :data:`MAX_TRACE_BYTES` bytes; lines that are not a JSON object (a line
    cut by the limit, or garbage) are skipped.

    Returns:
        ``(records, cut)``: the JSON objects in file order, and True when the file is
        longer than the limit. ``([], False)`` when the file does not exist.
    """
    out: list[dict[str, Any]] = []
    if not path.is_file():
        return out, False
    with path.open("rb") as fh:
        data = fh.read(MAX_TRACE_BYTES + 1)
    cut = len(data) > MAX_TRACE_BYTES
    for line in data[:MAX_TRACE_BYTES].splitlines():
        try:
            rec = json.loads(line)
        except ValueError:
            continue  # a line cut by the byte limit, or not JSON
        if isinstance(rec, dict):
            out.append(rec)
    return out, cut


def frames_of(directory: Path) -> dict[str, Any] | None:
    """The recording of the session whose evidence is ``directory``, or None without one.

    Returns:
        ``{"t": (N,) s simulated time, "qpos": (N, nq) the model's qpos per frame,
        "camera": name, "fps": frames per simulated second[, "wall": (N,) s since the
        first frame]}`` from ``frames.npz``.
    """
    path = directory / "frames.npz"
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as data:
        out = {"t": data["t"].astype(float), "qpos": data["qpos"], "camera": str(data["camera"]),
               "fps": float(data["fps"])}
        if "wall" in data.files:
            out["wall"] = data["wall"].astype(float)
        return out
