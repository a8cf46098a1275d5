"""Primitive leaves of behaviour trees, registered by the name trees use.

========================  ==========================================================
name                      behaviour
========================  ==========================================================
observe                   snapshot the world (blackboard + ENVIRONMENT.md)
compute_grasp             top-down grasp / pre-grasp tcp poses from the observation
compute_place             place / pre-place tcp poses over a region
ready_configuration       the arm's ready (home) joint configuration to the blackboard
solve_ik                  mink IK to a blackboard tcp pose
plan_path                 OMPL joint-space path with MuJoCo collision checking
retime_path               toppra time-optimal timing under joint limits
execute_trajectory        stream a timed trajectory with a tracking check
cartesian_move            straight-line tcp approach / lift / retreat
gripper                   open / close (closing checks the grasp)
check_holding             succeed only while the object is held
hold                      keep still for a simulated duration
wait_still                keep still until the cameras see the scene at rest
compute_affordance_grasp  grasp poses for the part an entity declares graspable
articulate_hinge          turn a held handle about its entity's hinge
articulate_slide          pull or push a held handle along its entity's slide (a drawer)
tool_move                 straight tcp motion by an offset in the tool frame
compute_place_as_held     place poses keeping the hand's orientation (hooked objects)
noop                      succeed after n ticks, touching no target (control.py)
give_way                  fail at once, recording nothing: ends a clean-up branch (control.py)
guarded_move              straight tcp motion that stops on contact (contact.py)
compute_place_at          place poses at an offset or slot inside a region (placement.py)
compute_push              start poses to push an object with the closed hand (contact.py)
push                      compliant push that must touch, with an effort limit (contact.py)
compute_door_push         the start of a push that shuts a fixture's door (door.py)
push_door                 sweep the closed fingers along a door's circle into its shut stop (door.py)
compute_handle_grasp      grasp poses taking an object by its handle from outside (handle_grasp.py)
compute_place_inside      place poses setting a held object inside a room through its mouth (inside.py)
compute_drawer_hook       poses hooking the closed fingers behind an open drawer's front (drawer_hook.py)
object_seen               succeed when the observation names the object, fail quietly otherwise (search.py)
compute_search_look       a look from nearer at an unnamed segment where the object may be (search.py)
game_*                    game primitives (explore, goto, collect, hunt, place, make,
                          sleep, survive) on a ``kind: game`` target (game/)
========================  ==========================================================
"""

from .affordance import ArticulateHinge, ArticulateSlide, ComputeAffordanceGrasp, ComputePlaceAsHeld, ToolMove
from .base import Primitive, PrimitiveFailure
from .contact import ComputePush, GuardedMove, Push
from .context import CancelToken, MotionSettings, Profiler, SkillContext, TraceRecorder
from .control import GiveWay, Noop
from .door import ComputeDoorPush, PushDoor
from .drawer_hook import ComputeDrawerHook
from .execution import CartesianMove, CheckHolding, ExecuteTrajectory, Gripper, Hold, WaitStill
from .game import GAME_PRIMITIVES
from .handle_grasp import ComputeHandleGrasp
from .inside import ComputePlaceInside
from .motion import PlanPath, ReadyConfiguration, RetimePath, SolveIK
from .perception import ComputeGrasp, ComputePlace, Observe
from .placement import ComputePlaceAt
from .search import ComputeSearchLook, ObjectSeen

__all__ = [
    "PRIMITIVES",
    "Primitive",
    "PrimitiveFailure",
    "SkillContext",
    "CancelToken",
    "MotionSettings",
    "Profiler",
    "TraceRecorder",
]

#: Primitive name (as used in ``trees/*.yaml``) -> behaviour class.
PRIMITIVES = {
    "observe": Observe,
    "compute_grasp": ComputeGrasp,
    "compute_place": ComputePlace,
    "ready_configuration": ReadyConfiguration,
    "solve_ik": SolveIK,
    "plan_path": PlanPath,
    "retime_path": RetimePath,
    "execute_trajectory": ExecuteTrajectory,
    "cartesian_move": CartesianMove,
    "gripper": Gripper,
    "check_holding": CheckHolding,
    "hold": Hold,
    "wait_still": WaitStill,
    "compute_affordance_grasp": ComputeAffordanceGrasp,
    "articulate_hinge": ArticulateHinge,
    "articulate_slide": ArticulateSlide,
    "tool_move": ToolMove,
    "compute_place_as_held": ComputePlaceAsHeld,
    "noop": Noop,
    "give_way": GiveWay,
    "guarded_move": GuardedMove,
    "compute_place_at": ComputePlaceAt,
    "compute_push": ComputePush,
    "push": Push,
    "compute_door_push": ComputeDoorPush,
    "push_door": PushDoor,
    "compute_handle_grasp": ComputeHandleGrasp,
    "compute_place_inside": ComputePlaceInside,
    "compute_drawer_hook": ComputeDrawerHook,
    "object_seen": ObjectSeen,
    "compute_search_look": ComputeSearchLook,
    **GAME_PRIMITIVES,
}
