"""LIBERO's own arm controller as the second action form (``osc_pose_delta_chunk``, the
policy flow's): one :meth:`LiberoOsc.osc_step` is one ``env.step`` of LIBERO's OSC_POSE
controller, and :meth:`LiberoOsc.osc_proprio` reads robosuite's proprioceptive observables,
the state openpi's LIBERO example sends (mixed into
:class:`~phyagentos.targets.libero.LiberoTarget`; see its module for the control model)."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from phyagentos.errors import TargetError

from ..contract import OscControlled

__all__ = ["CONTROL_PERIOD_S", "OSC_ACTION_DIM", "LiberoOsc"]

#: LIBERO's control period (20 Hz), s; one control step is 25 physics steps of 2 ms.
CONTROL_PERIOD_S = 0.05
#: Width of an OSC_POSE action (LIBERO's ``env.step``): dx dy dz drx dry drz gripper.
OSC_ACTION_DIM = 7


class LiberoOsc(OscControlled):
    """The ``osc_pose_delta_chunk`` action form of :class:`~phyagentos.targets.libero.LiberoTarget`."""

    def osc_step(self, action: Sequence[float]) -> None:
        """One LIBERO control step (:data:`CONTROL_PERIOD_S`) of ``action`` (7,) through
        ``env.step``: LIBERO's OSC_POSE controller (pose delta in [-1, 1] per axis, scaled by
        the controller's ``output_max``; gripper -1 open .. +1 closed), counted as env steps.
        Afterwards the arm servos hold where the step left the arm.

        Raises:
            TargetError: not 7 finite numbers.
        """
        self._check_open()
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (OSC_ACTION_DIM,) or not np.all(np.isfinite(a)):
            raise TargetError(f"an OSC_POSE action is {OSC_ACTION_DIM} finite numbers (dx dy dz drx dry drz gripper), "
                              f"got shape {a.shape}")
        m, d = self._model, self._data
        t0 = d.time
        self._servo(m, False)
        try:
            self._env.step(a)
        finally:
            self._servo(m, True)
            d.ctrl[self._arm_act] = np.clip(self.arm_qpos(), self._ctrl_lo[self._arm_act], self._ctrl_hi[self._arm_act])
        self._advance(int(round((d.time - t0) / m.opt.timestep)))

    def osc_proprio(self) -> dict[str, np.ndarray]:
        """robosuite's proprioceptive observables, as LIBERO's ``env.step`` returns them:
        ``eef_pos`` (3,) m (world; ``gripper0_grip_site``), ``eef_quat_xyzw`` (4,) (the hand
        body's orientation, robosuite's x, y, z, w order), ``gripper_qpos`` (2,) m (the two
        finger joints, the second negative when open)."""
        self._check_open()
        obs = self._env.env._get_observations(force_update=True)
        return {"eef_pos": np.asarray(obs["robot0_eef_pos"], dtype=float).copy(),
                "eef_quat_xyzw": np.asarray(obs["robot0_eef_quat"], dtype=float).copy(),
                "gripper_qpos": np.asarray(obs["robot0_gripper_qpos"], dtype=float).copy()}

    def osc_limits(self) -> dict[str, Any]:
        """LIBERO's arm controller as configured: ``type`` (``OSC_POSE``), ``input_max``,
        ``output_max`` (6,) (m and rad per control step at input 1), ``control_period_s``."""
        c = self._env.env.robots[0].controller
        return {"type": str(getattr(c, "name", type(c).__name__)), "input_max": float(np.max(c.input_max)),
                "output_max": [float(x) for x in np.asarray(c.output_max).reshape(-1)],
                "control_period_s": CONTROL_PERIOD_S}
