"""FrankaKitchen from gymnasium-robotics as a rollout target (external benchmark adapter).

The adapter wraps the real environment, ``gymnasium.make("FrankaKitchen-v1")``
(gymnasium-robotics 1.4, D4RL's kitchen): every motion goes through the environment's
own ``step`` (its action semantics, noise and success bookkeeping), and the
environment's own task-completion signal (``info["episode_task_completions"]``:
achieved-goal distance below its ``BONUS_THRESH`` of 0.3) is reported next to our
world snapshot as ``ground_truth``, so the benchmark can set it beside the
SessionVerifier's verdict.

Action bridge (joint trajectory -> environment action). The environment's action is a
normalised joint velocity ``a`` in [-1, 1]^9; it integrates ``ctrl = q_obs + 2 a dt``
from its own (noisy) joint reading ``q_obs`` over one step of ``dt = 0.08 s`` (40
physics steps of 2 ms) and holds that position command on the Franka's position
actuators. For a reference ``q_ref(t)`` the bridge asks for

    ctrl = q_ref(t + dt) + (b / kp) * qd_ref(t + dt) + tau_bias(q) / kp
    a    = clip((ctrl - q_obs) / (2 dt), -1, 1)

(damping feed-forward, and the bias torque ``tau_bias`` (gravity, Coriolis; MuJoCo's
``qfrc_bias``) as a position offset, since the kitchen's arm is not gravity-compensated)

(``b``, ``kp`` read from the model, as for :class:`~phyagentos.targets.franka_tabletop.MuJoCoTarget`);
the fingers get ``a = (opening - q_obs) / (2 dt)``. A command the clip cannot reach in
one step is a tracking error, checked against the caller's tolerance, never silently
repaired.

Tool frame: the environment's model is compiled from its own XML with one massless site
added, ``tcp`` on ``panda0_link7`` at 0.245 m (the same tool frame as the tabletop
target: origin between the fingertip pads, z out of the gripper, y along the finger
motion), so skills use one tool-frame convention on both targets. Sites have no
physics; the environment's dynamics and observations are unchanged.

World frame: the environment's (z up; robot base at (0, 0, 1.8) m, facing +y).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from phyagentos.errors import TargetError, format_choices
from phyagentos.geometry import matrix_to_quat as _quat
from phyagentos.geometry import pose_matrix as _pose

from ..base import ExecutionResult
from ..contract import TargetCapabilities
from ..mujoco_arm import GripperResult, MuJoCoArmTarget

__all__ = ["KitchenScene", "FrankaKitchenTarget", "KITCHEN_TASKS", "ENV_ID"]

log = logging.getLogger(__name__)

ENV_ID = "FrankaKitchen-v1"
#: Tasks the environment can check (its ``OBS_ELEMENT_GOALS`` keys).
KITCHEN_TASKS: tuple[str, ...] = ("microwave", "kettle", "bottom burner", "top burner", "light switch",
                                  "slide cabinet", "hinge cabinet")
ARM_JOINT_NAMES: tuple[str, ...] = tuple(f"robot:panda0_joint{i}" for i in range(1, 8))
FINGER_JOINT_NAMES: tuple[str, ...] = ("robot:panda0_finger_joint1", "robot:panda0_finger_joint2")
FINGER_BODIES: tuple[str, ...] = ("panda0_leftfinger", "panda0_rightfinger")
GRIPPER_MAX_OPENING_M = 0.04
_TCP_OFFSET_M = 0.245  # as the tabletop tcp (phyagentos.targets.scene)
#: Joint speed the bridge plans for, rad/s. The environment accepts 2 rad/s, but its
#: position command is held for a whole 80 ms step, so slower references keep the
#: tracking error (lag ~ qd * dt / 2) near 0.02 rad.
VELOCITY_LIMIT_RAD_S = 0.5

# Entities: kettle (free body) and microwave (door hinge). Geometry from the shipped
# item_assets/kettle_chain.xml and microwave_chain.xml.
_KETTLE_HALF = (0.122, 0.122, 0.1455)     # box around the body and the handle arch, m
_KETTLE_CENTRE_Z = 0.1455                 # above the body origin (its bottom face), m
_KETTLE_HANDLE_HALF = (0.05, 0.032, 0.032)  # graspable stretch of the handle capsule, m
_MICRO_HANDLE_HALF = (0.02, 0.02, 0.10)   # graspable stretch of the vertical door bar, m
_HOOK_CLEARANCE_M = 0.016                 # tcp below the handle's underside when hooking, m
# Burner regions: centres at the kettle's start (bottom left) and at the environment's
# kettle goal position (top left, OBS_ELEMENT_GOALS["kettle"][:2]); surface = the
# kettle's resting height (its body origin), half extents our own acceptance footprint.
_BURNERS = {"bottom_left_burner": (-0.269, 0.35), "top_left_burner": (-0.23, 0.75)}
_BURNER_HALF = (0.08, 0.08)
_BURNER_SURFACE_Z = 1.61523  # the kettle body's resting height in the model's keyframe, m


@dataclass(frozen=True)
class KitchenScene:
    """What a kitchen session asks of the environment.

    Attributes:
        tasks: environment tasks whose completion is the ground truth (:data:`KITCHEN_TASKS`).
        robot_noise_ratio: the environment's joint observation noise scale (its default 0.01).
        object_noise_ratio: the environment's object observation noise scale (default 0.0005).
        max_episode_steps: the environment's horizon in steps of 0.08 s (default 280,
            as registered); completions after it do not count as ground-truth success.
        start_jitter_rad: half width, rad, of a uniform offset added to each of the 7 arm
            joints' start positions at every ``reset(seed=...)``, drawn from the seed (then
            clipped 1 mrad inside the joint range): a randomised robot start, so that
            seeds give different episodes. Default 0.0: the environment's own keyframe.
    """

    tasks: tuple[str, ...] = ("microwave", "kettle")
    robot_noise_ratio: float = 0.01
    object_noise_ratio: float = 0.0005
    max_episode_steps: int = 280
    start_jitter_rad: float = 0.0

    def __post_init__(self) -> None:
        tasks = tuple(self.tasks)
        for t in tasks:
            if t not in KITCHEN_TASKS:
                raise TargetError(f"unknown kitchen task {t!r}; valid tasks: {format_choices(KITCHEN_TASKS)}")
        if not tasks:
            raise TargetError("a kitchen scene needs at least one task")
        object.__setattr__(self, "tasks", tasks)
        for key in ("robot_noise_ratio", "object_noise_ratio"):
            v = float(getattr(self, key))
            if not 0.0 <= v <= 1.0:
                raise TargetError(f"{key} must be in [0, 1], got {v}")
            object.__setattr__(self, key, v)
        jitter = float(self.start_jitter_rad)
        if not 0.0 <= jitter <= 0.5:
            raise TargetError(f"start_jitter_rad must be in [0, 0.5] rad, got {jitter}")
        object.__setattr__(self, "start_jitter_rad", jitter)
        if not isinstance(self.max_episode_steps, int) or self.max_episode_steps < 1:
            raise TargetError(f"max_episode_steps must be an integer >= 1, got {self.max_episode_steps!r}")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> "KitchenScene":
        """Build from plain data; unknown keys raise TargetError listing the valid ones."""
        d = dict(d or {})
        valid = tuple(cls.__dataclass_fields__)
        unknown = set(d) - set(valid)
        if unknown:
            raise TargetError(f"kitchen scene: unknown key(s) {format_choices(unknown)}; valid keys: {format_choices(valid)}")
        if "tasks" in d:
            d["tasks"] = tuple(d["tasks"])
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        return {"tasks": list(self.tasks), "robot_noise_ratio": self.robot_noise_ratio,
                "object_noise_ratio": self.object_noise_ratio, "max_episode_steps": self.max_episode_steps,
                "start_jitter_rad": self.start_jitter_rad}


def _make_env(scene: KitchenScene):
    import gymnasium as gym  # noqa: PLC0415
    import gymnasium_robotics  # noqa: PLC0415

    gym.register_envs(gymnasium_robotics)
    # disable_env_checker: gymnasium's passive checker only warns (observation buffers
    # shared between steps, which this adapter never keeps); the environment is unchanged.
    return gym.make(ENV_ID, tasks_to_complete=list(scene.tasks), terminate_on_tasks_completed=False,
                    remove_task_when_completed=False, robot_noise_ratio=scene.robot_noise_ratio,
                    object_noise_ratio=scene.object_noise_ratio, max_episode_steps=scene.max_episode_steps,
                    disable_env_checker=True)


def _with_tcp_site(env) -> None:
    """Recompile the environment's model from its own XML with the ``tcp`` site added and
    install it in the environment (model, data, name tables, renderer)."""
    from gymnasium.envs.mujoco.mujoco_rendering import MujocoRenderer  # noqa: PLC0415
    from gymnasium_robotics.utils.mujoco_utils import MujocoModelNames  # noqa: PLC0415

    robot = env.unwrapped.robot_env
    spec = mujoco.MjSpec.from_file(robot.fullpath)
    half = -math.pi / 8.0  # site yaw -pi/4 about link7 z, as the tabletop tcp
    spec.body("panda0_link7").add_site(name="tcp", pos=[0.0, 0.0, _TCP_OFFSET_M],
                                       quat=[math.cos(half), 0.0, 0.0, math.sin(half)], size=[0.006, 0, 0], group=4)
    model = spec.compile()
    old = robot.model
    if (model.nq, model.nv, model.nu, model.nbody, model.ngeom) != (old.nq, old.nv, old.nu, old.nbody, old.ngeom):
        raise TargetError("adding the tcp site changed the kitchen model's structure")  # pragma: no cover
    model.vis.global_.offwidth = old.vis.global_.offwidth
    model.vis.global_.offheight = old.vis.global_.offheight
    data = mujoco.MjData(model)
    robot.mujoco_renderer.close()
    robot.model, robot.data = model, data
    robot.model_names = MujocoModelNames(model)
    robot.init_qvel = np.zeros(model.nv)
    robot.mujoco_renderer = MujocoRenderer(model, data, None, robot.width, robot.height)
    env.unwrapped.model, env.unwrapped.data = model, data


class FrankaKitchenTarget(MuJoCoArmTarget):
    """The FrankaKitchen environment behind the rollout-target contract.

    Args:
        name: target name (TARGETS.md).
        scene: a :class:`KitchenScene`.
        seed: seeds the environment (``env.reset(seed=...)``: its observation noise).

    Raises:
        TargetError: gymnasium-robotics missing, or the environment does not build.

    Class attributes (read by preflight without constructing a target): ``KIND``,
    ``TOOLS``, ``ACTION_FORMS``.
    """

    ROBOT = "panda"
    CAPABILITIES = TargetCapabilities(action_forms=("joint_trajectory", "gripper_command"),
                                      sensors=("proprioception", "rgb", "contacts"), simulated_ground_truth=True,
                                      articulated_fixtures=True)
    SENSORS_KEY = "franka_kitchen"
    ROBOT_BASE = (0.0, 0.0, 1.8)

    @classmethod
    def scene_from_dict(cls, raw: Mapping[str, Any] | None, *, root: Any = None) -> KitchenScene:
        """The scene type of this driver (used by the target pool); ``root`` is unused
        (a kitchen scene names no files)."""
        return KitchenScene.from_dict(raw)

    def __init__(self, name: str, scene: KitchenScene | None = None, *, seed: int | None = None):
        super().__init__(name, "simulation")
        scene = scene if scene is not None else KitchenScene()
        if not isinstance(scene, KitchenScene):
            raise TargetError(f"scene must be a KitchenScene, got {type(scene).__name__}")
        self._scene = scene
        try:
            self._env = _make_env(scene)
            _with_tcp_site(self._env)
        except TargetError:
            raise
        except Exception as exc:  # gymnasium / gymnasium-robotics / mujoco errors
            raise TargetError(f"{ENV_ID} does not build: {type(exc).__name__}: {exc}") from exc
        u = self._env.unwrapped
        self._robot = u.robot_env
        m = self._robot.model
        self._init_arm(m, self._robot.data, ARM_JOINT_NAMES, tcp_site="tcp", arm_actuators=list(range(7)), seed=seed)
        self._finger_qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in FINGER_JOINT_NAMES])
        self._finger_bodies = {m.body(n).id for n in FINGER_BODIES}
        kettle_root = m.body("kettle").id
        door = m.body("microdoorroot").id
        self._geom_entity: dict[int, str] = {}
        for g in range(m.ngeom):
            b = int(m.geom_bodyid[g])
            while b > 0:
                if b == kettle_root:
                    self._geom_entity[g] = "kettle"
                    break
                if b == door:
                    self._geom_entity[g] = "microwave"
                    break
                b = int(m.body_parentid[b])
        self._micro_joint = m.joint("microwave").id
        self._steps = 0
        self._completed: dict[str, int] = {}
        self._q_cmd = np.zeros(7)
        self._finger_cmd = GRIPPER_MAX_OPENING_M
        self._track_clock = 0.0
        self._seed = seed
        self.reset(seed=seed)

    # -- accessors (the motion primitives' view) ---------------------------------------
    @property
    def env(self):
        """The wrapped gymnasium environment (read-only use)."""
        return self._env

    @property
    def timestep(self) -> float:
        """Physics step of the model, s (0.002; an environment step is 40 of them)."""
        return float(self.model.opt.timestep)

    @property
    def env_dt(self) -> float:
        """Seconds per environment step (0.08)."""
        return float(self._robot.dt)

    def _gripper_effort_n(self) -> float:
        """Squeeze of the two finger actuators (ids 7, 8), N per finger."""
        return float(max(0.0, -np.mean(self.data.actuator_force[7:9])))

    def gripper_opening(self) -> float:
        """Opening per finger, m (0 .. 0.04)."""
        return float(np.mean(self.data.qpos[self._finger_qadr]))

    @property
    def allowed_collision_pairs(self) -> tuple[tuple[str, str], ...]:
        """Robot body pairs allowed to touch in collision checking: consecutive links and
        the hand's parts (the environment's model does not exclude them)."""
        links = [f"panda0_link{i}" for i in range(8)]
        pairs = list(zip(links[:-1], links[1:]))
        pairs += [("panda0_link7", f) for f in FINGER_BODIES] + [FINGER_BODIES]
        return tuple(pairs)

    def object_pose(self, name: str) -> np.ndarray:
        """``(4, 4)`` world pose of a free object's body (``kettle``); TargetError otherwise."""
        if name != "kettle":
            raise TargetError(f"unknown free object {name!r}; objects: 'kettle'")
        b = self.data.body("kettle")
        return _pose(b.xpos, b.xmat)

    def velocity_limits(self) -> np.ndarray:
        """``(7,)`` rad/s the bridge plans with (:data:`VELOCITY_LIMIT_RAD_S`)."""
        return np.full(7, VELOCITY_LIMIT_RAD_S)

    # -- lifecycle --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None) -> dict:
        """The environment's own reset (its initial state and noise seed), then one settling
        step (see the comment); the step counter restarts at 0. Returns :meth:`observe`."""
        self._check_open()
        self._env.reset(seed=seed)
        self._steps = 0
        self._completed = {}
        # The environment's initial arm configuration has joint 2 at -1.7685 rad, 5.7 mrad
        # beyond the model's range: one environment step holding its projection into the
        # range settles it there, so every command starts from an admissible state.
        lo, hi = self.model.jnt_range[self._jids, 0], self.model.jnt_range[self._jids, 1]
        if self._scene.start_jitter_rad > 0.0:
            # randomised robot start (KitchenScene.start_jitter_rad), from the reset seed
            j = self._scene.start_jitter_rad
            offset = np.random.default_rng(seed).uniform(-j, j, size=len(self._jids))
            self.data.qpos[self._qadr] = np.clip(self.arm_qpos() + offset, lo + 1e-3, hi - 1e-3)
            self.data.qvel[self._dadr] = 0.0
            mujoco.mj_forward(self.model, self.data)
        self._finger_cmd = self.gripper_opening()
        self._env_step(np.clip(self.arm_qpos(), lo + 1e-3, hi - 1e-3), np.zeros(7))
        self._steps = 0
        self._completed = {}
        return self.observe()

    def close(self) -> None:
        if not self.closed:
            try:
                self._env.close()
            except Exception:  # noqa: BLE001 - pragma: no cover - renderer teardown
                pass
        super().close()

    # -- the action bridge ------------------------------------------------------------
    def _env_step(self, q_ref: np.ndarray, qd_ref: np.ndarray) -> None:
        robot = self._robot
        dt = robot.dt
        q_obs = np.asarray(robot._last_robot_qpos, dtype=float)  # what the env integrates from
        # The kitchen's arm has no gravity compensation: add the bias torque (gravity and
        # Coriolis at the current state) as a position offset tau / kp.
        bias = self.data.qfrc_bias[self._dadr] / self._kp
        ctrl = q_ref + self._ff_gain * qd_ref + bias
        arm = (ctrl - q_obs[:7]) / (robot.act_rng[:7] * dt)
        fingers = (self._finger_cmd - q_obs[7:9]) / (robot.act_rng[7:9] * dt)
        action = np.clip(np.concatenate([arm, fingers]), -1.0, 1.0)
        _, _, _, _, info = self._env.step(action)
        self._steps += 1
        self._q_cmd = np.asarray(q_ref, dtype=float).copy()
        for task in info.get("episode_task_completions", []):
            self._completed.setdefault(task, self._steps)

    def track(self, traj, *, t_start: float, t_end: float, tracking_tol_rad: float = 0.05,
              feedforward: bool = True) -> ExecutionResult:
        """Advance the environment through ``(t_start, t_end]`` of ``traj`` (s on its clock),
        one environment step (0.08 s) at a time; a remainder shorter than a step is
        carried to the next call. Stops early (``completed=False``) when a joint is more
        than ``tracking_tol_rad`` from the reference at a step's end."""
        self._check_open()
        t, Q, QD = self._traj_arrays(traj)
        duration = float(t[-1])
        if t_start <= 0.0:
            self._track_clock = 0.0
            start_err = float(np.max(np.abs(Q[0] - self.arm_qpos())))
            if start_err > max(tracking_tol_rad, 0.02):
                raise TargetError(f"trajectory starts {start_err:.3f} rad from the current arm configuration")
        dt = self.env_dt
        t_end = min(float(t_end), duration)
        t0 = self.sim_time
        max_err, steps = 0.0, 0
        while self._track_clock < duration - 1e-9 and (self._track_clock + dt <= t_end + 1e-9 or t_end >= duration - 1e-9):
            t_next = min(self._track_clock + dt, duration)
            q_ref = np.array([np.interp(t_next, t, Q[:, j]) for j in range(7)])
            qd_ref = np.array([np.interp(t_next, t, QD[:, j]) for j in range(7)]) if feedforward else np.zeros(7)
            self._env_step(q_ref, qd_ref)
            steps += 1
            self._track_clock = t_next
            err = float(np.max(np.abs(self.arm_qpos() - q_ref)))
            max_err = max(max_err, err)
            if err > tracking_tol_rad:
                self._q_cmd = self.arm_qpos()
                return ExecutionResult(False, max_err, self.sim_time - t0, steps,
                                       reason=f"tracking error {err:.4f} rad exceeded {tracking_tol_rad:.4f} rad "
                                              f"at t={t_next:.2f} s of {duration:.2f} s")
        return ExecutionResult(True, max_err, self.sim_time - t0, steps)

    def execute_trajectory(self, traj, *, tracking_tol_rad: float = 0.05) -> ExecutionResult:
        """Stream the whole trajectory (see :meth:`track`), then :meth:`settle` at its end."""
        t, Q, _ = self._traj_arrays(traj)
        result = self.track(traj, t_start=0.0, t_end=float(t[-1]), tracking_tol_rad=tracking_tol_rad)
        if result.completed:
            self.settle(Q[-1])
        return result

    def settle(self, q: Sequence[float] | None = None, *, settle_s: float = 0.5, tol_rad: float = 0.01) -> int:
        """Command ``q`` (7,) rad (default: the last command) until within ``tol_rad``, at
        most ``settle_s`` seconds of environment time. Returns environment steps taken."""
        self._check_open()
        target = self._q_cmd.copy() if q is None else np.asarray(q, dtype=float).reshape(-1)
        if target.shape != (7,):
            raise TargetError(f"settle: q must have shape (7,), got {target.shape}")
        n = 0
        for _ in range(max(1, int(round(settle_s / self.env_dt)))):
            self._env_step(target, np.zeros(7))
            n += 1
            if float(np.max(np.abs(self.arm_qpos() - target))) < tol_rad:
                break
        return n

    def hold(self, q: Sequence[float] | None = None, *, duration_s: float) -> int:
        """Hold ``q`` (default: the last command) for ``duration_s`` s (whole env steps)."""
        self._check_open()
        target = self._q_cmd.copy() if q is None else np.asarray(q, dtype=float).reshape(-1)
        if target.shape != (7,) or not np.all(np.isfinite(target)):
            raise TargetError(f"hold: q must be 7 finite joint angles, got {q!r}")
        n = int(math.ceil(float(duration_s) / self.env_dt - 1e-9))
        for _ in range(n):
            self._env_step(target, np.zeros(7))
        return n

    def halt(self) -> None:
        """Command the arm to stay where it is (applied from the next step on)."""
        if not self.closed:
            self._q_cmd = self.arm_qpos()

    def step(self, ctrl) -> None:
        """One environment step with the environment's own action ``ctrl`` (9,) in [-1, 1]."""
        self._check_open()
        a = np.asarray(ctrl, dtype=float).reshape(-1)
        if a.shape != (9,) or not np.all(np.isfinite(a)):
            raise TargetError(f"ctrl must be 9 finite normalised joint velocities, got shape {a.shape}")
        _, _, _, _, info = self._env.step(np.clip(a, -1.0, 1.0))
        self._steps += 1
        for task in info.get("episode_task_completions", []):
            self._completed.setdefault(task, self._steps)
        self._q_cmd = self.arm_qpos()

    def set_gripper(self, *, opening_m: float, settle_s: float = 0.5) -> GripperResult:
        """Drive both fingers to ``opening_m`` (0 .. 0.04 m per finger) until they stop
        (at least 2, at most ``settle_s / 0.08`` environment steps), arm held."""
        self._check_open()
        o = float(opening_m)
        if not (0.0 <= o <= GRIPPER_MAX_OPENING_M + 1e-9):
            raise TargetError(f"opening_m must be in [0, {GRIPPER_MAX_OPENING_M}] m, got {opening_m}")
        self._finger_cmd = o
        prev = self.gripper_opening()
        for k in range(max(2, int(round(settle_s / self.env_dt)))):
            self._env_step(self._q_cmd, np.zeros(7))
            now = self.gripper_opening()
            if k >= 1 and abs(now - prev) < 2e-4:
                break
            prev = now
        opening = self.gripper_opening()
        return GripperResult(opening_m=opening, stalled=abs(opening - o) > 0.002)

    # -- contacts and observation -----------------------------------------------------
    def held_objects(self) -> tuple[str, ...]:
        """Entities (``kettle``, ``microwave``) touching both fingers."""
        m, d = self.model, self.data
        touch: dict[str, set[int]] = {}
        for i in range(d.ncon):
            c = d.contact[i]
            if c.dist > c.includemargin + 1e-4:  # the kitchen's geoms carry margins
                continue
            g0, g1 = int(c.geom[0]), int(c.geom[1])
            for a, b in ((g0, g1), (g1, g0)):
                body = int(m.geom_bodyid[a])
                ent = self._geom_entity.get(b)
                if body in self._finger_bodies and ent is not None:
                    touch.setdefault(ent, set()).add(body)
        return tuple(sorted(e for e, bodies in touch.items() if len(bodies) == 2))

    def ground_truth(self) -> dict[str, Any]:
        """The privileged channel (YAML-ready): ``stamp_s``, the kettle's true pose
        (``objects``), the microwave door angle (``articulations``, rad), ``held``
        (simulator finger contacts) and ``benchmark`` (:meth:`benchmark_signals`)."""
        self._check_open()
        kb = self.data.body("kettle")
        j = self._micro_joint
        return {
            "stamp_s": self.sim_time,
            "objects": {"kettle": {"position": [float(x) for x in kb.xpos], "quat_wxyz": _quat(kb.xmat.reshape(3, 3))}},
            "articulations": {"microwave": {"joint_position": float(self.data.qpos[self.model.jnt_qposadr[j]])}},
            "held": list(self.held_objects()),
            "benchmark": self.benchmark_signals(),
        }

    def benchmark_signals(self) -> dict[str, Any]:
        """The environment's own verdict: tasks it counted complete and at which step."""
        horizon = self._scene.max_episode_steps
        tasks = {t: (t in self._completed and self._completed[t] <= horizon) for t in self._scene.tasks}
        return {
            "source": f"gymnasium-robotics {ENV_ID}: info['episode_task_completions'] (goal distance < 0.3)",
            "task": "+".join(self._scene.tasks),
            "tasks": tasks,
            "completed_at_step": {t: s for t, s in self._completed.items()},
            "env_steps": self._steps,
            "horizon_steps": horizon,
            "success": all(tasks.values()),
        }

    def snapshot(self) -> dict:
        """Simulator world state (YAML-ready; ground truth, for ``ground_truth.yaml`` and tests).

        Entities: ``panda`` (robot; attributes ``joint_positions`` (7,) rad,
        ``gripper_opening_m``), ``tcp``, ``gripper``, ``kettle`` (object: centre and
        half extents of a box around body and handle; ``attributes.grasp`` the handle's
        graspable stretch as a box pose/size, approached from above; ``attributes.hook``
        the point under the handle where closed fingers slid in horizontally carry the
        kettle on their top face, for grippers too weak to lift it by friction), ``microwave``
        (kind ``articulation``: door pose; attributes ``joint_position`` rad (0 closed,
        negative opening), ``joint_range``, hinge ``anchor`` and ``axis`` (world), and
        ``grasp``: the vertical door bar, approached along the door's inward normal
        (``approach``) with the fingers closing across it (``closing``), round about its
        vertical ``free_axis``: the only approach the arm reaches and the microwave's own
        panel leaves free, so the pull is held by finger friction alone), and the burner
        regions. Relations: ``gripper holding X``.
        """
        self._check_open()
        d = self.data
        tcp = self.tcp_pose()
        opening = self.gripper_opening()
        ents: list[dict] = [
            {"name": "panda", "kind": "robot", "position": [0.0, 0.0, 1.8], "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
             "size": [0.0, 0.0, 0.0], "attributes": {"joint_positions": [round(float(q), 6) for q in self.arm_qpos()],
                                                    "gripper_opening_m": round(opening, 6)}},
            {"name": "tcp", "kind": "robot", "position": [float(x) for x in tcp[:3, 3]], "quat_wxyz": _quat(tcp[:3, :3]),
             "size": [0.0, 0.0, 0.0]},
            {"name": "gripper", "kind": "gripper", "position": [float(x) for x in tcp[:3, 3]],
             "quat_wxyz": _quat(tcp[:3, :3]), "size": [opening, 0.0, 0.0], "attributes": {"opening_m": round(opening, 6)}},
        ]
        kb = d.body("kettle")
        Rk = kb.xmat.reshape(3, 3)
        centre = kb.xpos + Rk @ np.array([0.0, 0.0, _KETTLE_CENTRE_Z])
        handle = d.site("kettle_site")
        # hook point: closed fingers slid under the handle arch (bar radius + half the
        # closed fingers' 3 cm height below the bar's axis), carrying it on their top face
        hook = handle.xpos - Rk[:, 2] * (_KETTLE_HANDLE_HALF[2] + _HOOK_CLEARANCE_M)
        ents.append({"name": "kettle", "kind": "object", "position": [float(x) for x in centre], "quat_wxyz": _quat(Rk),
                     "size": list(_KETTLE_HALF),
                     "attributes": {"grasp": {"position": [float(x) for x in handle.xpos], "quat_wxyz": _quat(Rk),
                                              "size": list(_KETTLE_HANDLE_HALF)},
                                    "hook": {"position": [float(x) for x in hook], "quat_wxyz": _quat(Rk),
                                             "size": list(_KETTLE_HANDLE_HALF),
                                             "approach": [float(x) for x in Rk[:, 1]],
                                             "closing": [float(x) for x in Rk[:, 0]]}}})
        door = d.body("microdoorroot")
        Rd = door.xmat.reshape(3, 3)
        bar = d.site("microhandle_site")
        j = self._micro_joint
        ents.append({"name": "microwave", "kind": "articulation", "position": [float(x) for x in door.xpos],
                     "quat_wxyz": _quat(Rd), "size": [0.26, 0.025, 0.19],
                     "attributes": {"joint": "microwave", "joint_type": "hinge",
                                    "joint_position": float(d.qpos[self.model.jnt_qposadr[j]]),
                                    "joint_range": [float(x) for x in self.model.jnt_range[j]],
                                    "anchor": [float(x) for x in d.xanchor[j]], "axis": [float(x) for x in d.xaxis[j]],
                                    "grasp": {"position": [float(x) for x in bar.xpos], "quat_wxyz": _quat(Rd),
                                              "size": list(_MICRO_HANDLE_HALF),
                                              "approach": [float(x) for x in Rd[:, 1]],
                                              "closing": [float(x) for x in Rd[:, 0]],
                                              "free_axis": [float(x) for x in Rd[:, 2]]}}})
        for name, (x, y) in _BURNERS.items():
            ents.append({"name": name, "kind": "region", "position": [x, y, _BURNER_SURFACE_Z], "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
                         "size": [_BURNER_HALF[0], _BURNER_HALF[1], 0.0]})
        rel = [{"subject": "gripper", "relation": "holding", "object": n} for n in self.held_objects()]
        return {"sim_time_s": float(d.time), "time": float(d.time), "entities": ents, "relations": rel}

    def observe(self) -> dict:
        """Observation: ``time``, ``arm_qpos`` (7,), ``gripper_opening_m``, ``tcp_pose`` (4, 4),
        ``qpos`` (nq,), ``held``, ``env_steps``."""
        self._check_open()
        return {"time": self.sim_time, "arm_qpos": self.arm_qpos(), "gripper_opening_m": self.gripper_opening(),
                "tcp_pose": self.tcp_pose(), "qpos": self.data.qpos.copy(), "held": self.held_objects(),
                "env_steps": self._steps}

    def query_state(self) -> dict:
        snap = self.snapshot()
        return {"target": self.name, "kind": self.kind, "sim_time_s": self.sim_time,
                "arm_qpos": [float(x) for x in self.arm_qpos()], "gripper_opening_m": self.gripper_opening(),
                "relations": snap["relations"]}

    # -- persistence ----------------------------------------------------------------
    def _fingerprint_extra(self) -> dict[str, Any]:
        return {"env": ENV_ID}

    def _state_meta(self) -> dict[str, Any]:
        """The environment's bookkeeping beside the physics: steps, completions, commands."""
        return {"steps": self._steps, "completed": self._completed, "q_cmd": self._q_cmd.tolist(),
                "finger_cmd": self._finger_cmd,
                "last_robot_qpos": np.asarray(self._robot._last_robot_qpos, dtype=float).tolist()}

    def _restore_meta(self, meta: dict[str, Any]) -> None:
        self._steps = int(meta["steps"])
        self._completed = {k: int(v) for k, v in meta["completed"].items()}
        self._q_cmd = np.asarray(meta["q_cmd"], dtype=float)
        self._finger_cmd = float(meta["finger_cmd"])
        self._robot._last_robot_qpos = np.asarray(meta["last_robot_qpos"], dtype=float)
        u = self._env.unwrapped
        u.episode_task_completions[:] = list(self._completed)

    # -- tools ----------------------------------------------------------------------
