"""A real controller served as a policy: top-down reaching and grasping with mink.

It plays the role a VLA plays in the policy flow (observation in, joint action chunk
out) with a model-based controller, so the whole flow runs on this machine. Like a
VLA it is stateless: each call decides from the observation alone which phase the
task is in and returns the next ``horizon`` joint targets at ``rate_hz``.

Observation (openpi-style keys)::

    prompt                               str, e.g. "pick up the cube"
    observation/joint_position           (7,) float32, rad
    observation/joint_velocity           (7,) float32, rad/s
    observation/gripper_position         (1,) float32, 0 open .. 1 closed
    observation/object_pose              (7,) float32, object centre [x y z qw qx qy qz], world
    observation/object_half_extents      (3,) float32, m
    observation/image                    (224, 224, 3) uint8, optional (checked, unused)

Action: ``{"actions": (horizon, 8) float32}``: 7 absolute joint positions (rad) and the
gripper (0 open .. 1 closed) per step, plus ``phase`` and ``done``.

Phases, judged from the observation: *approach* the pre-grasp pose above the object,
*descend* straight down to the grasp, *close* the fingers, *lift* by ``lift_m``, *open*
(fingers closed on nothing: release and start again), *done* (lifted). Each phase
moves the tcp along a straight line with a trapezoidal speed profile (``max_speed``,
``max_accel``, starting from the measured tcp speed and stopping at the goal); every
waypoint is solved with mink IK (:func:`phyagentos.motion.ik.solve_ik`), warm-started
from the previous one. Grasp geometry: :func:`phyagentos.motion.grasp.top_down_grasp`.
The table top is z = 0 (the project's world convention), so "lifted" needs no memory.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import mujoco
import numpy as np

from phyagentos.errors import IKError
from phyagentos.motion.cartesian import interpolate_pose
from phyagentos.motion.grasp import hand_yaw, top_down_grasp
from phyagentos.motion.ik import solve_ik
from phyagentos.targets.scene import ARM_JOINT_NAMES, TCP_SITE, SceneSpec, build_scene

__all__ = ["GraspPolicy", "OBSERVATION_KEYS"]

logger = logging.getLogger(__name__)

#: Input keys -> (dtype, shape); ``None`` in a shape: any size.
OBSERVATION_KEYS: dict[str, tuple[str, tuple]] = {
    "observation/joint_position": ("float32", (7,)),
    "observation/joint_velocity": ("float32", (7,)),
    "observation/gripper_position": ("float32", (1,)),
    "observation/object_pose": ("float32", (7,)),
    "observation/object_half_extents": ("float32", (3,)),
}
_OPTIONAL_KEYS = {"observation/image": ("uint8", (224, 224, 3))}


class GraspPolicy:
    """Reach-and-grasp controller producing joint-position action chunks.

    Args:
        rate_hz: action rate, Hz.
        horizon: actions per chunk.
        approach_height_m: pre-grasp height above the grasp, m.
        lift_m: lift height of the object centre above its resting height, m.
        max_speed_m_s: tcp speed limit while approaching, m/s (a third of it near contact).
        max_accel_m_s2: tcp acceleration limit, m/s^2.
    """

    def __init__(self, *, rate_hz: float = 20.0, horizon: int = 10, approach_height_m: float = 0.10,
                 lift_m: float = 0.15, max_speed_m_s: float = 0.15, max_accel_m_s2: float = 0.4):
        if rate_hz <= 0 or horizon < 1:
            raise ValueError(f"rate_hz must be > 0 and horizon >= 1, got {rate_hz}, {horizon}")
        self.rate_hz, self.horizon = float(rate_hz), int(horizon)
        self.approach_height_m, self.lift_m = approach_height_m, lift_m
        self.max_speed, self.max_accel = max_speed_m_s, max_accel_m_s2
        self.model = build_scene(SceneSpec())  # the arm on its table, nothing else
        self._data = mujoco.MjData(self.model)
        self._qadr = np.array([self.model.jnt_qposadr[self.model.joint(n).id] for n in ARM_JOINT_NAMES])
        self._site = self.model.site(TCP_SITE).id
        self.metadata: dict[str, Any] = {
            "policy": "phyagentos.grasp_policy",
            "description": "top-down reach and grasp (mink IK, trapezoidal tcp profiles)",
            "action": {"space": "joint_position", "joint_names": list(ARM_JOINT_NAMES), "units": "rad",
                       "frame": "joint", "gripper": "normalized_closed", "rate_hz": self.rate_hz, "padding": 0},
            "action_horizon": self.horizon,
            "inputs": {k: {"dtype": d, "shape": list(s)} for k, (d, s) in OBSERVATION_KEYS.items()},
            "optional_inputs": {k: {"dtype": d, "shape": list(s)} for k, (d, s) in _OPTIONAL_KEYS.items()},
        }

    # -- kinematics -------------------------------------------------------------------
    def _tcp(self, q: np.ndarray) -> np.ndarray:
        d = self._data
        d.qpos[self._qadr] = q
        mujoco.mj_kinematics(self.model, d)
        T = np.eye(4)
        T[:3, 3] = d.site_xpos[self._site]
        T[:3, :3] = d.site_xmat[self._site].reshape(3, 3)
        return T

    # -- observation --------------------------------------------------------------------
    @staticmethod
    def _check(obs: dict[str, Any]) -> None:
        for key, (dtype, shape) in {**OBSERVATION_KEYS, **_OPTIONAL_KEYS}.items():
            if key not in obs:
                if key in OBSERVATION_KEYS:
                    raise ValueError(f"observation lacks {key!r}; required: {sorted(OBSERVATION_KEYS)}")
                continue
            v = obs[key]
            if not isinstance(v, np.ndarray) or v.dtype != np.dtype(dtype) or v.shape != shape:
                got = (getattr(v, "dtype", type(v).__name__), getattr(v, "shape", None))
                raise ValueError(f"observation {key!r} must be {dtype} {shape}, got {got}")
            if v.dtype.kind == "f" and not np.all(np.isfinite(v)):
                raise ValueError(f"observation {key!r} is not finite")
        if not isinstance(obs.get("prompt", ""), str):
            raise ValueError("observation 'prompt' must be a string")

    # -- the controller -----------------------------------------------------------------
    def infer(self, obs: dict[str, Any]) -> dict[str, Any]:
        """One chunk of actions for ``obs`` (see the module docstring for the keys).

        Raises:
            ValueError: a missing or malformed observation key.
        """
        self._check(obs)
        q = obs["observation/joint_position"].astype(float)
        qd = obs["observation/joint_velocity"].astype(float)
        g = float(obs["observation/gripper_position"][0])
        pose = obs["observation/object_pose"].astype(float)
        he = obs["observation/object_half_extents"].astype(float)
        T_obj = np.eye(4)
        T_obj[:3, 3] = pose[:3]
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, pose[3:] / np.linalg.norm(pose[3:]))
        T_obj[:3, :3] = R.reshape(3, 3)
        T = self._tcp(q)
        v_tcp = (self._tcp(q + 1e-4 * qd)[:3, 3] - T[:3, 3]) / 1e-4
        plan = top_down_grasp(T_obj, he, approach_height_m=self.approach_height_m, current_yaw_rad=hand_yaw(T),
                              current_q7_rad=q[6], support_z_m=0.0)
        err_grasp = np.linalg.norm(T[:3, 3] - plan.grasp[:3, 3])
        xy_err = np.linalg.norm(T[:2, 3] - plan.grasp[:2, 3])
        ori_err = _angle(T[:3, :3], plan.grasp[:3, :3])
        between_fingers = np.linalg.norm(pose[:3] - T[:3, 3]) < 0.03
        speed = self.max_speed
        if g > 0.3 and between_fingers:
            goal = T.copy()
            goal[2, 3] = T[2, 3] - pose[2] + he[2] + self.lift_m  # the held object keeps its offset
            lifted = pose[2] - he[2] >= self.lift_m - 0.01
            phase, grip = ("done" if lifted else "lift"), 1.0
            speed = self.max_speed / 2
        elif g > 0.3:
            phase, grip, goal = "open", 0.0, T  # closed on nothing: release, then start over
        elif err_grasp < 0.006 and ori_err < 0.05:
            phase, grip, goal = "close", 1.0, plan.grasp
        elif xy_err < 0.01 and ori_err < 0.05 and T[2, 3] <= plan.pregrasp[2, 3] + 0.01:
            phase, grip, goal = "descend", 0.0, plan.grasp
            speed = self.max_speed / 3
        else:
            phase, grip, goal = "approach", 0.0, plan.pregrasp
        if phase == "open":
            Q = np.repeat(q[None, :], self.horizon, axis=0)
        else:
            # Even "close" and "done" finish the current line: the arm may still be
            # moving, and holding the measured (lagging) pose would jerk it backwards.
            Q = self._line(q, T, goal, v_tcp, speed)
        actions = np.empty((self.horizon, 8), dtype=np.float32)
        actions[:, :7] = Q
        actions[:, 7] = grip
        return {"actions": actions, "phase": phase, "done": phase == "done"}

    def _line(self, q: np.ndarray, T0: np.ndarray, goal: np.ndarray, v_tcp: np.ndarray, v_max: float) -> np.ndarray:
        """Joint waypoints moving the tcp from ``T0`` towards ``goal`` along a straight
        line, trapezoidal speed profile (limit ``v_max``, ``max_accel``), one IK per step."""
        dt = 1.0 / self.rate_hz
        d = goal[:3, 3] - T0[:3, 3]
        dist = float(np.linalg.norm(d))
        ang = _angle(T0[:3, :3], goal[:3, :3])
        # Rotation is paced like translation at 1 rad per 0.1 m.
        length = max(dist, 0.1 * ang)
        if length < 1e-5:
            return np.repeat(q[None, :], self.horizon, axis=0)
        direction = d / dist if dist > 1e-9 else np.zeros(3)
        v = float(np.clip(direction @ v_tcp * (length / dist if dist > 1e-9 else 1.0), 0.0, v_max))
        s, out, seed = 0.0, [], q
        a = self.max_accel
        for _ in range(self.horizon):
            # Largest speed from which the arm can still stop at the goal after this step:
            # s + v dt + v^2 / (2 a) <= length.
            v_stop = -a * dt + math.sqrt((a * dt) ** 2 + 2.0 * a * max(0.0, length - s))
            v = min(v + a * dt, v_max, v_stop)
            s = min(length, s + v * dt)
            Tk = interpolate_pose(T0, goal, s / length)
            try:
                seed = np.array(solve_ik(self.model, q_seed=seed, target=Tk, position_tol_m=5e-4,
                                         orientation_tol_rad=5e-3, max_iters=60).q)
            except IKError as exc:
                logger.info("grasp policy: waypoint unreachable, holding: %s", exc)
            out.append(seed)
        return np.array(out)


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))

