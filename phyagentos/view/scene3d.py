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

from .evidence import frames_of, read_trace

__all__ = ["SceneRenderer", "overlay_markers"]

#: Marker colours (RGBA): perceived objects, grasp targets, place targets, the tool path.
MARKER_RGBA = {"perceived": (0.1, 0.35, 1.0, 0.55), "grasp": (0.1, 0.8, 0.2, 0.8), "place": (1.0, 0.55, 0.0, 0.8),
               "tcp_path": (0.9, 0.1, 0.6, 0.9)}
#: Most path points drawn (the path is thinned evenly beyond).
MAX_PATH_POINTS = 200

logger = logging.getLogger(__name__)

_MAX_MODELS = 4


def overlay_markers(directory: Path) -> list[dict[str, Any]]:
    """Markers from ``trace.jsonl``: ``{"kind", "pos" (3,) m world}`` for perceived object
    positions (``observe``), grasp and place targets (``grasp_pose``, ``place_pose``) and
    the tool centre point's path (``proprio`` ``tcp_position_m``, at most
    :data:`MAX_PATH_POINTS`). Empty when the session has no trace yet."""
    trace, _ = read_trace(directory / "trace.jsonl")
    out: list[dict[str, Any]] = []

    def vec(v: Any) -> list[float] | None:
        return [float(x) for x in v] if isinstance(v, list) and len(v) == 3 and \
            all(isinstance(x, (int, float)) for x in v) else None

    path = []
    for r in trace:
        kind = r.get("kind")
        if kind == "observe" and isinstance(r.get("objects"), dict):
            for name, o in r["objects"].items():
                if isinstance(o, dict) and (p := vec(o.get("position"))):
                    out.append({"kind": "perceived", "pos": p, "label": str(name)})
        elif kind == "grasp_pose" and (p := vec(r.get("grasp"))):
            out.append({"kind": "grasp", "pos": p, "label": str(r.get("object", ""))})
        elif kind == "place_pose" and (p := vec(r.get("place"))):
            out.append({"kind": "place", "pos": p, "label": str(r.get("object", ""))})
        elif kind == "proprio" and (p := vec(r.get("tcp_position_m"))):
            path.append(p)
    if len(path) > MAX_PATH_POINTS:
        path = [path[i] for i in np.linspace(0, len(path) - 1, MAX_PATH_POINTS).round().astype(int)]
    out += [{"kind": "tcp_path", "pos": p, "label": ""} for p in path]
    return out


def _draw_markers(scene: mujoco.MjvScene, markers: list[dict[str, Any]]) -> int:
    """Append ``markers`` to ``scene`` as spheres (the tool path as connected capsules); returns how many fit."""
    drawn = 0
    eye = np.eye(3).flatten()
    prev = None
    for m in markers:
        if scene.ngeom >= scene.maxgeom:
            break
        pos = np.asarray(m["pos"], dtype=np.float64)
        rgba = np.asarray(MARKER_RGBA[m["kind"]], dtype=np.float32)
        g = scene.geoms[scene.ngeom]
        if m["kind"] == "tcp_path":
            if prev is not None:
                mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), eye, rgba)
                mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, 0.003, prev, pos)
                scene.ngeom += 1
                drawn += 1
            prev = pos
            continue
        size = {"perceived": 0.028, "grasp": 0.012, "place": 0.016}[m["kind"]]
        mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_SPHERE, np.array([size, 0, 0]), pos, eye, rgba)
        scene.ngeom += 1
        drawn += 1
    return drawn


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
               distance: float | None, overlays: bool = False) -> tuple[bytes, dict[str, Any]]:
        """PNG of ``session_id``'s scene at recorded ``frame`` (None: the current checkpoint).

        Returns ``(png bytes, info)`` with ``info`` = ``{"source", "t", "overlays"}``.
        With ``overlays``, markers from the session's trace are drawn into the scene (see
        :func:`overlay_markers`); ``info["overlays"]`` counts them. The scene itself is the
        simulator's state, i.e. ground truth; the markers are what the robot perceived and
        planned, so their offset from the objects is the perception error.

        Raises:
            ViewError: nothing to show (no recording and no checkpoint of this session),
                a frame out of range, or a target the view cannot rebuild.
        """
        return self._pool.submit(self._render, session_id, frame, azimuth, elevation, distance,
                                 overlays).result(timeout=60)

    def joint_layout(self, session_id: str) -> dict[str, Any]:
        """``{"arm": [(joint name, qpos index)...], "fingers": [qpos index...]}`` of the session's model.

        Arm joints: hinge joints named ``...joint<digit>`` (at most 7, model order);
        fingers: joints whose name contains ``finger``.

        Raises:
            ViewError: the target cannot be rebuilt.
        """
        return self._pool.submit(self._layout, session_id).result(timeout=60)

    def _layout(self, session_id: str) -> dict[str, Any]:
        try:
            target, _ = self._target(session_id)
        except TargetError as exc:
            raise ViewError(str(exc)) from exc
        m = target.model
        arm, fingers = [], []
        for j in range(m.njnt):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
            adr = int(m.jnt_qposadr[j])
            if "finger" in name:
                fingers.append(adr)
            elif m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and name[-1:].isdigit() and len(arm) < 7:
                arm.append((name.rsplit(":", 1)[-1].replace("panda0_", ""), adr))
        return {"arm": arm, "fingers": fingers}

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

    def _render(self, session_id, frame, azimuth, elevation, distance, overlays=False) -> tuple[bytes, dict[str, Any]]:
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
        info["overlays"] = _draw_markers(self._renderer.scene, overlay_markers(
            self.workspace.root / "evidence" / session_id)) if overlays else 0
        pixels = self._renderer.render()
        buf = io.BytesIO()
        Image.fromarray(pixels).save(buf, format="PNG")
        return buf.getvalue(), info
