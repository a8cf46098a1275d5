"""Seeded synthetic tabletop scenes rendered by MuJoCo, with their true poses (tests and bench).

This module builds the tabletop Franka scene (:func:`phyagentos.targets.scene.build_scene_spec`)
with extra *static* box / cylinder / sphere geoms resting on the table and extra cameras,
renders RGB-D :class:`~phyagentos.perception.frames.CameraFrame` s from them, and returns the
truth used to score perception. The truth it returns is for tests and ``bench/perception.py``
only; nothing in the Runtime or Agent plane's session path calls this module.

Camera conventions (documented in ``docs/perception.md``): a MuJoCo camera looks along its
own -z axis with +y up; its pose in the world is ``(data.cam_xpos, data.cam_xmat)``. The
OpenCV optical frame (x right, y down, z forward) is ``R_opt = R_mj @ diag(1, -1, -1)`` at the
same origin (:func:`optical_pose_from_mujoco`). Intrinsics come from the vertical field of
view (:meth:`CameraIntrinsics.from_fovy`). MuJoCo's ``Renderer`` in depth mode returns metric
depth along the optical axis (MuJoCo >= 3.0 linearises the z-buffer with the model's
znear/zfar); pixels that hit nothing come back at the far plane and are set to 0 here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import mujoco
import numpy as np

from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics, Proprioception
from phyagentos.renderer import Renderer

__all__ = [
    "SyntheticObject",
    "SyntheticCamera",
    "SyntheticScene",
    "CameraNoise",
    "DEFAULT_CAMERAS",
    "WRIST_CAMERA",
    "optical_pose_from_mujoco",
    "look_at_quat",
    "random_objects",
]

_SHAPES = ("box", "cylinder", "sphere")

#: Where unused slots wait: under the table top, out of every camera's view. Not far away:
#: MuJoCo scales the clipping planes with the model's extent (znear = 0.01 x extent), and a
#: body 50 m away would clip everything closer than 0.5 m (the wrist camera's whole view).
_PARKING = (0.35, 0.0, -0.4)


def optical_pose_from_mujoco(pos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    """(4, 4) pose of the OpenCV optical frame given a MuJoCo camera's world pose.

    Args:
        pos: (3,) camera position in the world frame, m (``data.cam_xpos[i]``).
        xmat: (9,) or (3, 3) camera orientation (``data.cam_xmat[i]``), columns = camera x
            (right), y (up), z (backwards) in the world frame.

    Returns ``T`` with ``T[:3, :3] = R_mj @ diag(1, -1, -1)`` (flip y and z: y down, z forward).
    """
    T = np.eye(4)
    T[:3, :3] = np.asarray(xmat, float).reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = np.asarray(pos, float)
    return T


def look_at_quat(eye, target, up=(0.0, 0.0, 1.0)) -> list[float]:
    """Quaternion (wxyz) of a MuJoCo camera at ``eye`` looking at ``target`` with image-up
    direction ``up`` (all in the parent frame)."""
    eye = np.asarray(eye, float)
    fwd = np.asarray(target, float) - eye
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, np.asarray(up, float))
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.column_stack([x, y, -fwd]).flatten())
    return q.tolist()


@dataclass(frozen=True)
class SyntheticObject:
    """A static object resting on the table (or on ``z_base_m``).

    Attributes:
        name: geom name.
        shape: ``"box"``, ``"cylinder"`` or ``"sphere"``.
        half_extents: (hx, hy, hz) m; a cylinder uses (r, r, half height), a sphere (r, r, r).
        position: (x, y) world m of the centre.
        yaw: rad about world z (boxes; ignored for the round shapes' appearance).
        rgba: colour in [0, 1].
        z_base_m: height of the surface it rests on (0 = table; > 0 = stacked).
    """

    name: str
    shape: str
    half_extents: tuple[float, float, float]
    position: tuple[float, float]
    yaw: float = 0.0
    rgba: tuple[float, float, float, float] = (0.8, 0.2, 0.2, 1.0)
    z_base_m: float = 0.0

    def __post_init__(self) -> None:
        if self.shape not in _SHAPES:
            raise PerceptionError(f"shape must be one of {_SHAPES}, got {self.shape!r}")

    @property
    def centre(self) -> tuple[float, float, float]:
        """World (x, y, z) of the centre, m."""
        return (self.position[0], self.position[1], self.z_base_m + self.half_extents[2])


@dataclass(frozen=True)
class SyntheticCamera:
    """An RGB-D camera at ``eye`` looking at ``target`` with vertical fov ``fovy_deg``.

    ``eye`` and ``target`` are metres in the frame of ``body`` (None = the world); ``up`` is
    the image's up direction in that frame (None = +z).
    """

    name: str
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    fovy_deg: float = 45.0
    width: int = 320
    height: int = 240
    body: str | None = None
    up: tuple[float, float, float] | None = None


#: A wrist RGB-D camera on the Panda's link7 (the geometry of the tabletop target's wrist
#: camera): 7.5 cm off the tool axis, 12 cm past the flange, looking 20 cm beyond the tcp.
WRIST_CAMERA = SyntheticCamera(
    "wrist", eye=(0.075 * math.cos(-math.pi / 4), 0.075 * math.sin(-math.pi / 4), 0.12),
    target=(0.0, 0.0, 0.445), fovy_deg=58.0, body="panda0_link7",
    up=(-math.cos(-math.pi / 4), -math.sin(-math.pi / 4), 0.0),
)

#: Two cameras over the reachable table: one in front of the robot, one to its right.
DEFAULT_CAMERAS: tuple[SyntheticCamera, ...] = (
    SyntheticCamera("front", eye=(1.05, 0.05, 0.60), target=(0.50, 0.0, 0.0)),
    SyntheticCamera("side", eye=(0.55, -0.60, 0.60), target=(0.50, 0.0, 0.0)),
)


@dataclass(frozen=True)
class CameraNoise:
    """Camera noise added at capture: Gaussian depth noise sigma = base + quadratic * z**2 (m),
    Gaussian RGB noise (std in 0..255 units), a global brightness gain drawn per frame in
    [1 - gain_jitter, 1 + gain_jitter] (lighting), and a fraction of depth pixels dropped to 0."""

    depth_base_m: float = 0.0005
    depth_quadratic_per_m: float = 0.0015
    rgb_std: float = 3.0
    gain_jitter: float = 0.1
    dropout: float = 0.01


@dataclass
class SyntheticScene:
    """A compiled scene with its renderer; :meth:`capture` gives CameraFrames.

    Args:
        objects: what rests on the table.
        cameras: extra cameras (MuJoCo cameras named as given).
        arm_qpos: (7,) arm joint positions, rad (default: the scene's home configuration).
        finger_opening_m: per-finger opening, m.
        pool_per_shape: slots per shape beyond ``objects`` (for :meth:`place` of new draws).
    """

    objects: Sequence[SyntheticObject]
    cameras: Sequence[SyntheticCamera] = DEFAULT_CAMERAS
    arm_qpos: Sequence[float] | None = None
    finger_opening_m: float = 0.04
    pool_per_shape: int = 0
    _renderers: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        from phyagentos.targets.scene import HOME_QPOS, SceneSpec, build_scene_spec

        ms = build_scene_spec(SceneSpec(objects=(), regions=(), obstacles=()))
        ms.visual.global_.offwidth = max(1280, *(c.width for c in self.cameras))
        ms.visual.global_.offheight = max(960, *(c.height for c in self.cameras))
        wb = ms.worldbody
        for c in self.cameras:
            parent = wb if c.body is None else ms.body(c.body)
            # prefixed: the tabletop model has cameras of its own (``overview``, ``wrist``)
            parent.add_camera(name=f"synthetic:{c.name}", pos=list(c.eye), quat=look_at_quat(c.eye, c.target, c.up or (0, 0, 1)),
                              fovy=c.fovy_deg)
        # one mocap body per slot; objects are assigned to slots of their shape, so a new
        # draw of objects only edits sizes, colours and poses (no recompilation)
        counts = {sh: max(self.pool_per_shape, sum(o.shape == sh for o in self.objects)) for sh in _SHAPES}
        gtype = {"box": mujoco.mjtGeom.mjGEOM_BOX, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
                 "sphere": mujoco.mjtGeom.mjGEOM_SPHERE}
        self._slots: dict[str, list[str]] = {}
        for sh, n in counts.items():
            self._slots[sh] = []
            for k in range(n):
                slot = f"{sh}_{k}"
                body = wb.add_body(name=f"synthetic:{slot}", pos=list(_PARKING), mocap=True)
                body.add_geom(name=f"synthetic:{slot}", type=gtype[sh], size=[0.02, 0.02, 0.02],
                              contype=0, conaffinity=0)
                self._slots[sh].append(slot)
        self.model = ms.compile()
        self.data = mujoco.MjData(self.model)
        q = list(self.arm_qpos) if self.arm_qpos is not None else list(HOME_QPOS)
        self.data.qpos[:7] = q
        self.data.qpos[7:9] = self.finger_opening_m
        self.place(self.objects)

    # ------------------------------------------------------------------ pose edits

    def place(self, objects: Sequence[SyntheticObject]) -> None:
        """Show exactly ``objects`` (sizes, colours, poses); other slots move out of view.

        Raises:
            PerceptionError: more objects of one shape than the scene has slots.
        """
        m, d = self.model, self.data
        free = {sh: list(v) for sh, v in self._slots.items()}
        self._slot_of: dict[str, str] = {}
        for sh, slots in self._slots.items():
            for k, slot in enumerate(slots):
                mid = m.body_mocapid[m.body(f"synthetic:{slot}").id]
                d.mocap_pos[mid] = _PARKING
        for o in objects:
            if not free[o.shape]:
                raise PerceptionError(f"no free {o.shape} slot for {o.name!r}; build the scene with a larger pool")
            slot = free[o.shape].pop(0)
            self._slot_of[o.name] = slot
            gid = m.geom(f"synthetic:{slot}").id
            hx, hy, hz = o.half_extents
            m.geom_size[gid] = {"box": (hx, hy, hz), "cylinder": (hx, hz, 0.0), "sphere": (hx, 0.0, 0.0)}[o.shape]
            m.geom_rbound[gid] = math.sqrt(hx * hx + hy * hy + hz * hz)
            m.geom_rgba[gid] = o.rgba
            mid = m.body_mocapid[m.body(f"synthetic:{slot}").id]
            d.mocap_pos[mid] = o.centre
            d.mocap_quat[mid] = (math.cos(o.yaw / 2), 0.0, 0.0, math.sin(o.yaw / 2))
        self.objects = list(objects)
        mujoco.mj_forward(m, d)

    def move_object(self, name: str, position_xyz: Sequence[float], quat_wxyz: Sequence[float] | None = None) -> None:
        """Move object ``name`` to a world pose and recompute the kinematics."""
        mid = self.model.body_mocapid[self.model.body(f"synthetic:{self._slot_of[name]}").id]
        self.data.mocap_pos[mid] = position_xyz
        if quat_wxyz is not None:
            self.data.mocap_quat[mid] = quat_wxyz
        mujoco.mj_forward(self.model, self.data)

    def set_fingers(self, opening_m: float) -> None:
        """Set the per-finger opening (m) and recompute the kinematics."""
        self.data.qpos[7:9] = opening_m
        mujoco.mj_forward(self.model, self.data)

    def tcp_pose(self) -> np.ndarray:
        """(4, 4) pose of the tcp site in the world frame."""
        sid = self.model.site("tcp").id
        T = np.eye(4)
        T[:3, :3] = self.data.site_xmat[sid].reshape(3, 3)
        T[:3, 3] = self.data.site_xpos[sid]
        return T

    # ------------------------------------------------------------------ sensors

    def capture(self, camera: str, *, noise: CameraNoise | None = None,
                rng: np.random.Generator | None = None, stamp_s: float = 0.0) -> CameraFrame:
        """Render camera ``camera`` into a CameraFrame (with ``noise`` if given).

        Raises:
            PerceptionError: unknown camera name.
        """
        spec = next((c for c in self.cameras if c.name == camera), None)
        if spec is None:
            raise PerceptionError(f"no camera {camera!r}; cameras: {[c.name for c in self.cameras]}")
        r = self._renderers.get((spec.width, spec.height))
        if r is None:
            r = Renderer(self.model, height=spec.height, width=spec.width)
            self._renderers[(spec.width, spec.height)] = r
        cid = self.model.camera(f"synthetic:{camera}").id
        r.disable_depth_rendering()
        r.update_scene(self.data, camera=cid)
        rgb = r.render().copy()
        r.enable_depth_rendering()
        r.update_scene(self.data, camera=cid)
        depth = r.render().astype(np.float32).copy()
        r.disable_depth_rendering()
        far = self.model.vis.map.zfar * self.model.stat.extent
        depth[depth >= 0.999 * far] = 0.0
        if noise is not None:
            rng = rng if rng is not None else np.random.default_rng(0)
            sigma = noise.depth_base_m + noise.depth_quadratic_per_m * depth * depth
            depth = depth + (rng.standard_normal(depth.shape).astype(np.float32) * sigma).astype(np.float32)
            depth[rng.random(depth.shape) < noise.dropout] = 0.0
            depth = np.clip(depth, 0.0, None).astype(np.float32)
            gain = 1.0 + rng.uniform(-noise.gain_jitter, noise.gain_jitter)
            img = rgb.astype(np.float32) * gain + rng.standard_normal(rgb.shape).astype(np.float32) * noise.rgb_std
            rgb = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        T = optical_pose_from_mujoco(self.data.cam_xpos[cid], self.data.cam_xmat[cid])
        intr = CameraIntrinsics.from_fovy(spec.width, spec.height, float(self.model.cam_fovy[cid]))
        return CameraFrame(sensor=camera, frame_id=f"{camera}_optical", stamp_s=float(stamp_s), intrinsics=intr,
                           T_world_camera=T, rgb=rgb, depth_m=depth)

    def proprioception(self, *, gripper_effort_n: float = 0.0, wrist_force_n: Sequence[float] | None = (0.0, 0.0, 0.0),
                       stamp_s: float = 0.0) -> Proprioception:
        """The arm's proprioception at the current configuration (efforts as given, since the
        scene is kinematic)."""
        from phyagentos.targets.scene import ARM_JOINT_NAMES

        return Proprioception(
            stamp_s=float(stamp_s),
            joint_names=ARM_JOINT_NAMES,
            joint_positions=self.data.qpos[:7].copy(),
            joint_velocities=np.zeros(7),
            joint_efforts=np.zeros(7),
            gripper_opening_m=float(self.data.qpos[7]),
            gripper_effort_n=float(gripper_effort_n),
            wrist_force_n=None if wrist_force_n is None else np.asarray(wrist_force_n, float),
            wrist_torque_nm=None if wrist_force_n is None else np.zeros(3),
            tcp_pose=self.tcp_pose(),
        )

    def close(self) -> None:
        """Free the renderers' GL contexts."""
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()


def random_objects(rng: np.random.Generator, *, n_targets: int = 1, n_distractors: int = 0,
                   touching: bool = True, palette: Sequence[tuple[float, float, float]] | None = None,
                   x_range=(0.38, 0.68), y_range=(-0.2, 0.2), size_range=(0.02, 0.07)) -> list[SyntheticObject]:
    """Draw non-overlapping objects (2-7 cm edges/diameters by default) on the reachable table.

    Shapes uniform over box/cylinder/sphere, colours distinct entries of ``palette``,
    yaw uniform; with ``touching`` the first distractor is placed against the first object.
    """
    palette = list(palette or _PALETTE)
    colours = rng.permutation(len(palette))
    out: list[SyntheticObject] = []
    total = n_targets + n_distractors
    tries = 0
    while len(out) < total:
        tries += 1
        if tries > 2000:
            raise PerceptionError("could not place the requested objects without overlap")
        i = len(out)
        shape = _SHAPES[int(rng.integers(3))]
        edge = rng.uniform(*size_range, size=3) / 2.0
        if shape == "cylinder":
            he = (edge[0], edge[0], edge[2])
        elif shape == "sphere":
            he = (edge[0], edge[0], edge[0])
        else:
            he = (edge[0], edge[1], edge[2])
        yaw = float(rng.uniform(-math.pi, math.pi))
        r_i = math.hypot(he[0], he[1])
        if touching and i == n_targets and out:
            # against the first object, along a random direction
            a = out[0]
            ang = rng.uniform(-math.pi, math.pi)
            d = _support_radius(a, ang) + _support_radius_he(shape, he, yaw, ang + math.pi)
            pos = (a.position[0] + d * math.cos(ang), a.position[1] + d * math.sin(ang))
        else:
            pos = (float(rng.uniform(*x_range)), float(rng.uniform(*y_range)))
        ok = all(math.hypot(pos[0] - o.position[0], pos[1] - o.position[1]) >= 0.98 * _touch_dist(o, shape, he, yaw, pos)
                 for o in out)
        if not ok:
            continue
        rgb = palette[int(colours[i % len(palette)])]
        out.append(SyntheticObject(name=f"obj{i}", shape=shape, half_extents=tuple(float(v) for v in he),
                                   position=(float(pos[0]), float(pos[1])), yaw=yaw, rgba=(*rgb, 1.0)))
    return out


_PALETTE: tuple[tuple[float, float, float], ...] = (
    (0.85, 0.15, 0.12),  # red
    (0.15, 0.35, 0.85),  # blue
    (0.15, 0.70, 0.25),  # green
    (0.95, 0.80, 0.10),  # yellow
    (0.60, 0.20, 0.75),  # purple
    (0.95, 0.50, 0.10),  # orange
    (0.10, 0.75, 0.80),  # cyan
    (0.95, 0.95, 0.95),  # white
)


def _support_radius_he(shape: str, he, yaw: float, ang: float) -> float:
    """Distance from the centre to the footprint boundary in world direction ``ang``."""
    if shape != "box":
        return he[0]
    c, s = math.cos(ang - yaw), math.sin(ang - yaw)
    tx = he[0] / abs(c) if abs(c) > 1e-9 else math.inf
    ty = he[1] / abs(s) if abs(s) > 1e-9 else math.inf
    return min(tx, ty)


def _support_radius(o: SyntheticObject, ang: float) -> float:
    return _support_radius_he(o.shape, o.half_extents, o.yaw, ang)


def _touch_dist(o: SyntheticObject, shape: str, he, yaw: float, pos) -> float:
    ang = math.atan2(pos[1] - o.position[1], pos[0] - o.position[0])
    return _support_radius(o, ang) + _support_radius_he(shape, he, yaw, ang + math.pi)
