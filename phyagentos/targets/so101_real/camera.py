"""Physical cameras of the real target, through OpenCV, and what perception can do with them.

A camera sensor in ``sensors.yaml`` with a ``real`` block is a physical camera::

    so101_real:
    - name: front
      kind: rgb_camera            # a webcam: RGB only
      frame_id: front_optical
      rate_hz: 30
      width: 640
      height: 480
      real: {device: 0, fx: 615.0, fy: 615.0, cx: 320.0, cy: 240.0,   # from cv2.calibrateCamera
             position_m: [0.75, 0.0, 0.45], quat_wxyz: [0.0, 0.602, 0.0, -0.799]}

:class:`OpenCVCamera` opens ``device`` with ``cv2.VideoCapture`` (an index, a
``/dev/videoN`` path, or a video/image file), grabs a frame per :meth:`capture`, converts
it to RGB, checks its size against the declared width x height, and returns the
project's :class:`~phyagentos.perception.frames.CameraFrame` with the declared intrinsics
and pose, exactly what perception receives from a simulated camera.

What RGB alone allows: the project's perception (:mod:`phyagentos.perception`) locates
objects from depth (point clouds clustered on the table plane), so an RGB-only camera
gives images for the evidence and the view but no object poses. Criteria judged from
proprioception and the held-object model (``holding``, ``released``, ``still``) remain
checkable; ``lifted``, ``inside``, ``on``, ``unchanged`` and ``articulated`` need
perceived object poses, i.e. depth. :func:`depth_needing_criteria` finds them in a goal
graph so ``phyagentos run`` refuses such a graph on an RGB-only target before anything
moves.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from phyagentos.errors import TargetError
from phyagentos.geometry import quat_to_matrix

__all__ = ["OpenCVCamera", "DEPTH_PREDICATES", "RGB_ONLY_PREDICATES", "depth_needing_criteria", "has_depth"]

log = logging.getLogger(__name__)

#: Acceptance predicates that need perceived object poses (RGB-D perception).
DEPTH_PREDICATES = frozenset({"lifted", "inside", "on", "unchanged", "articulated"})
#: Judged from proprioception / the held-object model / joint states: fine with RGB only.
RGB_ONLY_PREDICATES = frozenset({"holding", "released", "still"})


class OpenCVCamera:
    """One physical camera (a :class:`~phyagentos.protocol.sensors.SensorSpec` with ``real``).

    Raises:
        TargetError: the spec has no ``real`` block, the device does not open, or a frame
            cannot be read or has another size than declared.
    """

    def __init__(self, spec):
        import cv2  # noqa: PLC0415 - cv2 only for a real camera

        if getattr(spec, "real", None) is None:
            raise TargetError(f"sensor {spec.name!r} is not a real camera (no `real:` block in sensors.yaml)")
        self.spec = spec
        r = spec.real
        dev = r.device
        self._cap = cv2.VideoCapture(dev if isinstance(dev, int) else str(Path(dev).expanduser()))
        if not self._cap.isOpened():
            raise TargetError(f"camera {spec.name!r}: cv2.VideoCapture({dev!r}) did not open; check the index "
                              f"(`v4l2-ctl --list-devices`) or the path")
        if isinstance(dev, int):
            self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, int(spec.width))
            self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, int(spec.height))
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(r.quat_wxyz)
        T[:3, 3] = r.position_m
        self.T_world_camera = T
        self.frames = 0

    def capture(self, *, stamp_s: float | None = None):
        """One frame as a :class:`~phyagentos.perception.frames.CameraFrame` (RGB, no depth)."""
        import cv2  # noqa: PLC0415

        from phyagentos.perception.frames import CameraFrame, CameraIntrinsics  # noqa: PLC0415

        ok, bgr = self._cap.read()
        if not ok or bgr is None:
            raise TargetError(f"camera {self.spec.name!r}: no frame from {self.spec.real.device!r}")
        h, w = bgr.shape[:2]
        if (w, h) != (int(self.spec.width), int(self.spec.height)):
            raise TargetError(f"camera {self.spec.name!r}: frames are {w}x{h}, sensors.yaml declares "
                              f"{self.spec.width}x{self.spec.height} (the intrinsics are for that size)")
        r = self.spec.real
        self.frames += 1
        return CameraFrame(sensor=self.spec.name, frame_id=self.spec.frame_id,
                           stamp_s=float(time.monotonic() if stamp_s is None else stamp_s),
                           intrinsics=CameraIntrinsics(w, h, r.fx, r.fy, r.cx, r.cy),
                           T_world_camera=self.T_world_camera.copy(),
                           rgb=np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)), depth_m=None)

    def close(self) -> None:
        self._cap.release()


def has_depth(sensors: Iterable[Any]) -> bool:
    """True if any camera among ``sensors`` gives depth (``rgbd_camera``)."""
    return any(getattr(s, "kind", None) == "rgbd_camera" for s in sensors)


def depth_needing_criteria(graph: dict) -> list[tuple[str, str]]:
    """``(node id, predicate)`` of every acceptance criterion of a goal graph (its raw YAML
    mapping) that needs perceived object poses (:data:`DEPTH_PREDICATES`)."""
    out = []
    for node in graph.get("nodes") or []:
        accept = node.get("accept") or {}
        items = accept.items() if isinstance(accept, dict) else (
            ((a.split("(")[0].strip(), None) if isinstance(a, str) else next(iter(a.items()), (None, None)))
            for a in accept)
        for name, _args in items:
            if name in DEPTH_PREDICATES:
                out.append((str(node.get("id")), str(name)))
    return out
