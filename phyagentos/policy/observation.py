"""The observation contract of the policy flow.

Whatever model sits behind a policy server, the runtime hands its PolicyAdapter the
same :class:`Observation`: the instruction, proprioception, object poses, camera
images (RGB, and depth where the target renders it) and a short history. The adapter
picks and converts what its model needs (:mod:`phyagentos.policy.adapter`).

Units: metres, radians, seconds; poses are (4, 4) world transforms.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

__all__ = ["ObjectObservation", "HistoryEntry", "Observation", "SOURCES"]

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
}


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
