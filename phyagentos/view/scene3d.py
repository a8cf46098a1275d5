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
import os
import threading
import zipfile
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from phyagentos.errors import PhyAgentOSError, TargetError, ViewError
from phyagentos.protocol import Workspace
from phyagentos.protocol.sensors import read_sensors
from phyagentos.renderer import Renderer
from phyagentos.runtime.target_pool import scene_for
from phyagentos.targets.contract import MuJoCoBacked
from phyagentos.targets.registry import DRIVERS
from phyagentos.untrusted import open_regular
from phyagentos.yamlsource import read_yaml

from .evidence import frames_of, read_trace
from .security import evidence_dir

__all__ = ["SceneRenderer", "overlay_markers", "planned_paths", "plan_segments", "camera_frustums", "cloud_file_at",
           "cloud_markers", "MARKER_RGBA"]

#: Marker colours (RGBA) per overlay kind. Blue: what perception reported (object
#: positions, the object point cloud); green/orange: grasp and place targets; cyan: the
#: planned path; magenta: the executed tool path; yellow: camera frustums.
MARKER_RGBA = {"perceived": (0.1, 0.35, 1.0, 0.55), "cloud": (0.1, 0.35, 1.0, 1.0), "grasp": (0.1, 0.8, 0.2, 0.8),
               "place": (1.0, 0.55, 0.0, 0.8), "planned_path": (0.0, 0.85, 0.85, 0.95),
               "tcp_path": (0.9, 0.1, 0.6, 0.9), "frustum": (1.0, 0.85, 0.0, 0.95)}
#: Most executed-path points drawn (the path is thinned evenly beyond).
MAX_PATH_POINTS = 200
#: Most planned-path points drawn, all plans of a session together.
MAX_PLAN_POINTS = 400
#: Largest joint-space step (rad) between two drawn points of a planned path.
PLAN_STEP_RAD = 0.05
#: Most point-cloud points drawn (an even subset beyond).
MAX_CLOUD_POINTS = 1500
#: Depth at which a camera frustum is drawn (its far rectangle), m.
FRUSTUM_DEPTH_M = 0.15
#: Draw order: when the scene runs out of geoms, the later kinds are the ones left out.
_ORDER = ("perceived", "grasp", "place", "planned_path", "tcp_path", "frustum", "cloud")

logger = logging.getLogger(__name__)

_MAX_MODELS = 4
#: Joint layouts kept (a few hundred bytes each).
_MAX_LAYOUTS = 256


def _vec3(v: Any) -> list[float] | None:
    return [float(x) for x in v] if isinstance(v, list) and len(v) == 3 and \
        all(isinstance(x, (int, float)) for x in v) else None


def overlay_markers(directory: Path, trace: list[dict[str, Any]] | None = None, *,
                    root: Path | None = None) -> list[dict[str, Any]]:
    """Markers from the session's ``trace.jsonl`` (``trace``: its records, when already read;
    else read, with ``root``: only a file resolving inside it).

    Returns:
        Point markers ``{"kind", "pos": (3,) m, "label"}`` (world frame) for perceived
        object positions (``observe``, kind ``perceived``), grasp and place targets
        (``grasp_pose``, ``place_pose``), and the tool centre point's executed path as
        segments ``{"kind": "tcp_path", "line": [(3,), (3,)] m}`` joining the ``proprio``
        entries' ``tcp_position_m`` (at most :data:`MAX_PATH_POINTS` points). Empty when
        the session has no trace yet.
    """
    if trace is None:
        trace, _ = read_trace(directory / "trace.jsonl", root=root)
    out: list[dict[str, Any]] = []
    path = []
    for r in trace:
        kind = r.get("kind")
        if kind == "observe" and isinstance(r.get("objects"), dict):
            for name, o in r["objects"].items():
                if isinstance(o, dict) and (p := _vec3(o.get("position"))):
                    out.append({"kind": "perceived", "pos": p, "label": str(name)})
        elif kind == "grasp_pose" and (p := _vec3(r.get("grasp"))):
            out.append({"kind": "grasp", "pos": p, "label": str(r.get("object", ""))})
        elif kind == "place_pose" and (p := _vec3(r.get("place"))):
            out.append({"kind": "place", "pos": p, "label": str(r.get("object", ""))})
        elif kind == "proprio" and (p := _vec3(r.get("tcp_position_m"))):
            path.append(p)
    if len(path) > MAX_PATH_POINTS:
        path = [path[i] for i in np.linspace(0, len(path) - 1, MAX_PATH_POINTS).round().astype(int)]
    out += [{"kind": "tcp_path", "line": [a, b]} for a, b in zip(path, path[1:])]
    return out


