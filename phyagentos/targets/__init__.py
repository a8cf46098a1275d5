"""Rollout targets: the abstract contract and the MuJoCo Franka tabletop simulation."""

from .base import TARGET_KINDS, BaseRolloutTarget, ExecutionResult
from .mujoco_target import GripperResult, MuJoCoTarget
from .scene import (
    ARM_JOINT_NAMES,
    DEFAULT_SCENE,
    FINGER_JOINT_NAMES,
    GRIPPER_MAX_OPENING_M,
    HOME_QPOS,
    TCP_SITE,
    ObjectSpec,
    ObstacleSpec,
    RegionSpec,
    SceneSpec,
    build_scene,
    build_scene_spec,
    franka_asset_dir,
)

__all__ = [
    "BaseRolloutTarget",
    "ExecutionResult",
    "TARGET_KINDS",
    "MuJoCoTarget",
    "GripperResult",
    "ObjectSpec",
    "RegionSpec",
    "ObstacleSpec",
    "SceneSpec",
    "DEFAULT_SCENE",
    "build_scene",
    "build_scene_spec",
    "franka_asset_dir",
    "ARM_JOINT_NAMES",
    "FINGER_JOINT_NAMES",
    "GRIPPER_MAX_OPENING_M",
    "HOME_QPOS",
    "TCP_SITE",
]
