"""Motion algorithms for the Franka arm: mink IK, MuJoCo collision checking, OMPL
planning, toppra retiming, Cartesian paths and box grasps.

Nothing here depends on :mod:`phyagentos.targets`; every function takes a MuJoCo model
(or a :class:`CollisionChecker`) built by the caller. Units: metres, radians, seconds;
poses are (4, 4) world transforms; joint vectors are (7,) in joint1..joint7 order.
"""

from .cartesian import cartesian_path, forward_kinematics, interpolate_pose
from .collision import CollisionChecker
from .dynamics import ArmDynamics
from .grasp import (
    FINGERTIP_BELOW_TCP_M,
    JOINT7_RANGE_RAD,
    PAD_DEPTH_ABOVE_TCP_M,
    GraspPlan,
    hand_yaw,
    place_pose,
    top_down_grasp,
    top_down_grasp_candidates,
    top_down_rotation,
)
from .ik import DEFAULT_ARM_JOINT_NAMES, IKSolution, pose_error, qp_solver_name, solve_ik
from .planner import PLANNERS, last_plan_stats, plan_path
from .retime import (
    DEFAULT_ACCELERATION_LIMITS,
    FRANKA_ACCELERATION_LIMITS,
    FRANKA_VELOCITY_LIMITS,
    Trajectory,
    actuator_velocity_limits,
    franka_limits,
    retime,
)

__all__ = [
    # ik
    "IKSolution",
    "solve_ik",
    "qp_solver_name",
    "pose_error",
    "DEFAULT_ARM_JOINT_NAMES",
    # collision
    "CollisionChecker",
    # planner
    "plan_path",
    "PLANNERS",
    "last_plan_stats",
    # retime
    "Trajectory",
    "retime",
    "ArmDynamics",
    "actuator_velocity_limits",
    "franka_limits",
    "FRANKA_VELOCITY_LIMITS",
    "FRANKA_ACCELERATION_LIMITS",
    "DEFAULT_ACCELERATION_LIMITS",
    # cartesian
    "cartesian_path",
    "forward_kinematics",
    "interpolate_pose",
    # grasp
    "GraspPlan",
    "top_down_grasp",
    "top_down_grasp_candidates",
    "place_pose",
    "top_down_rotation",
    "hand_yaw",
    "FINGERTIP_BELOW_TCP_M",
    "PAD_DEPTH_ABOVE_TCP_M",
    "JOINT7_RANGE_RAD",
]
