"""Motion algorithms for the Franka arm: mink IK, MuJoCo collision checking, OMPL
planning, toppra retiming, Cartesian paths and box grasps.

Nothing here depends on :mod:`phyagentos.targets`; every function takes a MuJoCo model
(or a :class:`CollisionChecker`) built by the caller.
"""

from .cartesian import cartesian_path, forward_kinematics, interpolate_pose
from .collision import CollisionChecker
from .grasp import GraspPlan, hand_yaw, place_pose, top_down_grasp, top_down_rotation
from .ik import IKSolution, qp_solver_name, solve_ik
from .planner import PLANNERS, last_plan_stats, plan_path
from .retime import (
    DEFAULT_ACCELERATION_LIMITS,
    FRANKA_ACCELERATION_LIMITS,
    FRANKA_VELOCITY_LIMITS,
    Trajectory,
    actuator_velocity_limits,
    retime,
)

__all__ = [
    "IKSolution",
    "solve_ik",
    "qp_solver_name",
    "CollisionChecker",
    "plan_path",
    "PLANNERS",
    "last_plan_stats",
    "Trajectory",
    "retime",
    "actuator_velocity_limits",
    "FRANKA_VELOCITY_LIMITS",
    "FRANKA_ACCELERATION_LIMITS",
    "DEFAULT_ACCELERATION_LIMITS",
    "cartesian_path",
    "forward_kinematics",
    "interpolate_pose",
    "GraspPlan",
    "top_down_grasp",
    "place_pose",
    "top_down_rotation",
    "hand_yaw",
]