def planned_paths(trace: list[dict[str, Any]], n_joints: int) -> list[np.ndarray]:
    """The joint paths the session planned: each ``plan`` entry's ``path_rad`` as an
    ``(M, n_joints)`` array (rad, the arm's joint order), in trace order; entries without
    a well-formed path (older traces, a failed plan) are skipped."""
    out = []
    for r in trace:
        if r.get("kind") != "plan" or not isinstance(r.get("path_rad"), list):
            continue
        try:
            q = np.asarray(r["path_rad"], dtype=float)
        except (TypeError, ValueError):
            continue
        if q.ndim == 2 and q.shape[0] >= 2 and q.shape[1] == n_joints and np.all(np.isfinite(q)):
            out.append(q)
    return out


def plan_segments(model: mujoco.MjModel, arm_qposadr: list[int], tcp_site: int, paths: list[np.ndarray], *,
                  max_points: int = MAX_PLAN_POINTS) -> list[dict[str, Any]]:
    """The tool centre point along each planned joint path, as ``planned_path`` segments.

    Each path is followed in joint space (straight segments between waypoints, as the
    planner returns them) in steps of at most :data:`PLAN_STEP_RAD`, and the site
    ``tcp_site``'s world position (m) computed by forward kinematics on a scratch
    ``MjData`` (the rendered state is not touched). At most ``max_points`` points in all
    (shared between the paths, each thinned evenly).

    Returns:
        ``[{"kind": "planned_path", "line": [(3,), (3,)] m, "plan": index}]``, world frame.
    """
    if not paths:
        return []
    scratch = mujoco.MjData(model)
    per_path = max(2, max_points // len(paths))
    out: list[dict[str, Any]] = []
    for k, q in enumerate(paths):
        dense = [q[0]]
        for a, b in zip(q[:-1], q[1:]):
            steps = max(1, int(np.ceil(np.max(np.abs(b - a)) / PLAN_STEP_RAD)))
            dense += [a + (b - a) * (i / steps) for i in range(1, steps + 1)]
        if len(dense) > per_path:
            dense = [dense[i] for i in np.linspace(0, len(dense) - 1, per_path).round().astype(int)]
        pts = []
        for qi in dense:
            scratch.qpos[arm_qposadr] = qi
            mujoco.mj_kinematics(model, scratch)
            pts.append(scratch.site_xpos[tcp_site].tolist())
        out += [{"kind": "planned_path", "line": [a, b], "plan": k} for a, b in zip(pts, pts[1:])]
    return out


def camera_frustums(model: mujoco.MjModel, data: mujoco.MjData, sensors, *,
                    depth_m: float = FRUSTUM_DEPTH_M) -> list[dict[str, Any]]:
    """Each camera sensor's viewing frustum as ``frustum`` segments, world frame, m.

    Args:
        model, data: the session's model in the state being shown (``mj_forward`` done).
        sensors: the target's :class:`~phyagentos.protocol.sensors.SensorSpec` list from
            ``sensors.yaml``; cameras only are drawn.
        depth_m: distance of the far rectangle along the optical axis, m.

    The intrinsics are the sensor's: a real camera's calibrated ``fx, fy, cx, cy`` at
    ``width x height`` px, else ``fovy_deg`` with square pixels and the principal point at
    the image centre (``fy = (height / 2) / tan(fovy / 2)``). The pose is a real fixed
    camera's calibrated optical frame (``position_m``, ``quat_wxyz``), else that of the
    model camera rendering the sensor (``mount.camera``) in ``data``: it follows the body
    it is mounted on (a wrist camera moves with the arm). Sensors with neither are skipped.

    Returns:
        8 segments per camera (apex to the 4 corners, the 4 sides of the far rectangle):
        ``{"kind": "frustum", "line": [(3,), (3,)], "camera": sensor name}``.
    """
    out: list[dict[str, Any]] = []
    for s in sensors:
        if s.kind not in ("rgbd_camera", "rgb_camera") or not s.width or not s.height:
            continue
        w, h = float(s.width), float(s.height)
        if s.real is not None:
            x0, x1 = -s.real.cx / s.real.fx, (w - 1 - s.real.cx) / s.real.fx
            y0, y1 = -s.real.cy / s.real.fy, (h - 1 - s.real.cy) / s.real.fy
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, np.asarray(s.real.quat_wxyz, dtype=float))
            origin, r_opt = np.asarray(s.real.position_m, dtype=float), rot.reshape(3, 3)
        else:
            cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, s.camera_name)
            if cam < 0 or s.fovy_deg is None:
                continue
            ty = float(np.tan(np.radians(s.fovy_deg) / 2))
            tx = ty * w / h
            x0, x1, y0, y1 = -tx, tx, -ty, ty
            # MuJoCo cameras look along their -z with +y up: the optical frame (x right,
            # y down, z forward) is R_mj @ diag(1, -1, -1) at the same origin
            origin = np.array(data.cam_xpos[cam])
            r_opt = np.array(data.cam_xmat[cam]).reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
        corners = [origin + r_opt @ (np.array([x, y, 1.0]) * depth_m)
                   for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
        pts = [c.tolist() for c in corners]
        out += [{"kind": "frustum", "line": [origin.tolist(), c], "camera": s.name} for c in pts]
        out += [{"kind": "frustum", "line": [pts[i], pts[(i + 1) % 4]], "camera": s.name} for i in range(4)]
    return out


def cloud_file_at(directory: Path, trace: list[dict[str, Any]], t: float, t_last: float | None) -> Path | None:
    """The perceived point cloud in force at simulated time ``t`` (s), or None.

    Perception writes one ``frames/<tag>_cloud.npz`` per observation
    (:func:`phyagentos.primitives.observation.save_cloud`): ``initial`` before the skill,
    ``NN_<leaf>`` for the skill's NN-th observation (at the ``stamp_s`` of the NN-th
    ``observe`` trace entry), ``terminal`` after it (placed at ``t_last``, the last
    recorded frame's time, when known). Returns the latest at or before ``t``, else the
    earliest.
    """
    fdir = directory / "frames"
    if not fdir.is_dir():
        return None
    observe_t = [float(r["stamp_s"]) for r in trace
                 if r.get("kind") == "observe" and isinstance(r.get("stamp_s"), (int, float))]
    timed = []
    for p in fdir.glob("*_cloud.npz"):
        tag = p.name[: -len("_cloud.npz")]
        head = tag.split("_", 1)[0]
        if tag == "initial":
            when = -np.inf
        elif tag == "terminal":
            when = t_last if t_last is not None else np.inf
        elif head.isdigit() and 0 < int(head) <= len(observe_t):
            when = observe_t[int(head) - 1]
        else:
            continue
        timed.append((when, p.name, p))
    if not timed:
        return None
    timed.sort(key=lambda x: (x[0], x[1]))
    before = [x for x in timed if x[0] <= t + 1e-9]
    return (before[-1] if before else timed[0])[2]


#: Largest saved cloud file read (bytes): perception keeps at most 4,000 points (96 KB).
MAX_CLOUD_BYTES = 8 * 1024 * 1024


def cloud_markers(path: Path, *, max_points: int = MAX_CLOUD_POINTS, root: Path | None = None) -> list[dict[str, Any]]:
    """Points of a saved cloud (``points`` (M, 3) m, world frame) as ``cloud`` markers
    ``{"kind": "cloud", "pos": (3,)}``; at most ``max_points`` (an even subset). With
    ``root``, only a regular file resolving inside it and at most :data:`MAX_CLOUD_BYTES`
    long (uncompressed) is read; anything else is logged and draws nothing."""
    try:
        with os.fdopen(open_regular(path, root=root), "rb") as fh:
            with zipfile.ZipFile(fh) as z:
                if sum(i.file_size for i in z.infolist()) > MAX_CLOUD_BYTES:
                    raise ValueError(f"more than {MAX_CLOUD_BYTES} bytes uncompressed")
            fh.seek(0)
            with np.load(fh, allow_pickle=False) as data:
                pts = np.asarray(data["points"], dtype=float)
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        logger.warning("view: point cloud %s unreadable: %s", path, exc)
        return []
    if pts.ndim != 2 or pts.shape[1] != 3:
        return []
    if len(pts) > max_points:
        pts = pts[np.linspace(0, len(pts) - 1, max_points).round().astype(int)]
    return [{"kind": "cloud", "pos": p} for p in pts.tolist()]


def _draw_markers(scene: mujoco.MjvScene, markers: list[dict[str, Any]]) -> dict[str, int]:
    """Append ``markers`` to ``scene``: points as spheres (the cloud as 4 mm cubes),
    segments as thin capsules, in :data:`_ORDER`; returns how many of each kind fit."""
    counts: dict[str, int] = {}
    eye = np.eye(3).flatten()
    zero = np.zeros(3)
    for m in sorted(markers, key=lambda m: _ORDER.index(m["kind"])):
        if scene.ngeom >= scene.maxgeom:
            break
        rgba = np.asarray(MARKER_RGBA[m["kind"]], dtype=np.float32)
        g = scene.geoms[scene.ngeom]
        if "line" in m:
            a, b = (np.asarray(p, dtype=np.float64) for p in m["line"])
            radius = {"planned_path": 0.004, "tcp_path": 0.003, "frustum": 0.002}[m["kind"]]
            mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, zero, zero, eye, rgba)
            mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, radius, a, b)
        elif m["kind"] == "cloud":
            mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_BOX, np.full(3, 0.002), np.asarray(m["pos"], dtype=np.float64),
                                eye, rgba)
        else:
            size = {"perceived": 0.028, "grasp": 0.012, "place": 0.016}[m["kind"]]
            mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_SPHERE, np.array([size, 0, 0]),
                                np.asarray(m["pos"], dtype=np.float64), eye, rgba)
        scene.ngeom += 1
        counts[m["kind"]] = counts.get(m["kind"], 0) + 1
    return counts


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
        #: per cached session: its target's camera sensors (sensors.yaml) and the planned
        #: paths' tool points, keyed by the trace file's (mtime, size)
        self._sensors: dict[str, tuple[Any, ...]] = {}
        self._plans: dict[str, tuple[tuple[int, int], list[dict[str, Any]]]] = {}
        #: joint layouts per session, built on their own thread: a timeline's signals never
        #: wait behind the scene renders queued by other pages (or by tabs since closed)
        self._layout_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="view-layout")
        self._layouts: OrderedDict[str, dict[str, Any]] = OrderedDict()

    def close(self) -> None:
        self._layout_pool.shutdown(wait=True)
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

        Returns ``(png bytes, info)`` with ``info`` = ``{"source", "t" (simulated s),
        "overlays", "overlay_kinds"[, "cloud"]}``. The scene itself is the simulator's
        state, i.e. ground truth. With ``overlays``, the robot's own data is drawn into
        it, from the session's evidence and the target's sensors (world frame): perceived
        object positions, grasp and place targets and the executed tool path
        (:func:`overlay_markers`), the planned paths' tool points
        (:func:`plan_segments` of :func:`planned_paths`), the camera frustums at this
        instant (:func:`camera_frustums`, from ``sensors.yaml``) and the perceived
        object point cloud in force at this instant (:func:`cloud_file_at`, its file name
        in ``info["cloud"]``). ``info["overlays"]`` counts the markers drawn,
        ``info["overlay_kinds"]`` per kind; a perceived marker's offset from its object
        is the perception error.

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

        Built once per session on the layout thread, from a model of its own (never behind
        the render queue), and kept for the :data:`_MAX_LAYOUTS` most recent sessions.

        Raises:
            ViewError: the target cannot be rebuilt.
            TimeoutError: no layout within 60 s.
        """
        with self._lock:
            cached = self._layouts.get(session_id)
        if cached is not None:
            return cached
        layout = self._layout_pool.submit(self._layout, session_id).result(timeout=60)
        with self._lock:
            self._layouts[session_id] = layout
            while len(self._layouts) > _MAX_LAYOUTS:
                self._layouts.popitem(last=False)
        return layout

    def _layout(self, session_id: str) -> dict[str, Any]:
        with self._lock:
            cached = self._layouts.get(session_id)
        if cached is not None:  # asked twice while the first was queued
            return cached
        try:
            target = self._build_target(session_id)
        except TargetError as exc:
            raise ViewError(str(exc)) from exc
        try:
            return self._layout_of(target.model)
        finally:
            target.close()

    @staticmethod
    def _layout_of(m: mujoco.MjModel) -> dict[str, Any]:
        arm: list[tuple[str, int]] = []
        fingers: list[int] = []
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
        target = self._build_target(session_id, rec)
        entry = (target, mujoco.MjData(target.model))
        self._models[session_id] = entry
        try:
            self._sensors[session_id] = read_sensors(self.workspace.root).for_target(rec.target)
        except PhyAgentOSError as exc:
            logger.warning("view: no camera frustums for session %s: %s", session_id, exc)
            self._sensors[session_id] = ()
        while len(self._models) > _MAX_MODELS:
            gone, (old, _) = self._models.popitem(last=False)
            self._sensors.pop(gone, None)
            self._plans.pop(gone, None)
            old.close()
        return entry

    def _build_target(self, session_id: str, rec: Any = None) -> Any:
        """A fresh MuJoCo target of ``session_id``'s target and scene (the caller closes it).

        Raises:
            ViewError: the target is not one the view can rebuild, or has no MuJoCo model.
        """
        rec = rec if rec is not None else self.workspace.load_session(session_id)
        spec = next((t for t in self.workspace.read("TARGETS").data.targets if t.name == rec.target), None)
        if spec is None or spec.driver not in DRIVERS:
            raise ViewError(f"session {session_id}: target {rec.target!r} is not one the view can rebuild")
        target = DRIVERS[spec.driver](spec.name, scene_for(rec, spec, root=self.workspace.root), seed=rec.seed)
        if not isinstance(target, MuJoCoBacked) or not isinstance(target.model, mujoco.MjModel):
            target.close()
            raise ViewError(f"session {session_id}: target {rec.target!r} exposes no MuJoCo model")
        return target

    def _planned(self, session_id: str, target, trace: list[dict[str, Any]],
                 key: tuple[int, int]) -> list[dict[str, Any]]:
        """The session's planned paths as tool-point segments (cached per trace version)."""
        cached = self._plans.get(session_id)
        if cached is not None and cached[0] == key:
            return cached[1]
        names, tcp = target.arm_joint_names, target.tcp_site  # a MuJoCoBacked target (_target)
        segments: list[dict[str, Any]] = []
        if names and tcp:
            model = target.model
            try:
                adr = [int(model.joint(n).qposadr[0]) for n in names]
                site = int(model.site(tcp).id)
            except KeyError as exc:
                logger.warning("view: no planned path for session %s: %s", session_id, exc)
            else:
                segments = plan_segments(model, adr, site, planned_paths(trace, len(adr)))
        self._plans[session_id] = (key, segments)
        return segments

    def _overlays(self, session_id: str, target, data: mujoco.MjData, info: dict[str, Any]) -> list[dict[str, Any]]:
        """Every overlay marker of the session at the shown instant (see :meth:`render`)."""
        root = self.workspace.root
        directory = evidence_dir(root, session_id)  # ViewError: a link out of the workspace
        path = directory / "trace.jsonl"
        try:
            st = path.stat()
            key = (st.st_mtime_ns, st.st_size)
        except OSError:
            key = (0, 0)
        trace, _ = read_trace(path, root=root)
        markers = overlay_markers(directory, trace, root=root)
        markers += self._planned(session_id, target, trace, key)
        markers += camera_frustums(target.model, data, self._sensors.get(session_id, ()))
        cloud = cloud_file_at(directory, trace, info["t"], info.pop("_t_last", None))
        if cloud is not None:
            markers += cloud_markers(cloud, root=root)
            info["cloud"] = cloud.name
        return markers

    def _state(self, session_id: str, target, data: mujoco.MjData, frame: int | None) -> dict[str, Any]:
        model = target.model
        if frame is not None:
            try:
                frames = frames_of(evidence_dir(self.workspace.root, session_id), root=self.workspace.root)
            except (OSError, ValueError) as exc:
                raise ViewError(f"session {session_id}: recording not read: {exc}") from None
            if frames is None or not len(frames["t"]):
                raise ViewError(f"session {session_id} has no recording (run with --record)")
            if not 0 <= frame < len(frames["t"]) or frames["qpos"].shape[1:] != (model.nq,):
                raise ViewError(f"frame {frame} out of range 0..{len(frames['t']) - 1} (or qpos of another model)")
            data.qpos[:] = frames["qpos"][frame]
            mujoco.mj_forward(model, data)
            return {"source": "recording", "t": float(frames["t"][frame]), "_t_last": float(frames["t"][-1])}
        rec = self.workspace.load_session(session_id)
        meta_path = self.workspace.root / "targets" / rec.target / "state.yaml"
        meta = read_yaml(meta_path, error=ViewError, root=self.workspace.root) if meta_path.is_file() else None
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
            self._renderer = Renderer(model, height=self.height, width=self.width)
            self._renderer_model = model
        cam = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(model, cam)
        cam.lookat[:] = (0.45, 0.0, 0.25)
        cam.azimuth = float(azimuth)
        cam.elevation = float(np.clip(elevation, -89.0, 89.0))
        cam.distance = float(distance) if distance else 1.9
        self._renderer.update_scene(data, camera=cam)
        self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        kinds = _draw_markers(self._renderer.scene, self._overlays(session_id, target, data, info)) if overlays else {}
        info.pop("_t_last", None)
        info["overlays"] = sum(kinds.values())
        info["overlay_kinds"] = kinds
        pixels = self._renderer.render()
        buf = io.BytesIO()
        Image.fromarray(pixels).save(buf, format="PNG")
        return buf.getvalue(), info
