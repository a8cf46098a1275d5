"""Rollout targets: the abstract contract and the MuJoCo Franka tabletop simulation.

Units: metres, radians, seconds; poses are (4, 4) world transforms (z up, origin at the
robot base, table top at z = 0).
"""

from .base import TARGET_KINDS, BaseRolloutTarget, ExecutionResult, TargetKind
from .franka_tabletop import MuJoCoTarget
from .mujoco_arm import GripperResult
from .scene import (
    ARM_ACTUATOR_NAMES,
    ARM_JOINT_NAMES,
    DEFAULT_SCENE,
    FINGER_ACTUATOR_NAMES,
    FINGER_BODY_NAMES,
    FINGER_JOINT_NAMES,
    FLOOR_GEOM,
    GRIPPER_MAX_OPENING_M,
    HOME_QPOS,
    ROBOT_BODY_NAMES,
    TABLE_GEOM,
    TCP_SITE,
    ObjectSpec,
    ObstacleSpec,
    RegionSpec,
    SceneSpec,
    build_scene,
    build_scene_spec,
    franka_asset_dir,
    object_joint_name,
    obstacle_geom_name,
    region_geom_name,
)

__all__ = [
    # base
    "BaseRolloutTarget",
    "ExecutionResult",
    "TargetKind",
    "TARGET_KINDS",
    # franka_tabletop, mujoco_arm
    "MuJoCoTarget",
    "GripperResult",
    # scene
    "ObjectSpec",
    "RegionSpec",
    "ObstacleSpec",
    "SceneSpec",
    "DEFAULT_SCENE",
    "build_scene",
    "build_scene_spec",
    "franka_asset_dir",
    "ARM_JOINT_NAMES",
    "ARM_ACTUATOR_NAMES",
    "FINGER_JOINT_NAMES",
    "FINGER_ACTUATOR_NAMES",
    "FINGER_BODY_NAMES",
    "ROBOT_BODY_NAMES",
    "GRIPPER_MAX_OPENING_M",
    "HOME_QPOS",
    "TCP_SITE",
    "TABLE_GEOM",
    "FLOOR_GEOM",
    "region_geom_name",
    "obstacle_geom_name",
    "object_joint_name",
]
