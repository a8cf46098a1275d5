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
import logging
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from phyagentos.untrusted import json_depth, open_regular

__all__ = ["MAX_TRACE_BYTES", "MAX_FRAMES_BYTES", "frames_of", "read_trace"]

logger = logging.getLogger(__name__)

#: Bytes of trace.jsonl read (the rest is left out, and said so).
MAX_TRACE_BYTES = 32 * 1024 * 1024


def read_trace(path: Path, *, root: Path | None = None) -> tuple[list[dict[str, Any]], bool]:
    """The records of a ``trace.jsonl`` and whether the file was cut.

    Reads at most :data:`MAX_TRACE_BYTES` bytes; lines that are not a JSON object (a line
    cut by the limit, garbage, or nested deeper than 200 levels) are skipped. With
    ``root``, only a file resolving inside it (links followed) is read; a FIFO or a
    device reads as empty, never blocks (:mod:`phyagentos.untrusted`).

    Returns:
        ``(records, cut)``: the JSON objects in file order, and True when the file is
        longer than the limit. ``([], False)`` when the file does not exist or is refused.
    """
    out: list[dict[str, Any]] = []
    try:
        fd = open_regular(path, root=root)
    except FileNotFoundError:
        return out, False
    except OSError as exc:
        logger.info("trace not read: %s", exc)
        return out, False
    with os.fdopen(fd, "rb") as fh:
        data = fh.read(MAX_TRACE_BYTES + 1)
    cut = len(data) > MAX_TRACE_BYTES
    for line in data[:MAX_TRACE_BYTES].splitlines():
        try:
            rec = json.loads(line) if len(line) < 4096 or json_depth(line.decode("utf-8", "replace")) <= 200 else None
        except (ValueError, RecursionError):
            continue  # a line cut by the byte limit, or not JSON
        if isinstance(rec, dict):
            out.append(rec)
    return out, cut


#: Largest uncompressed ``frames.npz`` the view loads (bytes): an hour of a 16-DoF recording
#: at 30 fps is about 14 MB; a zip bomb declaring gigabytes is refused before it inflates.
MAX_FRAMES_BYTES = 256 * 1024 * 1024


def frames_of(directory: Path, *, root: Path | None = None) -> dict[str, Any] | None:
    """The recording of the session whose evidence is ``directory``, or None without one.

    With ``root``, the file must resolve inside it (links followed); a FIFO or a device
    is never opened for a blocking read.

    Returns:
        ``{"t": (N,) s simulated time, "qpos": (N, nq) the model's qpos per frame,
        "camera": name, "fps": frames per simulated second[, "wall": (N,) s since the
        first frame]}`` from ``frames.npz``.

    Raises:
        OSError: outside ``root`` or not a regular file (:mod:`phyagentos.untrusted`).
        ValueError: not a recording, or more than :data:`MAX_FRAMES_BYTES` uncompressed.
    """
    path = directory / "frames.npz"
    try:
        fd = open_regular(path, root=root)
    except FileNotFoundError:
        return None
    with os.fdopen(fd, "rb") as fh:
        try:
            with zipfile.ZipFile(fh) as z:
                total = sum(i.file_size for i in z.infolist())
        except zipfile.BadZipFile as exc:
            raise ValueError(f"{path.name} is not a recording (.npz): {exc}") from None
        if total > MAX_FRAMES_BYTES:
            raise ValueError(f"{path.name} holds {total} bytes uncompressed, more than the limit of "
                             f"{MAX_FRAMES_BYTES}")
        fh.seek(0)
        try:
            with np.load(fh, allow_pickle=False) as data:
                out = {"t": data["t"].astype(float), "qpos": data["qpos"], "camera": str(data["camera"]),
                       "fps": float(data["fps"])}
                if "wall" in data.files:
                    out["wall"] = data["wall"].astype(float)
                return out
        except (KeyError, TypeError) as exc:
            raise ValueError(f"frames.npz is not a recording: {exc}") from None
