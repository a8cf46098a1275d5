"""Where a hand takes a mug by its handle: the fingers across the handle's outer bar, the hand
coming in along the handle's direction from outside, pitched down (the skill's primitive is
:class:`phyagentos.primitives.handle_grasp.ComputeHandleGrasp`; the perceiver reads the same
point to tell that the hand holds the mug).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["GRIP_DEPTH_M", "handle_grip_xy", "handle_grasp_rotation"]

#: The tool point (between the fingertips) this far inside the handle's reach (its outer face),
#: horizontally, m: LIBERO's mug handles' bars are 5-8 mm thick with 3 cm or more to the cup
#: behind them, so the pads close on the bar's middle, past its centre line, the fingertips clear
#: of the cup (LIBERO-10 task 9's generated scene 500: the mug lifted level by its handle).
GRIP_DEPTH_M = 0.014


def handle_grip_xy(axis_xy: np.ndarray, handle_xy: np.ndarray, reach_m: float) -> np.ndarray:
    """(2,) world m: where the tool point takes the handle of a round body whose axis stands at
    ``axis_xy`` (2,), its handle pointing along ``handle_xy`` (2,) and reaching ``reach_m`` m out."""
    u = np.asarray(handle_xy, dtype=float)[:2]
    return np.asarray(axis_xy, dtype=float)[:2] + (float(reach_m) - GRIP_DEPTH_M) * u / np.linalg.norm(u)


def handle_grasp_rotation(handle_xy: np.ndarray, pitch_rad: float) -> np.ndarray:
    """(3, 3) world rotation of the tool frame grasping a handle pointing along ``handle_xy``
    ((2,) world unit): z (the hand's axis) back along the handle towards the cup, pitched down by
    ``pitch_rad``; y (the fingers' closing) horizontal, across the handle."""
    u = np.asarray(handle_xy, dtype=float)[:2]
    u = u / np.linalg.norm(u)
    z = np.array([-u[0] * math.cos(pitch_rad), -u[1] * math.cos(pitch_rad), -math.sin(pitch_rad)])
    y = np.cross([0.0, 0.0, 1.0], z)
    y /= np.linalg.norm(y)
    return np.column_stack([np.cross(y, z), y, z])
