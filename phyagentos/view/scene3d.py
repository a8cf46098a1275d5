"""The robot in 3D: a session's MuJoCo scene re-rendered at a recorded or current state.

The view rebuilds the session's target model exactly as the runner did (the target's
driver with the session's scene, :func:`phyagentos.runtime.target_pool.scene_for`), puts
a private ``MjData`` into the state of one instant and renders it with MuJoCo's own
renderer from a free camera the browser orbits (azimuth, elevation, distance). The
instant is either a recorded frame (``evidence/<session>/frames.npz``, written under
``--record``: simulated time and ``qpos`` per frame) or the target's latest checkpoint
(``targets/<name>/state.npz``, written every 0.25 s while a session runs) when that
checkpoint belongs to this session. Nothing is written: checkpoints are only read.

OpenGL contexts belong to the thread that made them, so every render runs on one
dedicated thread; models are cached per session (a handful at most).
"""

from __future__ import annotations

import io
import logging
import threading
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from phyagentos.errors import TargetError, ViewError
from phyagentos.protocol import Workspace
from phyagentos.runtime.target_pool import scene_for
from phyagentos.targets.registry import DRIVERS
from phyagentos.yamlsource import read_yaml

__all__ = ["SceneRenderer", "frames_of"]

logger = logging.getLogger(__name__)

_MAX_MODELS = 4


def frames_of(directory: Path) -> dict[str, Any] | None:
    """``{"t": [...], "qpos": (N, nq) array, "camera", "fps"}`` from ``frames.npz``, or None."""
    path = directory / "frames.npz"
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as data:
        return {"t": data["t"].astype(float), "qpos": data["qpos"], "camera": str(data["camera"]),
                "fps": float(data["fps"])}


class SceneRenderer:
    """Renders sessions' scenes on one thread; see the module docstring.

    Args:
        workspace: the workspace (read only).
        width, height: image size in pixels.
    """

    def __init__(self, workspace: Workspace, *, width: int = 480, height: int = 360) -> None:
        self.workspace = workspace
        self.width, self.height = width, height
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="view-render")
        self._models: OrderedDict[str, tuple[Any, mujoco.MjData]] = OrderedDict()
        self._renderer: mujoco.Renderer | None = None
        self._renderer_model: Any = None
        self._lock = threading.Lock()

    def close(self) -> None:
        self._pool.submit(self._close_all).result()
        self._pool.shutdown(wait=True)

    def _close_all(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        for target, _ in self._models.values():
            target.close()
        self._models.clear()

    def render(self, session_id: str, *, frame: int | None, azimuth: float, elevation: float,
               distance: float | None) -> tuple[bytes, dict[str, Any]]:
        """PNG of ``session_id``'s scene at recorded ``frame`` (None: the current checkpoint).

        Returns ``(png bytes, info)`` with ``info`` = ``{"source", "t"}``.

        Raises:
            ViewError: nothing to show (no recording and no checkpoint of this session),
                a frame out of range, or a target the view cannot rebuild.
        """
        return self._pool.submit(self._render, session_id, frame, azimuth, elevation, distance).result(timeout=60)

    def _target(self, session_id: str):
        if session_id in self._models:
            self._models.move_to_end(session_id)
            return self._models[session_id]
        rec = self.workspace.load_session(session_id)
        spec = next((t for t in self.workspace.read("TARGETS").data.targets if t.name == rec.target), None)
        if spec is None or spec.driver not in DRIVERS:
            raise ViewError(f"session {session_id}: target {rec.target!r} is not one the view can rebuild")
        target = DRIVERS[spec.driver](spec.name, scene_for(rec, spec, root=self.workspace.root), seed=rec.seed)
        model = getattr(target, "model", None)
        if not isinstance(model, mujoco.MjModel):
            target.close()
            raise ViewError(f"session {session_id}: target {rec.target!r} exposes no MuJoCo model")
        entry = (target, mujoco.MjData(model))
        self._models[session_id] = entry
        while len(self._models) > _MAX_MODELS:
            _, (old, _) = self._models.popitem(last=False)
            old.close()
        return entry

    def _state(self, session_id: str, target, data: mujoco.MjData, frame: int | None) -> dict[str, Any]:
        model = target.model
        if frame is not None:
            frames = frames_of(self.workspace.root / "evidence" / session_id)
            if frames is None or not len(frames["t"]):
                raise ViewError(f"session {session_id} has no recording (run with --record)")
            if not 0 <= frame < len(frames["t"]) or frames["qpos"].shape[1:] != (model.nq,):
                raise ViewError(f"frame {frame} out of range 0..{len(frames['t']) - 1} (or qpos of another model)")
            data.qpos[:] = frames["qpos"][frame]
            mujoco.mj_forward(model, data)
            return {"source": "recording", "t": float(frames["t"][frame])}
        rec = self.workspace.load_session(session_id)
        meta_path = self.workspace.root / "targets" / rec.target / "state.yaml"
        meta = read_yaml(meta_path, error=ViewError) if meta_path.is_file() else None
        if not meta or meta.get("session_id") != session_id:
            raise ViewError(f"session {session_id}: no current state (the target's checkpoint belongs to another "
                            "session) and no recording")
        try:
            target.load_state(self.workspace.root / "targets" / rec.target / "state.npz")
        except (TargetError, OSError, KeyError, ValueError) as exc:
            raise ViewError(f"session {session_id}: checkpoint unreadable: {exc}") from exc
        data.qpos[:] = target.data.qpos
        mujoco.mj_forward(model, data)
        return {"source": "checkpoint", "t": float(target.data.time)}

    def _render(self, session_id, frame, azimuth, elevation, distance) -> tuple[bytes, dict[str, Any]]:
        from PIL import Image  # noqa: PLC0415

        try:
            target, data = self._target(session_id)
            info = self._state(session_id, target, data, frame)
        except TargetError as exc:
            raise ViewError(str(exc)) from exc
        model = target.model
        if self._renderer is None or self._renderer_model is not model:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = mujoco.Renderer(model, height=self.height, width=self.width)
            self._renderer_model = model
        cam = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(model, cam)
        cam.lookat[:] = (0.45, 0.0, 0.25)
        cam.azimuth = float(azimuth)
        cam.elevation = float(np.clip(elevation, -89.0, 89.0))
        cam.distance = float(distance) if distance else 1.9
        self._renderer.update_scene(data, camera=cam)
        self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        pixels = self._renderer.render()
        buf = io.BytesIO()
        Image.fromarray(pixels).save(buf, format="PNG")
        return buf.getvalue(), info
