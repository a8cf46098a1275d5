"""Former home of the Franka tabletop target, kept as an alias for code written against
the old layout: the target is :mod:`phyagentos.targets.franka_tabletop`, the gripper
result :class:`phyagentos.targets.mujoco_arm.GripperResult`."""

from .franka_tabletop.target import MAX_GRIP_FORCE_N, ExecutionResult, GripperResult, MuJoCoTarget

__all__ = ["MuJoCoTarget", "GripperResult", "ExecutionResult", "MAX_GRIP_FORCE_N"]
