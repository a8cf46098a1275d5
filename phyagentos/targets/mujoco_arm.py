"""One base for every simulated MuJoCo arm: scene, sensors, rendering, checkpoints, truth.

:class:`MuJoCoArmTarget` holds what the Franka tabletop
(:class:`~phyagentos.targets.franka_tabletop.MuJoCoTarget`), the SO-101
(:class:`~phyagentos.targets.so101.SO101Target`) and FrankaKitchen
(:class:`~phyagentos.targets.kitchen.FrankaKitchenTarget`) have in common:

- joint bookkeeping (``arm_qpos``, ``tcp_pose``, trajectory validation, hold, halt);
- the tabletop scene's world model (entities and relations of a
  :class:`~phyagentos.targets.scene.SceneSpec`) and the finger-contact bookkeeping;
- sensors: :meth:`capture` renders an RGB-D :class:`~phyagentos.perception.frames.CameraFrame`
  from a model camera with intrinsics from its ``fovy`` and seeded camera noise;
  :meth:`proprioception` reads joints, actuator forces, the gripper and the wrist
  force-torque sensor;
- checkpoints (:meth:`save_state` / :meth:`load_state`, atomic npz with a model fingerprint);
- the privileged ground-truth channel :meth:`ground_truth` (true poses, sizes, masses,
  frictions, contacts), read only by benchmark scoring and tests (CONTRACT_9 section 2).

Units: metres, radians, seconds, kilograms, newtons; poses are (4, 4) world transforms.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import math
import os
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.geometry import matrix_to_quat as mat_quat
from phyagentos.geometry import pose_matrix
from phyagentos.perception.frames import CameraFrame, CameraIntrinsics, Proprioception
from phyagentos.protocol.atomic import atomic_write_bytes

from .base import BaseRolloutTarget
from .camera_noise import CameraNoise
from .contract import ExecutionResult, TargetCapabilities
from .state_file import read_state_npz

__all__ = ["MuJoCoArmTarget", "GripperResult", "pose_matrix", "mat_quat", "K_NONE", "K_ENV", "K_ROBOT", "K_FINGER", "K_OBJECT"]

log = logging.getLogger(__name__)

_STATE_FORMAT = 2
# geom kinds for contact classification
K_NONE, K_ENV, K_ROBOT, K_FINGER, K_OBJECT = 0, 1, 2, 3, 4
#: Camera frame (MuJoCo: x right, y up, looking along -z) -> optical frame (OpenCV:
#: x right, y down, z forward).
_CAM_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])


def _floats(v) -> list[float]:
    return [float(x) for x in np.asarray(v, dtype=float).reshape(-1)]


@dataclass(frozen=True)
class GripperResult:
    """Outcome of :meth:`set_gripper` of a MuJoCo arm target.

    Attributes:
        opening_m: measured opening per finger after settling, metres (0 .. 0.04).
        stalled: the fingers stopped more than 2 mm short of the commanded opening
            (something is between them).
        grasped: name of the object touching both finger pads, else ``None``.
    """

    opening_m: float
    stalled: bool
    grasped: str | None

    def to_dict(self) -> dict[str, Any]:
        return {"opening_m": self.opening_m, "stalled": self.stalled, "grasped": self.grasped}


class MuJoCoArmTarget(BaseRolloutTarget):
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
    #: The gripper's body names for the collision checker; ``None``: the checker's default.
    gripper_body_names: tuple[str, ...] | None = None
    #: For an arm that cannot reach every orientation: position-priority IK accepting
    #: orientations within this tolerance, rad; ``None``: full-pose IK.
    ik_orientation_tol_rad: float | None = None

    # -- construction helpers -----------------------------------------------------------
    def _prepare_scene(self, scene):
        """The physical scene to build: ``scene`` itself, or its randomised world
        (:func:`~phyagentos.targets.world.draw_world`), recorded in :attr:`world_draw`."""
        from .world import draw_world  # noqa: PLC0415

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
        from .scene import FLOOR_GEOM, TABLE_GEOM, object_joint_name  # noqa: PLC0415

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

    # -- contacts (tabletop scenes) -----------------------------------------------------
    def _finger_contacts(self) -> tuple[set[int], set[int]]:
        """Objects (indices) touching finger side 1 and finger side 2."""
        d = self._data
        a_side: set[int] = set()
        b_side: set[int] = set()
        if d.ncon == 0:
            return a_side, b_side
        geoms = d.contact.geom
        dist = d.contact.dist
        for i in range(d.ncon):
            if dist[i] > 1e-4:
                continue
            g0, g1 = int(geoms[i, 0]), int(geoms[i, 1])
            for a, b in ((g0, g1), (g1, g0)):
                o = int(self._gobj[b])
                if o < 0 or not self._gside[a]:
                    continue
                (a_side if self._gside[a] == 1 else b_side).add(o)
        return a_side, b_side

    def held_objects(self) -> tuple[str, ...]:
        """Objects in contact with both finger pads (simulator contacts: ground truth)."""
        left, right = self._finger_contacts()
        return tuple(self._obj_names[i] for i in sorted(left & right))

    def _object_contacts(self) -> list[list[str]]:
        """Sorted pairs of objects touching each other (simulator contacts)."""
        d = self._data
        pairs: set[tuple[str, str]] = set()
        for i in range(d.ncon):
            if d.contact.dist[i] > 1e-4:
                continue
            a, b = int(self._gobj[d.contact.geom[i, 0]]), int(self._gobj[d.contact.geom[i, 1]])
            if a >= 0 and b >= 0 and a != b:
                pairs.add(tuple(sorted((self._obj_names[a], self._obj_names[b]))))  # type: ignore[arg-type]
        return [list(p) for p in sorted(pairs)]

    def _unexpected_matrix(self, held: set[int]) -> np.ndarray:
        """(ngeom, ngeom) bool: True where a contact between the two geoms is unexpected."""
        k = self._gkind
        o = self._gobj
        robotish = (k == K_ROBOT) | (k == K_FINGER)
        collides = k != K_NONE
        U = np.zeros((len(k), len(k)), dtype=bool)
        U |= robotish[:, None] & collides[None, :]
        U |= U.T
        held_mask = np.array([oi in held for oi in o]) & (k == K_OBJECT)
        fingers = k == K_FINGER
        U[np.ix_(fingers, held_mask)] = False
        U[np.ix_(held_mask, fingers)] = False
        obstacles = (k == K_ENV) & ~np.isin(np.arange(len(k)), list(self._support_geoms))
        U[np.ix_(held_mask, obstacles)] = True
        U[np.ix_(obstacles, held_mask)] = True
        return U

    def _unexpected_for_current_grasp(self) -> np.ndarray:
        left, right = self._finger_contacts()
        key = frozenset(left & right)
        U = self._U_cache.get(key)
        if U is None:
            U = self._U_cache[key] = self._unexpected_matrix(set(key))
        return U

    def _collect_contacts(self, U: np.ndarray, bad_pairs: set) -> None:
        d = self._data
        if d.ncon:
            g = d.contact.geom
            hit = U[g[:, 0], g[:, 1]] & (d.contact.dist < 0.0)
            if hit.any():
                for i in np.nonzero(hit)[0]:
                    bad_pairs.add((int(g[i, 0]), int(g[i, 1])))

    def _geom_label(self, g: int) -> str:
        m = self._model
        k = self._gkind[g]
        if k in (K_ROBOT, K_FINGER):
            return m.body(int(m.geom_bodyid[g])).name
        if k == K_OBJECT:
            return self._obj_names[int(self._gobj[g])]
        return m.geom(g).name or m.body(int(m.geom_bodyid[g])).name

    def _contact_names(self, bad_pairs: set) -> tuple[tuple[str, str], ...]:
        out = tuple(sorted({tuple(sorted((self._geom_label(a), self._geom_label(b)))) for a, b in bad_pairs}))
        if out:
            log.info("unexpected contacts during execution: %s", out)
        return out  # type: ignore[return-value]

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

    # -- world model of a tabletop scene (truth) -----------------------------------------
    def _robot_entities(self) -> list[dict]:
        tcp = self.tcp_pose()
        opening = self.gripper_opening()
        return [
            {"name": self.ROBOT, "kind": "robot", "position": [float(c) for c in self.ROBOT_BASE],
             "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": [0.0, 0.0, 0.0],
             "attributes": {"joint_positions": [round(float(q), 6) for q in self.arm_qpos()],
                            "gripper_opening_m": round(opening, 6)}},
            {"name": "tcp", "kind": "robot", "position": _floats(tcp[:3, 3]), "quat_wxyz": mat_quat(tcp[:3, :3]),
             "size": [0.0, 0.0, 0.0]},
            {"name": "gripper", "kind": "gripper", "position": _floats(tcp[:3, 3]), "quat_wxyz": mat_quat(tcp[:3, :3]),
             "size": [opening, 0.0, 0.0], "attributes": {"opening_m": round(opening, 6)}},
        ]

    def _object_bottom_top(self, name: str) -> tuple[float, float]:
        """(bottom z, top z) of an object's bounding box in the world, metres."""
        T = self.object_pose(name)
        he = np.array(self._scene.object(name).half_extents)
        ext = float(np.abs(T[2, :3]) @ he)
        return float(T[2, 3] - ext), float(T[2, 3] + ext)

    def snapshot(self) -> dict:
        """Simulator world state (ground truth), plain Python types only (YAML/JSON ready).

        Returns ``{"sim_time_s": s, "time": s, "entities": [...], "relations": [...]}``.
        Entities: ``{"name", "kind", "position" (3,) m, "quat_wxyz" (4,), "size" (3,),
        "attributes"}`` with ``size`` the half extents in metres, for the arm (kind
        ``robot``, attributes ``joint_positions`` rad and ``gripper_opening_m``), the tcp
        (``name='tcp'``), the gripper (kind ``gripper``, ``size[0]`` = opening per
        finger), every object (kind ``object``, attributes ``shape``), region (kind
        ``region``) and obstacle (kind ``obstacle``); world frame. Relations are
        ``{"subject", "relation", "object"}``:

        - ``gripper holding X``: X touches both finger pads (simulator contacts);
        - ``X on table``: X rests on the table (bottom within 5 mm of z = 0);
        - ``X on R`` (region): X rests on the table and its footprint overlaps R;
        - ``X inside R``: X rests on the table and its centre is inside R's footprint;
        - ``X on Y`` (object): X's bottom is within 6 mm of Y's top and X's centre lies
          over Y's footprint.

        This is the simulator's truth: it goes to ``ground_truth.yaml`` and tests only.
        """
        self._check_open()
        ents = self._robot_entities()
        for o in self._scene.objects:
            T = self.object_pose(o.name)
            ents.append({"name": o.name, "kind": "object", "position": _floats(T[:3, 3]),
                         "quat_wxyz": mat_quat(T[:3, :3]), "size": [float(h) for h in o.half_extents],
                         "attributes": {"shape": o.shape}})
        for r in self._scene.regions:
            ents.append({"name": r.name, "kind": "region", "position": [float(r.center[0]), float(r.center[1]), 0.0],
                         "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                         "size": [float(r.half_extents[0]), float(r.half_extents[1]), 0.0]})
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

    def ground_truth(self) -> dict[str, Any]:
        """The privileged channel: what the simulator knows and no robot measures.

        Returns (YAML-ready) ``{"stamp_s", "objects": {name: {"position" (3,) m,
        "quat_wxyz", "shape", "half_extents" (3,) m, "mass_kg", "friction", "rgba"}},
        "held": [names touching both fingers], "finger_contacts": {"1": [...], "2": [...]},
        "object_contacts": [[a, b], ...], "relations": [...] (as :meth:`snapshot`)}``.
        Mass and friction are read from the live model (after any randomisation).
        Only benchmark scoring and tests read it (CONTRACT_9 section 2).
        """
        self._check_open()
        m = self._model
        objects: dict[str, Any] = {}
        for o in getattr(self._scene, "objects", ()):
            T = self.object_pose(o.name)
            objects[o.name] = {
                "position": _floats(T[:3, 3]), "quat_wxyz": mat_quat(T[:3, :3]), "shape": o.shape,
                "half_extents": [float(h) for h in o.half_extents],
                "mass_kg": float(m.body_mass[self._obj_body[o.name]]),
                "friction": float(m.geom_friction[self._obj_geom[o.name], 0]),
                "rgba": [float(c) for c in o.rgba],
            }
        left, right = self._finger_contacts()
        snap = self.snapshot()
        return {
            "stamp_s": self.sim_time,
            "objects": objects,
            "held": list(self.held_objects()),
            "finger_contacts": {"1": sorted(self._obj_names[i] for i in left),
                                "2": sorted(self._obj_names[i] for i in right)},
            "object_contacts": self._object_contacts(),
            "relations": snap["relations"],
        }

    def scene_record(self) -> dict[str, Any]:
        """The physical scene this target was built from (YAML-ready; masses, frictions,
        poses and, for a randomised world, the draw): for ``ground_truth.yaml`` only."""
        sc = self._scene
        out = sc.to_dict() if hasattr(sc, "to_dict") else {}
        decl = getattr(self, "_declared_scene", None)
        if decl is not None and decl is not sc and hasattr(decl, "to_dict"):
            out["declared"] = decl.to_dict()
        draw = getattr(self, "world_draw", None)
        if draw:
            out = {**out, "draw": draw}
        return out

    def benchmark_signals(self) -> dict[str, Any]:
        """The target's own task-success signals (an external benchmark's checker), for
        ``ground_truth.yaml``'s ``benchmark:``; empty for the tabletop targets."""
        return {}

    def describe_declared(self) -> dict[str, Any]:
        """What the user declared (CONTRACT_9 section 3), YAML-ready: ``{"objects": [{name,
        class?, shape, colour_rgb, size_m}], "regions": [...], "obstacles": [...]}``;
        never mass, friction or pose of an object."""
        sc = getattr(self, "_declared_scene", None) or self._scene
        drawn = bool(getattr(self, "world_draw", None))
        objs = []
        for o in sc.objects:
            d: dict[str, Any] = {"name": o.name, "colour_rgb": [float(c) for c in o.rgba[:3]]}
            if not drawn:  # a randomised object's shape and size are the world's, not the user's
                d["shape"] = o.shape
                d["size_m"] = [round(2.0 * float(h), 4) for h in o.half_extents]
            if o.cls:
                d["class"] = o.cls
            objs.append(d)
        return {
            "objects": objs,
            "regions": [{"name": r.name, "center": [float(c) for c in r.center],
                         "half_extents": [float(h) for h in r.half_extents]} for r in sc.regions],
            "obstacles": [{"name": ob.name, "center": [float(c) for c in ob.center],
                           "half_extents": [float(h) for h in ob.half_extents]} for ob in sc.obstacles],
        }

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

    # -- sensors ------------------------------------------------------------------------
    def configure_sensors(self, sensors: Sequence[Any]) -> None:
        """Install the target's sensor list (:class:`phyagentos.protocol.sensors.SensorSpec`
        items from ``sensors.yaml``). Cameras must name a model camera (``mount.camera``,
        default the sensor name) whose parent body is ``mount.body`` when given; a
        ``fovy_deg`` overrides the model camera's field of view.

        Raises:
            TargetError: a camera the model does not have, a mount body mismatch, or a
                camera larger than the model's offscreen framebuffer (``sensors.yaml`` named).
        """
        m = self._model
        specs = {}
        for s in sensors:
            if s.kind in ("rgbd_camera", "rgb_camera"):
                cam = s.camera_name
                cid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, cam)
                if cid < 0:
                    cams = [m.camera(i).name for i in range(m.ncam)]
                    raise TargetError(f"sensor {s.name!r}: target {self.name!r} has no camera {cam!r}; "
                                      f"cameras: {format_choices(cams)}")
                body = m.body(int(m.cam_bodyid[cid])).name
                if s.mount.body and s.mount.body != body:
                    raise TargetError(f"sensor {s.name!r}: camera {cam!r} is mounted on body {body!r}, "
                                      f"sensors.yaml says {s.mount.body!r}")
                fb_w, fb_h = int(m.vis.global_.offwidth), int(m.vis.global_.offheight)
                if int(s.width) > fb_w or int(s.height) > fb_h:
                    raise TargetError(f"sensors.yaml: camera {s.name!r} of target {self.name!r} is {s.width}x{s.height} "
                                      f"pixels, larger than the model's offscreen framebuffer ({fb_w}x{fb_h}); "
                                      f"use at most {fb_w}x{fb_h}")
                if s.fovy_deg is not None:
                    m.cam_fovy[cid] = float(s.fovy_deg)
            elif s.kind == "force_torque" and self._ft_adr is None:
                raise TargetError(f"sensor {s.name!r}: target {self.name!r} has no wrist force/torque sensor")
            specs[s.name] = s
        self._sensor_specs = specs
        self._camera_noise = {}

    @property
    def sensors(self) -> dict[str, Any]:
        """Installed sensor specs by name (empty until :meth:`configure_sensors`)."""
        return dict(self._sensor_specs)

    def camera_names(self) -> tuple[str, ...]:
        """Names of the configured camera sensors, in sensors.yaml order."""
        return tuple(n for n, s in self._sensor_specs.items() if s.kind in ("rgbd_camera", "rgb_camera"))

    def prepare_cameras(self) -> int:
        """Open the renderers (OpenGL contexts) of the configured cameras now, so the first
        :meth:`capture` does not pay for them (about 0.1-0.3 s each on OSMesa); renders
        nothing and draws no camera noise. Returns how many renderers are open.

        Raises:
            TargetError: no OpenGL backend.
        """
        self._check_open()
        for name in self.camera_names():
            spec = self._sensor_specs[name]
            try:
                self._renderer(int(spec.width), int(spec.height))
            except Exception as exc:
                raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc
        return len(self._renderers)

    def _renderer(self, width: int, height: int):
        key = (int(width), int(height))
        r = self._renderers.get(key)
        if r is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # glfw warns before failing without a display
                r = self._renderers[key] = mujoco.Renderer(self._model, height=height, width=width)
        return r

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
        t0 = self._data.time
        bad: set = set()
        completed, max_err, steps, reason = self._stream(t, Q, QD, times, tracking_tol_rad, feedforward, bad)
        if completed:
            steps += self.settle(Q[-1], settle_s=settle_s, tol_rad=settle_tol_rad, _contacts=bad)
        return ExecutionResult(
            completed=completed,
            max_tracking_error_rad=max_err,
            sim_time_s=float(self._data.time - t0),
            steps=steps,
            contacts=self._contact_names(bad),
            reason=reason,
        )

    def render(self, camera: str = "overview", width: int = 640, height: int = 480, *,
               shadows: bool = True) -> np.ndarray:
        """``(height, width, 3)`` uint8 image from model camera ``camera``; ``shadows=False``
        renders about 5x faster under OSMesa. Raises TargetError if no OpenGL backend is
        available or the camera is unknown."""
        self._check_open()
        m = self._model
        cams = [m.camera(i).name for i in range(m.ncam)]
        if camera not in cams:
            raise TargetError(f"unknown camera {camera!r}; cameras: {format_choices(cams)}")
        try:
            r = self._renderer(width, height)
            r.disable_depth_rendering()
            r.update_scene(self._data, camera=camera, scene_option=self._render_scene_option())
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = bool(shadows)
            return r.render().copy()
        except Exception as exc:
            self._renderers.pop((int(width), int(height)), None)
            raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc

    def _render_scene_option(self) -> mujoco.MjvOption | None:
        """The ``MjvOption`` :meth:`render` draws with (None: MuJoCo's defaults); a target
        whose model carries geoms a camera would not see (collision hulls) overrides it."""
        return None

    def _noise_for(self, spec) -> CameraNoise:
        n = self._camera_noise.get(spec.name)
        if n is None:
            # seeded by the episode and the sensor name: two sensors never share a stream
            seed = [zlib.crc32(spec.name.encode())]
            if self._episode_seed is not None:
                seed.append(abs(int(self._episode_seed)))
            n = self._camera_noise[spec.name] = CameraNoise(spec.noise, np.random.default_rng(seed))
        return n

    @property
    def _capture_option(self) -> mujoco.MjvOption:
        """What a real camera sees: geoms only (no sites, joints or other markers)."""
        opt = getattr(self, "_cap_opt", None)
        if opt is None:
            opt = self._cap_opt = mujoco.MjvOption()
            opt.sitegroup[:] = 0
        return opt

    def capture(self, sensor: str) -> CameraFrame:
        """Render camera sensor ``sensor`` (RGB, and depth for ``rgbd_camera``).

        Returns a :class:`CameraFrame`: intrinsics from the camera's ``fovy``
        (:meth:`CameraIntrinsics.from_fovy`), ``T_world_camera`` the (4, 4) optical frame
        (x right, y down, z forward) in the world, depth in metres along the optical axis
        (MuJoCo's linearised depth buffer; 0 beyond the far plane), with the sensor's seeded
        noise (:class:`~phyagentos.targets.camera_noise.CameraNoise`) applied.

        Raises:
            TargetError: an unknown sensor, a non-camera sensor, or no OpenGL backend.
        """
        self._check_open()
        spec = self._sensor_specs.get(sensor)
        cams = self.camera_names()
        if spec is None or spec.kind not in ("rgbd_camera", "rgb_camera"):
            raise TargetError(f"target {self.name!r} has no camera sensor {sensor!r}; cameras: {format_choices(cams)}")
        m, d = self._model, self._data
        cid = m.camera(spec.camera_name).id
        w, h = int(spec.width), int(spec.height)
        opt = self._capture_option
        try:
            r = self._renderer(w, h)
            r.disable_depth_rendering()
            r.update_scene(d, camera=cid, scene_option=opt)
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            rgb = r.render().copy()
            depth = None
            if spec.kind == "rgbd_camera":
                r.enable_depth_rendering()
                r.update_scene(d, camera=cid, scene_option=opt)
                depth = r.render().astype(np.float32)
                r.disable_depth_rendering()
                far = float(m.vis.map.zfar * m.stat.extent)
                depth[depth >= 0.999 * far] = 0.0
        except Exception as exc:
            self._renderers.pop((w, h), None)
            raise TargetError(f"rendering is not available (no OpenGL backend?): {exc}") from exc
        noise = self._noise_for(spec)
        rgb, depth = noise.apply(rgb, depth)
        T = pose_matrix(d.cam_xpos[cid], d.cam_xmat[cid])
        T[:3, :3] = T[:3, :3] @ _CAM_TO_OPTICAL
        self._frame_count += 1
        return CameraFrame(sensor=spec.name, frame_id=spec.frame_id, stamp_s=self.sim_time,
                           intrinsics=CameraIntrinsics.from_fovy(w, h, float(m.cam_fovy[cid])),
                           T_world_camera=T, rgb=rgb, depth_m=depth)

    def _gripper_effort_n(self) -> float:
        """Finger actuator force, N (squeeze; 0 when free). Subclasses with fingers override."""
        return 0.0

    def wrist_wrench(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``((3,) N, (3,) N m)`` of the wrist force/torque sensor in its site frame, or None."""
        if self._ft_adr is None:
            return None
        f, t = self._ft_adr
        sd = self._data.sensordata
        return sd[f:f + 3].copy(), sd[t:t + 3].copy()

    def _hand_bodies(self) -> list[int]:
        hb = getattr(self, "_hand_body_ids", None)
        if hb is None:
            m = self._model
            root = int(m.site_bodyid[m.site(self.FT_SITE).id])
            hb = self._hand_body_ids = [b for b in range(m.nbody) if self._is_under(b, root)]
        return hb

    def wrist_external_force_n(self) -> np.ndarray | None:
        """``(3,)`` N, world frame: the wrist sensor's force minus what the hand itself
        causes (its weight and inertial forces, predicted from the robot model's inertias
        and the joint accelerations, as payload identification does); i.e. the load of
        whatever the hand carries or pushes. ``None`` without a force sensor.

        Prediction: sum over the bodies distal to the sensor of ``m_i a_i`` (MuJoCo's
        ``mj_objectAcceleration`` at each body's centre of mass, gravity included)."""
        if self._ft_adr is None:
            return None
        m, d = self._model, self._data
        mujoco.mj_rnePostConstraint(m, d)
        mujoco.mj_sensorAcc(m, d)
        site = m.site(self.FT_SITE).id
        f_meas = d.site_xmat[site].reshape(3, 3) @ d.sensordata[self._ft_adr[0]:self._ft_adr[0] + 3]
        pred = np.zeros(3)
        acc = np.zeros(6)
        for b in self._hand_bodies():
            mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_BODY, b, acc, 0)
            pred += m.body_mass[b] * acc[3:]
        return f_meas - pred

    def unloaded_wrist_force_n(self) -> float | None:
        """|f| (N) the wrist sensor reads when the hand holds nothing and is still: the
        weight of everything distal to the sensor site, from the robot model (what a real
        robot's end-effector load configuration states). ``None`` without a sensor."""
        if self._ft_adr is None:
            return None
        m = self._model
        body = int(m.site_bodyid[m.site(self.FT_SITE).id])
        return float(m.body_subtreemass[body]) * float(np.linalg.norm(m.opt.gravity))

    def proprioception(self) -> Proprioception:
        """Joint state, actuator forces, gripper opening and effort, wrist wrench, tcp pose
        (forward kinematics) at the current simulated time."""
        self._check_open()
        d = self._data
        mujoco.mj_rnePostConstraint(self._model, d)  # cfrc_int for the force/torque sensors
        mujoco.mj_sensorAcc(self._model, d)
        ww = self.wrist_wrench()
        return Proprioception(
            stamp_s=self.sim_time, joint_names=self._arm_names, joint_positions=self.arm_qpos(),
            joint_velocities=self.arm_qvel(), joint_efforts=d.actuator_force[self._arm_act].copy(),
            gripper_opening_m=float(self.gripper_opening()), gripper_effort_n=float(self._gripper_effort_n()),
            wrist_force_n=None if ww is None else ww[0], wrist_torque_nm=None if ww is None else ww[1],
            tcp_pose=self.tcp_pose(),
        )

    # -- checkpoints --------------------------------------------------------------------
    def _fingerprint_extra(self) -> dict[str, Any]:
        return {}

    def _fingerprint(self) -> str:
        m = self._model
        scene = self._scene.to_dict() if hasattr(self._scene, "to_dict") else None
        return json.dumps({"robot": self.ROBOT, "nq": m.nq, "nv": m.nv, "nu": m.nu, "na": m.na, "scene": scene,
                           **self._fingerprint_extra()}, sort_keys=True)

    def _state_meta(self) -> dict[str, Any]:
        """Extra JSON-ready state a subclass keeps beside the physics (default none)."""
        return {}

    def _restore_meta(self, meta: dict[str, Any]) -> None:
        """Restore what :meth:`_state_meta` wrote."""

    def _holds_state_of(self, path: Path) -> bool:
        """Whether the live world is exactly the one in the state file at ``path``: this
        target wrote or read that file with the same bytes (SHA-256 of the file) and its
        :meth:`world_digest` has not changed since. Saving to it again or loading it
        would then change nothing."""
        known = self._state_file
        if known is None or known[0] != str(path.absolute()):
            return False
        try:
            content = path.read_bytes()
        except OSError:
            return False
        return known == (str(path.absolute()), hashlib.sha256(content).hexdigest(), self.world_digest())

    def _remember_state_file(self, path: Path, content: bytes) -> None:
        """Record that the live world is the one in ``content``, the bytes of ``path``."""
        self._state_file = (str(path.absolute()), hashlib.sha256(content).hexdigest(), self.world_digest())

    def save_state(self, path: str | os.PathLike) -> Path:
        """Write the simulated state to ``path``: npz with MuJoCo's full integration state,
        ``qpos``/``qvel``/``ctrl``/``act``/``time``, the subclass's metadata and a model
        fingerprint. The write is atomic (temporary file, fsync, rename). Returns the path.

        Writes nothing if the file at ``path`` already holds this world: this target wrote
        or read that file with the same bytes (SHA-256) and its :meth:`world_digest` is
        unchanged since (e.g. the checkpoint before a session's first tick, right after
        the previous session's last one). The file is as durable as that earlier write
        made it (fsynced, or inside a batch that fsyncs it before the batch ends)."""
        self._check_open()
        p = Path(path)
        if self._holds_state_of(p):
            return p
        m, d = self._model, self._data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, full, spec)
        p.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez(buf, format=np.array(_STATE_FORMAT), qpos=d.qpos.copy(), qvel=d.qvel.copy(), ctrl=d.ctrl.copy(),
                 act=d.act.copy(), time=np.array(d.time), full_state=full,
                 meta=np.array(json.dumps({**self._state_meta(), "runtime_notes": self.runtime_notes})),
                 fingerprint=np.array(self._fingerprint()))
        content = buf.getvalue()
        atomic_write_bytes(p, content)
        self._remember_state_file(p, content)
        return p

    def world_digest(self) -> str:
        """A digest of everything :meth:`save_state` keeps (MuJoCo's full integration state,
        the subclass's metadata, ``runtime_notes`` and the model fingerprint): two equal
        digests mean the same simulated world, e.g. before :meth:`save_state` and after
        :meth:`load_state` of that file. Hex string (SHA-256)."""
        self._check_open()
        m, d = self._model, self._data
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, full, spec)
        h = hashlib.sha256(full.tobytes())
        meta = {**self._state_meta(), "runtime_notes": self.runtime_notes}
        h.update(json.dumps(meta, sort_keys=True, default=str).encode())
        h.update(self._fingerprint().encode())
        return h.hexdigest()

    def load_state(self, path: str | os.PathLike) -> None:
        """Restore a state written by :meth:`save_state` for the same scene and robot.
        Raises TargetError if the file is missing, malformed or from another scene.

        If the live world already is the file's (this target wrote or read these very bytes
        and its :meth:`world_digest` is unchanged since; see :meth:`save_state`), nothing
        is parsed or restored: only the derived quantities are recomputed (``mj_forward``), as a
        restore does, so either way the target ends in the same state."""
        self._check_open()
        m, d = self._model, self._data
        p = Path(path)
        if self._holds_state_of(p):
            mujoco.mj_forward(m, d)
            return
        try:
            content = p.read_bytes()
        except OSError:
            content = None  # read_state_npz reports it
        data = read_state_npz(p, content=content)
        if "fingerprint" not in data or str(data["fingerprint"]) != self._fingerprint():
            raise TargetError(f"state file {p} was saved from a different scene or model")
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        full = data.get("full_state")
        if full is not None and full.shape == (mujoco.mj_stateSize(m, spec),):
            mujoco.mj_setState(m, d, full, spec)
        else:
            missing = [k for k in ("qpos", "qvel", "ctrl", "act", "time") if k not in data]
            if missing:
                raise TargetError(f"state file {p} lacks {', '.join(missing)}")
            for k, n in (("qpos", m.nq), ("qvel", m.nv), ("ctrl", m.nu), ("act", m.na)):
                if data[k].shape != (n,):
                    raise TargetError(f"state file {p}: {k} has shape {data[k].shape}, expected ({n},)")
            d.qpos[:], d.qvel[:], d.ctrl[:], d.act[:] = data["qpos"], data["qvel"], data["ctrl"], data["act"]
            d.time = float(data["time"])
        mujoco.mj_forward(m, d)
        self.runtime_notes = {}
        if "meta" in data:
            meta = json.loads(str(data["meta"]))
            self.runtime_notes = dict(meta.pop("runtime_notes", None) or {})
            self._restore_meta(meta)
        self._remember_state_file(p, content)

    # -- tools ----------------------------------------------------------------------------
    def tools(self) -> tuple[str, ...]:
        """``('observe', 'move_joints', 'set_gripper', 'hold', 'snapshot')``."""
        return self.TOOLS

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
                      acc_limits=self.acceleration_limits() * speed_scale, dt=self.timestep)
        return self.execute_trajectory(traj, tracking_tol_rad=tracking_tol_rad).to_dict()

    def _tool_set_gripper(self, opening_m: float, settle_s: float = 0.5) -> dict:
        return self.set_gripper(opening_m=opening_m, settle_s=settle_s).to_dict()

    def _tool_hold(self, duration_s: float = 0.5, q: Sequence[float] | None = None) -> dict:
        """Hold ``q`` (default: the current configuration) for ``duration_s`` s."""
        return {"steps": self.hold(q, duration_s=duration_s), "sim_time_s": self.sim_time}

    def _tool_snapshot(self) -> dict:
        return self.snapshot()
