"""The observation contract of the policy flow.

Whatever model sits behind a policy server, the runtime hands its PolicyAdapter the
same :class:`Observation`: the instruction, proprioception, object poses, camera
images (RGB, and depth where the target renders it) and a short history. The adapter
picks and converts what its model needs (:mod:`phyagentos.policy.adapter`).

Units: metres, radians, seconds; poses are (4, 4) world transforms.

Images are kept upright (row 0 at the top); an adapter input may ask for another
orientation (:mod:`phyagentos.policy.adapter`, ``orientation``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Mapping, Sequence

import numpy as np

__all__ = ["ObjectObservation", "HistoryEntry", "Observation", "SOURCES", "quat_xyzw_to_axis_angle", "eef_state"]

#: Observation source (what an adapter input is made of) -> the target observation
#: modality (TARGETS.md ``observations``) it needs; ``None``: always available.
SOURCES: dict[str, str | None] = {
    "instruction": None,
    "joint_positions": "joint_positions",
    "joint_velocities": "joint_positions",
    "gripper_opening": "gripper_opening",
    "object_pose": "object_poses",
    "object_half_extents": "object_poses",
    "rgb": "rgb",
    "depth": "depth",
    "history_joint_positions": "joint_positions",
    # end-effector position, axis-angle and finger joints: forward kinematics of the
    # proprioception (targets with ``osc_proprio()``, e.g. LIBERO)
    "eef_state": "joint_positions",
}


def quat_xyzw_to_axis_angle(quat: Sequence[float]) -> np.ndarray:
    """Axis-angle ``(3,)`` rad of a unit quaternion in x, y, z, w order.

    robosuite's ``transform_utils.quat2axisangle`` (which openpi's ``examples/libero/main.py``
    copies as ``_quat2axisangle``): ``w`` is clipped to [-1, 1]; when ``sqrt(1 - w^2)`` is
    (``math.isclose``) zero the rotation is zero; otherwise ``xyz * 2 acos(w) / sqrt(1 - w^2)``
    (so a quaternion with ``w < 0`` gives an angle above pi, as robosuite's does).
    """
    q = np.asarray(quat, dtype=float).reshape(4)
    w = min(1.0, max(-1.0, float(q[3])))
    den = math.sqrt(1.0 - w * w)
    if math.isclose(den, 0.0):
        return np.zeros(3)
    return q[:3] * 2.0 * math.acos(w) / den


def eef_state(proprio: Mapping[str, np.ndarray]) -> np.ndarray:
    """openpi's LIBERO state ``(8,)`` float64 from a target's ``osc_proprio()``: end-effector
    position (3) m, axis-angle of its quaternion (3) rad, the two finger joint positions (2) m
    (``observation/state`` of ``examples/libero/main.py``)."""
    return np.concatenate((np.asarray(proprio["eef_pos"], dtype=float),
                           quat_xyzw_to_axis_angle(proprio["eef_quat_xyzw"]),
                           np.asarray(proprio["gripper_qpos"], dtype=float)))


@dataclass(frozen=True)
class ObjectObservation:
    """An object's world pose ``(4, 4)`` and box half extents ``(3,)`` m."""

    pose: np.ndarray
    half_extents: np.ndarray


@dataclass(frozen=True)
class HistoryEntry:
    """One past step: target time (s), measured joints (7,) rad, last admitted action or ``None``."""

    time_s: float
    joint_positions: np.ndarray
    action: np.ndarray | None = None


@dataclass(frozen=True)
class Observation:
    """What the runtime observed at ``time_s`` (target clock, s).

    Attributes:
        instruction: natural-language task, e.g. ``"pick up the cube"``.
        joint_positions, joint_velocities: ``(7,)`` rad, rad/s.
        gripper_opening_m: opening per finger, m.
        objects: name -> :class:`ObjectObservation`.
        focus: the object the instruction is about (the session's ``object``), if any.
        rgb: ``(H, W, 3)`` uint8 camera image, if requested.
        depth: ``(H, W)`` float32 depth in m, if requested and rendered by the target.
        history: the most recent steps, oldest first.
        images: every rendered image by ``(source, camera)`` (``rgb`` upright uint8, ``depth``
            float32 m) at the size the adapter asked for; ``rgb`` / ``depth`` above are the first.
        eef_state: ``(8,)`` (:func:`eef_state`), if an input needs it.
    """

    instruction: str
    time_s: float
    joint_positions: np.ndarray
    joint_velocities: np.ndarray
    gripper_opening_m: float
    objects: Mapping[str, ObjectObservation] = field(default_factory=dict)
    focus: str | None = None
    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None
    history: tuple[HistoryEntry, ...] = ()
    images: Mapping[tuple[str, str], np.ndarray] = field(default_factory=dict)
    eef_state: np.ndarray | None = None
