"""Arm inverse dynamics on a MuJoCo model, for timing motions within the actuators' torques.

A joint's speed limit alone does not bound the torque its actuator must give: in a world with
a medium (MuJoCo's fluid model, ``opt.density`` / ``opt.viscosity``) every moving body is
dragged, and the drag on the bodies past a joint loads it however the other joints move them.
LIBERO's worlds are such (robosuite sets air, density 1.2 kg/m^3, viscosity 2e-5 Pa s), and
robosuite's Panda gives its finger-tip bodies 0.01 kg with 0.01 kg m^2 of inertia, so their
equivalent inertia boxes (MuJoCo's inertia-box fluid model) are metres wide: turning the
hand about its axis at 0.6 rad/s, with the shoulder and elbow swinging it the other way,
asks about 12 N m of the wrist (measured, libero_object task 7; the Panda's wrist actuators
give 12 N m), and the servo then lags its reference (docs/libero.md, forty-fourth pass).

:class:`ArmDynamics` computes the torque each arm joint's actuator must give to follow
``(q, qd, qdd)``: ``M(q) qdd + c(q, qd) - f_passive(q, qd)`` over the arm's degrees of freedom
(MuJoCo's mass matrix, bias forces and passive forces: damping, gravity compensation and the
fluid), with contacts left out, and the torques the timing may ask
(:func:`~phyagentos.motion.retime.retime`'s ``dynamics``: toppra's ``JointTorqueConstraint``).
"""

from __future__ import annotations

from typing import Sequence

import mujoco
import numpy as np

from phyagentos.errors import MotionError

__all__ = ["ArmDynamics"]


class ArmDynamics:
    """Inverse dynamics of an arm's joints on a MuJoCo model, and the torques they may use.

    Args:
        model: the model the arm moves in (read, never changed).
        joint_names: ``(n,)`` the arm's hinge joints, base to hand.
        torque_limits: ``(n,)`` N m, the largest torque each joint's actuator may be asked for
            (positive; symmetric).

    The other degrees of freedom (objects, fingers) stand still where a private data copy
    last put them (the model's reference configuration): the arm's trees do not depend on
    them but through contacts, which are left out.

    Raises:
        MotionError: an unknown or non-hinge joint, or limits not ``(n,)`` finite and > 0.
    """

    def __init__(self, model: mujoco.MjModel, joint_names: Sequence[str], *, torque_limits: Sequence[float]):
        names = tuple(joint_names)
        jids = []
        for name in names:
            jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if jid < 0 or model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
                raise MotionError(f"ArmDynamics: {name!r} is not a hinge joint of the model")
            jids.append(jid)
        lim = np.asarray(torque_limits, dtype=float).reshape(-1)
        if lim.shape != (len(names),) or not np.all(np.isfinite(lim)) or np.any(lim <= 0):
            raise MotionError(f"ArmDynamics: torque_limits must be {len(names)} finite numbers > 0 (N m), "
                              f"got {torque_limits!r}")
        self._model = model
        self._data = mujoco.MjData(model)
        self._qadr = np.array([model.jnt_qposadr[j] for j in jids])
        self._dadr = np.array([model.jnt_dofadr[j] for j in jids])
        self._qacc = np.zeros(model.nv)
        self._mqdd = np.zeros(model.nv)
        self._bias = np.zeros(model.nv)
        self.torque_limits = lim
        self.joint_names = names

    def inverse(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """``(n,)`` N m: the torque each arm joint's actuator must give for the arm to be at
        ``q`` (n,) rad moving at ``qd`` (n,) rad/s and accelerating at ``qdd`` (n,) rad/s^2:
        ``M(q) qdd + c(q, qd) - f_passive(q, qd)`` on the arm's degrees of freedom (gravity
        included in ``c``; a body compensated for gravity has it cancelled by the passive
        force, as the simulator does), contacts left out."""
        m, d = self._model, self._data
        d.qpos[self._qadr] = q
        d.qvel[:] = 0.0
        d.qvel[self._dadr] = qd
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_crb(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_passive(m, d)
        mujoco.mj_rne(m, d, 0, self._bias)
        self._qacc[:] = 0.0
        self._qacc[self._dadr] = qdd
        mujoco.mj_mulM(m, d, self._mqdd, self._qacc)
        return (self._mqdd + self._bias - d.qfrc_passive)[self._dadr]
