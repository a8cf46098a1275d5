"""MuJoCoArmTarget: the one base of every simulated MuJoCo arm (construction, accessors,
keyframe reset, trajectories, streaming, observation, tools).

Contacts, the world model and ground truth, sensors and checkpoints are the mix-ins
:mod:`.contacts`, :mod:`.world_truth`, :mod:`.sensors` and :mod:`.checkpoints`; the package
docstring says what the subclasses share.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, ClassVar, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.geometry import matrix_to_quat as mat_quat
from phyagentos.geometry import pose_matrix

from ..base import BaseRolloutTarget
from ..camera_noise import CameraNoise
from ..contract import (
    ExecutionResult,
    MuJoCoBacked,
    PlanningBodies,
    PlansInPerceivedWorld,
    RendersImages,
    TargetCapabilities,
)
from .checkpoints import ArmCheckpoints
from .common import K_ENV, K_FINGER, K_OBJECT, K_ROBOT
from .common import floats as _floats
from .contacts import ArmContacts
from .sensors import ArmSensors
from .world_truth import ArmWorldTruth

__all__ = ["MuJoCoArmTarget", "GripperResult"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GripperResult:
    """Outcome of :meth:`set_gripper` of a MuJoCo arm target.

    Attributes:
        opening_m: measured opening per finger after settling, metres (0 .. 0.04).
        stalled: the fingers stopped more than 2 mm short of the commanded opening
            (something is between them).

    What is between the fingers is not named: a real hand's encoders say only how far it
    closed. The simulator's answer (:meth:`held_objects`) is ground truth, for scoring and tests.
    """

    opening_m: float
    stalled: bool

    def to_dict(self) -> dict[str, Any]:
        return {"opening_m": self.opening_m, "stalled": self.stalled}


class MuJoCoArmTarget(ArmContacts, ArmWorldTruth, ArmSensors, ArmCheckpoints, BaseRolloutTarget, MuJoCoBacked,
                      RendersImages):
    """Base of the MuJoCo arm targets. Subclasses build their model, then call
    :meth:`_init_arm` and, for tabletop scenes, :meth:`_init_tabletop`.

    Subclass hooks: :attr:`ROBOT` (robot entity name), :attr:`ROBOT_BASE` (xyz of the base
    in the world, m), :meth:`gripper_opening`, :meth:`set_gripper`, :meth:`reset`,
    :meth:`track`, :meth:`settle`, :meth:`_state_meta` / :meth:`_restore_meta` (extra
    checkpoint content), :meth:`_fingerprint_extra`, :meth:`_gripper_effort_n`.

    Class attributes (read by preflight without constructing a target): ``KIND``,
    ``TOOLS``, ``ACTION_FORMS``.
    """

    KIND = "simulation"
    TOOLS = ("observe", "move_joints", "set_gripper", "hold", "snapshot")
    CAPABILITIES = TargetCapabilities(action_forms=("joint_trajectory", "gripper_command"),
                                      sensors=("proprioception", "rgb", "contacts"), simulated_ground_truth=True)
    ROBOT = "robot"
    ROBOT_BASE: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Name of the site carrying the wrist force/torque sensors, if the model has them.
    FT_SITE: str | None = None
    #: Report unexpected contacts during trajectory execution.
    REPORT_CONTACTS = True
    #: Entry of the shipped ``phyagentos/data/protocol/sensors.yaml`` whose sensors a new target installs
    #: (the target pool then installs the workspace's entry for the target's own name).
    SENSORS_KEY: str | None = None
    #: Robot body-name pairs the model lets touch (e.g. adjacent links a third-party model
    #: does not exclude), ignored by the collision checker; default none.
    allowed_collision_pairs: tuple[tuple[str, str], ...] = ()
    #: The widest object the gripper takes in a top-down grasp, m (the Franka Hand's 8 cm);
    #: grasp planning and the graph preflight refuse wider objects before anything moves.
    max_grasp_width_m: ClassVar[float | None] = 0.08  # motion.grasp.DEFAULT_MAX_GRASP_WIDTH_M (not imported: 2 s)
    #: The gripper's body names for the collision checker; ``None``: the checker's default.
    gripper_body_names: tuple[str, ...] | None = None
    #: For an arm that cannot reach every orientation: position-priority IK accepting
    #: orientations within this tolerance, rad; ``None``: full-pose IK.
    ik_orientation_tol_rad: float | None = None
    #: The randomised world's draw (:func:`~phyagentos.targets.world.draw_world`), set by
    #: :meth:`_prepare_scene`; ``None``: the scene was built as declared.
    world_draw: Any = None
    #: The scene as the user declared it (before the draw), set by :meth:`_prepare_scene`;
    #: ``None``: the built scene is the declared one.
    _declared_scene: Any = None

    # -- construction helpers -----------------------------------------------------------
    def _prepare_scene(self, scene):
        """The physical scene to build: ``scene`` itself, or its randomised world
        (:func:`~phyagentos.targets.world.draw_world`), recorded in :attr:`world_draw`."""
        from ..world import draw_world  # noqa: PLC0415

        self._declared_scene = scene
        drawn, self.world_draw = draw_world(scene)
        return drawn

    def _init_arm(self, model: mujoco.MjModel, data: mujoco.MjData, joint_names: Sequence[str], *,
                  tcp_site: str, arm_actuators: Sequence[int] | None = None, seed: int | None = None) -> None:
        """Index the arm: joints ``joint_names`` driven by ``arm_actuators`` (ids; default:
        the actuator whose transmission is each joint), tool site ``tcp_site``."""
        self._model, self._data = model, data
        m = model
        self._arm_names = tuple(joint_names)
        self._jids = np.array([m.joint(n).id for n in joint_names])
        self._qadr = m.jnt_qposadr[self._jids].copy()
        self._dadr = m.jnt_dofadr[self._jids].copy()
        if arm_actuators is None:
            acts = []
            for j in self._jids:
                found = [a for a in range(m.nu) if m.actuator_trnid[a, 0] == j]
                if not found:
                    raise TargetError(f"no actuator drives joint {m.joint(int(j)).name!r}")
                acts.append(found[0])
            arm_actuators = acts
        self._arm_act = np.array(arm_actuators, dtype=int)
        self._kp = m.actuator_gainprm[self._arm_act, 0].copy()
        self._ff_gain = m.dof_damping[self._dadr] / self._kp
        self._ctrl_lo = m.actuator_ctrlrange[:, 0].copy()
        self._ctrl_hi = m.actuator_ctrlrange[:, 1].copy()
        self._tcp = m.site(tcp_site).id
        self._tcp_name = tcp_site
        self._renderers: dict[tuple[int, int], Any] = {}
        self._rng = np.random.default_rng(seed)
        self._episode_seed = seed
        self._camera_noise: dict[str, CameraNoise] = {}
        self._state_file: tuple[str, str, str] | None = None  # (path, file SHA-256, world digest): save_state
        self._sensor_specs: dict[str, Any] = {}
        self._obj_names: tuple[str, ...] = ()
        self._obj_body: dict[str, int] = {}
        self._frame_count = 0
        #: The runtime's own notes about this robot (e.g. the grasp it believes it holds,
        #: :mod:`phyagentos.primitives.grasp_sense`): plain data, checkpointed with the state.
        self.runtime_notes: dict[str, Any] = {}
        #: Target-local e-stop hook: any object with ``is_set()`` (the SafetyGuard's latch);
        #: trajectory streaming checks it every physics step and halts the arm when set.
        self.estop = None
        self._ft_adr: tuple[int, int] | None = None
        if self.FT_SITE is not None:
            f = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "wrist_force")
            t = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "wrist_torque")
            if f >= 0 and t >= 0:
                self._ft_adr = (int(m.sensor_adr[f]), int(m.sensor_adr[t]))
        if self.SENSORS_KEY is not None:
            from phyagentos.protocol.sensors import read_sensors  # noqa: PLC0415

            self.configure_sensors(read_sensors().for_target(self.SENSORS_KEY))

    def _init_tabletop(self, scene, *, robot_root: int, finger_sides: dict[int, int]) -> None:
        """Index a :class:`SceneSpec` world: object bodies, and every colliding geom's kind
        (``K_*``), object index and finger side (1 / 2 for the two fingers or jaws).

        Args:
            robot_root: body id under which every robot body lies.
            finger_sides: body id -> side (1 or 2) of the finger bodies.
        """
        from ..scene import FLOOR_GEOM, TABLE_GEOM, object_joint_name  # noqa: PLC0415

        m = self._model
        self._scene = scene
        self._obj_names = scene.object_names
        self._obj_body = {o.name: m.body(o.name).id for o in scene.objects}
        self._obj_geom = {o.name: m.geom(o.name).id for o in scene.objects}
        self._obj_qadr = {o.name: int(m.jnt_qposadr[m.joint(object_joint_name(o.name)).id]) for o in scene.objects}
        self._obj_dadr = {o.name: int(m.jnt_dofadr[m.joint(object_joint_name(o.name)).id]) for o in scene.objects}
        body_obj = {b: n for n, b in self._obj_body.items()}
        kind = np.zeros(m.ngeom, dtype=np.int8)
        gobj = np.full(m.ngeom, -1, dtype=np.int32)
        side = np.zeros(m.ngeom, dtype=np.int8)
        for g in range(m.ngeom):
            if m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0:
                continue
            b = int(m.geom_bodyid[g])
            if b in finger_sides:
                kind[g] = K_FINGER
                side[g] = finger_sides[b]
            elif b != 0 and self._is_under(b, robot_root):
                kind[g] = K_ROBOT
            elif int(m.body_rootid[b]) in body_obj:
                kind[g] = K_OBJECT
                gobj[g] = self._obj_names.index(body_obj[int(m.body_rootid[b])])
            else:
                kind[g] = K_ENV
        self._gkind, self._gobj, self._gside = kind, gobj, side
        self._support_geoms = frozenset((m.geom(TABLE_GEOM).id, m.geom(FLOOR_GEOM).id))
        self._robot_root = robot_root
        self._planning: PlanningBodies | None = None  # built on first use (:class:`PlansOnTheTabletop`)
        self._U_cache: dict[frozenset, np.ndarray] = {}

    def _is_under(self, b: int, root: int) -> bool:
        while b > 0:
            if b == root:
                return True
            b = int(self._model.body_parentid[b])
        return False

    # -- accessors --------------------------------------------------------------------
    @property
    def model(self) -> mujoco.MjModel:
        """The compiled MuJoCo model (treat as read-only)."""
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The live MuJoCo data."""
        return self._data

    @property
    def scene(self):
        """The scene this target was built from."""
        return self._scene

    @property
    def rng(self) -> np.random.Generator:
        """numpy Generator seeded by ``reset(seed=...)``."""
        return self._rng

    @property
    def arm_joint_names(self) -> tuple[str, ...]:
        return self._arm_names

    @property
    def n_arm(self) -> int:
        """Number of arm joints."""
        return len(self._arm_names)

    @property
    def tcp_site(self) -> str:
        return self._tcp_name

    @property
    def sim_time(self) -> float:
        """Simulated time in seconds since the last reset (or loaded state)."""
        return float(self._data.time)

    @property
    def timestep(self) -> float:
        return float(self._model.opt.timestep)

    @property
    def feedforward_gain(self) -> np.ndarray:
        """``(n,)`` s: joint damping / actuator kp, read from the model."""
        return self._ff_gain.copy()

    @property
    def home_qpos(self) -> np.ndarray:
        """``(n,)`` rad ready configuration: the arm joints of the model's ``home`` keyframe."""
        m = self._model
        return m.key_qpos[m.key("home").id][self._qadr].copy()

    def arm_qpos(self) -> np.ndarray:
        """``(n,)`` current arm joint angles, rad."""
        return self._data.qpos[self._qadr].copy()

    def arm_qvel(self) -> np.ndarray:
        """``(n,)`` current arm joint velocities, rad/s."""
        return self._data.qvel[self._dadr].copy()

    def gripper_opening(self) -> float:  # pragma: no cover - every subclass overrides
        raise NotImplementedError

    def tcp_pose(self) -> np.ndarray:
        """``(4, 4)`` world pose of the tool site."""
        d = self._data
        return pose_matrix(d.site_xpos[self._tcp], d.site_xmat[self._tcp])

    def object_pose(self, name: str) -> np.ndarray:
        """``(4, 4)`` world pose of object ``name``; TargetError listing objects if unknown."""
        b = self._obj_body.get(name)
        if b is None:
            raise TargetError(f"unknown object {name!r}; objects: {format_choices(self._obj_names)}")
        d = self._data
        return pose_matrix(d.xpos[b], d.xmat[b])

    def object_body(self, name: str) -> str:
        """Name of the model body carrying object ``name`` (the collision checker attaches
        that body to the gripper while the object is held); default: the object's own name."""
        return name

    def _check_open(self) -> None:
        if self.closed:
            raise TargetError(f"target {self.name!r} is closed")

    def close(self) -> None:
        for r in getattr(self, "_renderers", {}).values():
            try:
                r.close()
            except Exception:  # noqa: BLE001 - pragma: no cover - GL teardown
                pass
        self._renderers = {}
        super().close()

    # -- keyframe reset -----------------------------------------------------------------
    def _reset_keyframe(self, key: int, settle_s: float, seed: int | None) -> None:
        """Reset to keyframe ``key``, settle ``settle_s`` s, restart the clock at 0 and
        re-seed :attr:`rng` and the camera noise."""
        self._check_open()
        self._rng = np.random.default_rng(seed)
        self._episode_seed = seed
        self._camera_noise = {}
        self._frame_count = 0
        self.runtime_notes = {}
        m, d = self._model, self._data
        mujoco.mj_resetDataKeyframe(m, d, key)
        mujoco.mj_forward(m, d)
        for _ in range(int(round(settle_s / m.opt.timestep))):
            mujoco.mj_step(m, d)
        d.time = 0.0
        mujoco.mj_forward(m, d)

    # -- trajectories -------------------------------------------------------------------
    def _traj_arrays(self, traj) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = self.n_arm
        t = np.asarray(traj.t, dtype=float).reshape(-1)
        Q = np.asarray(traj.q, dtype=float)
        QD = np.asarray(getattr(traj, "qd", np.zeros_like(Q)), dtype=float)
        if len(t) < 1 or Q.shape != (len(t), n) or QD.shape != Q.shape:
            raise TargetError(f"trajectory must have t (M,), q and qd (M, {n}); got {t.shape}, {Q.shape}, {QD.shape}")
        if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(QD)) and np.all(np.isfinite(t))):
            raise TargetError("trajectory contains non-finite values")
        return t - t[0], Q, QD

    def _check_start(self, Q0: np.ndarray, tracking_tol_rad: float) -> None:
        start_err = float(np.max(np.abs(Q0 - self.arm_qpos())))
        allowed = max(tracking_tol_rad, 0.02)
        if start_err > allowed:
            raise TargetError(
                f"trajectory starts {start_err:.3f} rad from the current arm configuration (allowed {allowed:.3f} rad)"
            )

    def _slice_times(self, t: np.ndarray, t_start: float, t_end: float) -> np.ndarray:
        duration = float(t[-1])
        t_end = min(float(t_end), duration)
        ts = self._model.opt.timestep
        n = max(0, int(round((t_end - max(t_start, 0.0)) / ts)))
        times = np.minimum(max(t_start, 0.0) + (np.arange(n) + 1) * ts, duration)
        if n and t_end >= duration - 1e-12:
            times[-1] = duration
        return times

    # -- streaming (tabletop arms driven directly by position actuators) ----------------
    def _stream(self, t, Q, QD, times, tracking_tol_rad, feedforward, bad_pairs) -> tuple[bool, float, int, str]:
        """Step once per entry of ``times`` (s, trajectory clock) with the interpolated
        reference ``ctrl = q_ref + (b / kp) qd_ref``; returns (completed, max error, steps,
        reason)."""
        m, d = self._model, self._data
        n = len(times)
        if n == 0:
            return True, 0.0, 0, ""
        nj = self.n_arm
        Qr = np.column_stack([np.interp(times, t, Q[:, j]) for j in range(nj)])
        QDr = np.column_stack([np.interp(times, t, QD[:, j]) for j in range(nj)])
        ff = self._ff_gain if feedforward else np.zeros(nj)
        lo, hi = self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act]
        C = np.clip(Qr + ff * QDr, lo, hi)
        U = self._unexpected_for_current_grasp() if self.REPORT_CONTACTS else None
        arm_act, qadr = self._arm_act, self._qadr
        ctrl, qpos = d.ctrl, d.qpos
        max_err = 0.0
        estop = self.estop
        for k in range(n):
            if estop is not None and estop.is_set():
                ctrl[arm_act] = np.clip(qpos[qadr], lo, hi)  # halt: stay where we are
                return False, max_err, k, f"e-stop at t={times[k]:.3f} s"
            ctrl[arm_act] = C[k]
            mujoco.mj_step(m, d)
            err = float(np.max(np.abs(qpos[qadr] - Qr[k])))
            if err > max_err:
                max_err = err
            if U is not None:
                self._collect_contacts(U, bad_pairs)
            if self._on_step is not None:
                self._on_step()
            if err > tracking_tol_rad:
                ctrl[arm_act] = np.clip(qpos[qadr], lo, hi)  # stop where we are
                reason = (
                    f"tracking error {err:.4f} rad exceeded {tracking_tol_rad:.4f} rad at "
                    f"t={times[k]:.3f} s of {float(t[-1]):.3f} s"
                )
                return False, max_err, k + 1, reason
        return True, max_err, n, ""

    #: Optional callable run after every physics step of a streamed trajectory (the
    #: runtime's proprioception sampler while holding); ``None`` by default.
    _on_step = None

    def set_step_hook(self, hook) -> None:
        """Install ``hook()`` to run after each streamed physics step (``None`` removes it)."""
        self._on_step = hook

    def settle(self, q: Sequence[float] | None = None, *, settle_s: float = 0.5, tol_rad: float = 0.005,
               _contacts: set | None = None) -> int:
        """Command the arm to ``q`` (n,) rad (default: the current command) and step until
        it is within ``tol_rad`` and slower than 0.02 rad/s, at most ``settle_s``
        simulated seconds. Returns the number of steps."""
        self._check_open()
        m, d = self._model, self._data
        lo, hi = self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act]
        if q is not None:
            q_end = np.asarray(q, dtype=float).reshape(-1)
            if q_end.shape != (self.n_arm,):
                raise TargetError(f"settle: q must have shape ({self.n_arm},), got {q_end.shape}")
            d.ctrl[self._arm_act] = np.clip(q_end, lo, hi)
        else:
            q_end = d.ctrl[self._arm_act].copy()
        U = self._unexpected_for_current_grasp() if (_contacts is not None and self.REPORT_CONTACTS) else None
        qadr, dadr = self._qadr, self._dadr
        steps = 0
        for _ in range(int(round(settle_s / m.opt.timestep))):
            mujoco.mj_step(m, d)
            steps += 1
            if U is not None:
                self._collect_contacts(U, _contacts)  # type: ignore[arg-type]
            if float(np.max(np.abs(d.qpos[qadr] - q_end))) < tol_rad and float(np.max(np.abs(d.qvel[dadr]))) < 0.02:
                break
        return steps

    def hold(self, q: Sequence[float] | None = None, *, duration_s: float) -> int:
        """Hold the arm at ``q`` (n,) rad (default: where it is now) for ``duration_s``
        simulated seconds. Returns the number of physics steps."""
        self._check_open()
        target = self.arm_qpos() if q is None else np.asarray(q, dtype=float).reshape(-1)
        if target.shape != (self.n_arm,) or not np.all(np.isfinite(target)):
            raise TargetError(f"hold: q must be {self.n_arm} finite joint angles, got {q!r}")
        if duration_s < 0 or not math.isfinite(duration_s):
            raise TargetError(f"seconds must be a finite number >= 0, got {duration_s}")
        self._data.ctrl[self._arm_act] = np.clip(target, self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act])
        n = int(round(duration_s / self._model.opt.timestep))
        for _ in range(n):
            mujoco.mj_step(self._model, self._data)
        return n

    def halt(self) -> None:
        """Stop: command the arm to stay where it is (velocity feed-forward dropped)."""
        if self.closed:
            return
        lo, hi = self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act]
        self._data.ctrl[self._arm_act] = np.clip(self.arm_qpos(), lo, hi)

    # -- observation --------------------------------------------------------------------
    def observe(self) -> dict:
        """Current simulator observation: ``time`` (s), ``arm_qpos`` (n,) rad, ``arm_qvel``
        (n,) rad/s, ``gripper_opening_m``, ``tcp_pose`` (4, 4), ``objects`` {name: (4, 4)},
        ``qpos`` (nq,) full configuration (for collision checkers), ``held``."""
        self._check_open()
        return {"time": self.sim_time, "arm_qpos": self.arm_qpos(), "arm_qvel": self.arm_qvel(),
                "gripper_opening_m": self.gripper_opening(), "tcp_pose": self.tcp_pose(),
                "objects": {n: self.object_pose(n) for n in self._obj_names}, "qpos": self._data.qpos.copy(),
                "held": self.held_objects()}

    def query_state(self) -> dict:
        """JSON-ready state: target name/kind, ``sim_time_s``, ``arm_qpos``,
        ``gripper_opening_m``, ``tcp`` {position, quat_wxyz}, ``objects`` {name:
        {position, quat_wxyz}} and ``relations`` (as in :meth:`snapshot`)."""
        self._check_open()
        tcp = self.tcp_pose()
        snap = self.snapshot()
        return {"target": self.name, "kind": self.kind, "sim_time_s": self.sim_time,
                "arm_qpos": _floats(self.arm_qpos()), "gripper_opening_m": self.gripper_opening(),
                "tcp": {"position": _floats(tcp[:3, 3]), "quat_wxyz": mat_quat(tcp[:3, :3])},
                "objects": {e["name"]: {"position": e["position"], "quat_wxyz": e["quat_wxyz"]}
                            for e in snap["entities"] if e["kind"] == "object"},
                "relations": snap["relations"]}

    def execute_trajectory(
        self,
        traj,
        *,
        tracking_tol_rad: float = 0.05,
        feedforward: bool = True,
        settle_s: float = 0.5,
        settle_tol_rad: float = 0.005,
    ) -> ExecutionResult:
        """Stream a timed joint trajectory to the arm's position actuators, then settle.

        Each physics step gets ``ctrl = q_ref + (b / kp) * qd_ref`` (linear
        interpolation of the trajectory at the step's end time; ``b`` joint damping and
        ``kp`` actuator gain read from the model).

        Args:
            traj: object with ``t`` (M,) s, ``q`` (M, n) rad and ``qd`` (M, n) rad/s for
                the arm's n joints
                (e.g. :class:`phyagentos.motion.retime.Trajectory`); ``q[0]`` must be
                within ``max(tracking_tol_rad, 0.02)`` rad of the current arm configuration.
            tracking_tol_rad: stop early (``completed=False``, arm held where it is) when
                any joint is farther than this from the reference.
            feedforward: add the damping velocity feed-forward; ``False`` streams bare
                positions (for comparison).
            settle_s: after the last sample, hold the final configuration until the arm is
                within ``settle_tol_rad`` and nearly still, at most this long.
            settle_tol_rad: settling tolerance, rad.

        Returns:
            :class:`ExecutionResult`; ``contacts`` lists unexpected contact pairs (robot
            against anything except a held object in the fingers, or a held object
            against an obstacle).

        Raises:
            TargetError: malformed trajectory or a start far from the current state.
        """
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        self._check_start(Q[0], tracking_tol_rad)
        ts = self._model.opt.timestep
        duration = float(t[-1])
        n = int(math.ceil(duration / ts - 1e-9)) if duration > 0 else 0
        times = np.minimum((np.arange(n) + 1) * ts, duration)
        return self._stream_result(t, Q, QD, times, tracking_tol_rad, feedforward,
                                   then=lambda bad: self.settle(Q[-1], settle_s=settle_s, tol_rad=settle_tol_rad,
                                                                _contacts=bad))

    def _stream_result(self, t, Q, QD, times, tracking_tol_rad, feedforward, *, then=None) -> ExecutionResult:
        """Stream ``Q`` at ``times`` (:meth:`_stream`) and report it; ``then(contacts)``, run
        when the stream completed, returns the control steps it took (e.g. the final settle)."""
        t0 = self._data.time
        bad: set = set()
        completed, max_err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, feedforward, bad)
        if completed and then is not None:
            steps += then(bad)
        return ExecutionResult(
            completed=completed,
            max_tracking_error_rad=max_err,
            sim_time_s=float(self._data.time - t0),
            steps=steps,
            contacts=self._contact_names(bad),
            reason=reason,
        )

    # -- tools ----------------------------------------------------------------------------
    def tools(self) -> tuple[str, ...]:
        """``('observe', 'move_joints', 'set_gripper', 'hold', 'snapshot')``."""
        return self.TOOLS

    def arm_dynamics(self):
        """The arm's :class:`~phyagentos.motion.dynamics.ArmDynamics` for timing motions within
        its actuators' torques, or None (the default: speed and acceleration limits alone
        keep this target's servos on their references)."""
        return None

    def acceleration_limits(self) -> np.ndarray:
        """``(n,)`` rad/s^2 for trajectory timing (default: the motion package's limits)."""
        from phyagentos.motion.retime import DEFAULT_ACCELERATION_LIMITS  # noqa: PLC0415

        return np.array(DEFAULT_ACCELERATION_LIMITS)[: self.n_arm]

    def _tool_observe(self) -> dict:
        return self.query_state()

    def _tool_move_joints(self, q: Sequence[float], tracking_tol_rad: float = 0.05, speed_scale: float = 1.0) -> dict:
        """Straight joint-space move to ``q`` (n,) rad, time-optimal within the velocity
        limits (scaled by ``speed_scale``); no collision checking."""
        from phyagentos.motion.retime import retime  # noqa: PLC0415

        n = self.n_arm
        qg = np.asarray(q, dtype=float).reshape(-1)
        if qg.shape != (n,) or not np.all(np.isfinite(qg)):
            raise TargetError(f"move_joints: q must be {n} finite joint angles, got {q!r}")
        lo = self._model.jnt_range[self._jids, 0]
        hi = self._model.jnt_range[self._jids, 1]
        if np.any(qg < lo) or np.any(qg > hi):
            raise TargetError(f"move_joints: q outside the joint limits {lo.round(3).tolist()} .. {hi.round(3).tolist()}")
        if not 0 < speed_scale <= 1.0:
            raise TargetError(f"move_joints: speed_scale must be in (0, 1], got {speed_scale}")
        traj = retime(np.array([self.arm_qpos(), qg]), vel_limits=self.velocity_limits() * speed_scale,
                      acc_limits=self.acceleration_limits() * speed_scale, dt=self.timestep,
                      dynamics=self.arm_dynamics())
        return self.execute_trajectory(traj, tracking_tol_rad=tracking_tol_rad).to_dict()

    def _tool_set_gripper(self, opening_m: float, settle_s: float = 0.5) -> dict:
        return self.set_gripper(opening_m=opening_m, settle_s=settle_s).to_dict()

    def _tool_hold(self, duration_s: float = 0.5, q: Sequence[float] | None = None) -> dict:
        """Hold ``q`` (default: the current configuration) for ``duration_s`` s."""
        return {"steps": self.hold(q, duration_s=duration_s), "sim_time_s": self.sim_time}

    def _tool_snapshot(self) -> dict:
        return self.snapshot()


class PlansOnTheTabletop(PlansInPerceivedWorld):
    """A tabletop scene's target (mixed in before :class:`MuJoCoArmTarget`, whose
    ``_init_tabletop`` indexed the scene) whose motion planner checks collisions in the world
    its robot perceived (:mod:`phyagentos.primitives.planning_world`)."""

    def planning_bodies(self) -> PlanningBodies:
        """Where perceived things go in a tabletop scene's model, for a planning world built
        from perception (:class:`~phyagentos.targets.contract.PlanningBodies`): the robot's
        joints (every joint under its root body), each declared object's body (its free joint;
        its pose the perceiver's), no fixtures and no slides: the table, walls and bins are the
        scene the user declared, a known workcell; and the scene's spare boxes
        (:data:`~phyagentos.targets.scene.UNSEEN_SLOTS`) for the segments perception could not
        name. Every object of a primitive shape takes the perceived shape and size
        (``perceived_shapes``: a randomised world draws them, so the model's are the
        simulator's, not the robot's). Built once per scene.

        Raises:
            TargetError: the target was not built from a tabletop scene.
        """
        if getattr(self, "_robot_root", None) is None:
            raise TargetError(f"target {self.name!r} has no tabletop scene to plan in")  # type: ignore[attr-defined]
        if self._planning is None:
            from ..scene import UNSEEN_SLOTS, unseen_slot_name  # noqa: PLC0415

            m = self._model  # type: ignore[attr-defined]
            joints = tuple(m.joint(j).name for j in range(m.njnt)
                           if self._is_under(int(m.jnt_bodyid[j]), self._robot_root))  # type: ignore[attr-defined]
            slots = tuple(unseen_slot_name(i) for i in range(UNSEEN_SLOTS)
                          if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, unseen_slot_name(i)) >= 0)
            self._planning = PlanningBodies(robot_joints=joints,
                                            objects={n: m.body(b).name for n, b in self._obj_body.items()},  # type: ignore[attr-defined]
                                            fixtures={}, slides={}, unseen_slots=slots, perceived_shapes=True)
        return self._planning
