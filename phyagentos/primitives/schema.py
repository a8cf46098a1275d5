"""Machine-readable parameter schema of every primitive (what ``trees/*.yaml`` may pass).

Each primitive class has a small declarative table: parameter name -> (type, unit,
description). Defaults and which parameters are required are not repeated here: they
come from the class's ``__init__`` signature, so the schema cannot drift from the
code. A primitive class may carry its table itself as ``PARAMS``; the tables of the
shipped primitives live in :data:`TABLES` so their modules stay as they are.

``phyagentos primitives`` and ``docs/primitives.md`` are generated from
:func:`primitive_schemas`; a test keeps the document current and checks that every
table names exactly the parameters of its class.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Mapping

from .affordance import ArticulateHinge, ArticulateSlide, ComputeAffordanceGrasp, ComputePlaceAsHeld, ToolMove
from .contact import ComputePush, GuardedMove, Push
from .control import GiveWay, Noop
from .door import ComputeDoorPush, PushDoor
from .drawer_hook import ComputeDrawerHook
from .execution import CartesianMove, CheckHolding, ExecuteTrajectory, Gripper, Hold, WaitStill
from .game.survival import GameSurvive
from .game.tasks import GameCollect, GameExplore, GameGoto, GameHunt, GameMake, GameObserve, GamePlace, GameSleep
from .handle_grasp import ComputeHandleGrasp
from .inside import ComputePlaceInside
from .motion import PlanPath, ReadyConfiguration, RetimePath, SolveIK
from .perception import ComputeGrasp, ComputePlace, Observe
from .placement import ComputePlaceAt
from .search import ComputeSearchLook, ObjectSeen

__all__ = ["ParamSpec", "PrimitiveSchema", "TABLES", "primitive_schema", "primitive_schemas", "REQUIRED"]

#: Marker of a parameter without a default.
REQUIRED = "required"

_KEY = ("str", "", "blackboard key")  # most keys: a blackboard entry name


@dataclass(frozen=True)
class ParamSpec:
    """One primitive parameter: ``type`` (YAML-level: str, float, int, bool, [x, y, z], ...),
    ``unit`` (SI, empty when unitless), ``default`` (:data:`REQUIRED` when none)."""

    name: str
    type: str
    unit: str
    default: Any
    description: str

    @property
    def required(self) -> bool:
        return self.default is REQUIRED


@dataclass(frozen=True)
class PrimitiveSchema:
    """A primitive's name (as trees use it), class, one-line summary and parameters."""

    name: str
    cls: type
    summary: str
    params: tuple[ParamSpec, ...]


#: class -> parameter -> (type, unit, description)
TABLES: dict[type, Mapping[str, tuple[str, str, str]]] = {
    Observe: {
        "out": (*_KEY[:2], "blackboard key written with the snapshot"),
        "samples": ("int", "", "perception frames averaged (0 = skip the observation)"),
        "or_if": (*_KEY[:2], "blackboard flag that makes a skipped observation take one sample (null: none)"),
    },
    ComputeGrasp: {
        "object": ("str", "", "scene object to grasp"),
        "approach_height_m": ("float", "m", "pre-grasp height above the grasp"),
        "candidate": ("int", "", "which top-down grasp, best first (another approach direction)"),
        "rim_wall_m": ("float", "m", "assumed wall of a bowl or mug taken by its rim (null: perception.yaml's 3 mm / 7 mm)"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "grasp": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp grasp pose"),
        "pregrasp": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pre-grasp pose"),
        "look_closer": (*_KEY[:2], "blackboard flag written True when the object was seen only in part"),
    },
    ComputePlace: {
        "object": ("str", "", "the held object"),
        "region": ("str", "", "region (or object, to stack on) to set it down in"),
        "approach_height_m": ("float", "m", "pre-place height above the place pose"),
        "beside": ("str", "", "left / right: beside the region (a landmark) on the viewer's side, not on it; null: on it"),
        "slot": ("list | null", "", "[k, n]: slot k of n side by side on the region (within an open container's "
                 "walls: a row, or corner to corner); null: its centre"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "place": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp place pose"),
        "preplace": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pre-place pose"),
        "sunk": (*_KEY[:2], "blackboard key written with how far (m) the place was lowered into an open "
                            "container below its top (0 elsewhere)"),
    },
    SolveIK: {
        "pose": (*_KEY[:2], "blackboard key of the (4, 4) world tcp pose to reach"),
        "out": (*_KEY[:2], "blackboard key written with the (n,) joint solution in rad"),
        "position_tol_m": ("float", "m", "position convergence tolerance"),
        "orientation_tol_rad": ("float", "rad", "orientation convergence tolerance"),
    },
    PlanPath: {
        "goal": (*_KEY[:2], "blackboard key of the (n,) goal configuration in rad"),
        "out": (*_KEY[:2], "blackboard key written with the (N, n) path"),
        "planner": ("str | null", "", "OMPL planner (null: the session's motion settings)"),
        "timeout_s": ("float | null", "s", "planning budget (null: the session's motion settings)"),
    },
    RetimePath: {
        "path": (*_KEY[:2], "blackboard key of the (N, n) path"),
        "out": (*_KEY[:2], "blackboard key written with the timed trajectory"),
        "velocity_scale": ("float | null", "", "fraction (0, 1] of the joint velocity limits"),
        "acceleration_scale": ("float | null", "", "fraction (0, 1] of the joint acceleration limits"),
    },
    ExecuteTrajectory: {
        "trajectory": (*_KEY[:2], "blackboard key of the timed trajectory to stream"),
    },
    CartesianMove: {
        "to": ("str | null", "", "blackboard key of a (4, 4) world tcp pose (give `to` or `offset`)"),
        "offset": ("[dx, dy, dz] | null", "m", "world-frame tcp displacement, orientation kept"),
        "velocity_scale": ("float", "", "fraction (0, 1] of the joint velocity limits"),
        "check_collisions": ("bool", "", "re-check the timed motion against the scene"),
        "at_least_m": ("float | null", "m", "with `offset`: where the line leaves the arm's reach, end as far "
                                           "along it as reached when that is at least this far (null: all or fail)"),
        "grasp_kind": ("str | null", "", "move only after a grasp of this kind was planned (rim, across, ...); "
                                         "else succeed at once (null: always)"),
        "offset_plus": ("str | null", "", "with `offset`: blackboard key of a length in m the move goes further "
                                          "along it (a retreat from a place sunk into a container); null: none"),
    },
    Gripper: {
        "command": ("open | close | preshape", "", "what to do (preshape: open only as far as the planned "
                                                  "grasp of `object` asks; nothing when it asks fully open)"),
        "object": ("str | null", "", "when closing: the object that must end up between the fingers; when "
                                     "pre-shaping: the object whose planned grasp sets the opening"),
        "force_n": ("float | null", "N", "when closing: grip force per finger (null: close on position)"),
    },
    CheckHolding: {
        "object": ("str", "", "the object that must be held"),
    },
    Hold: {
        "duration_s": ("float", "s", "simulated time to keep still"),
    },
    WaitStill: {
        "max_s": ("float", "s", "the longest wait for the cameras to see the scene at rest (0: no wait)"),
        "step_s": ("float", "s", "simulated time between the two captures of a look"),
    },
    ComputeAffordanceGrasp: {
        "object": ("str", "", "entity whose declared part to grasp"),
        "approach_height_m": ("float", "m", "pre-grasp distance along the approach"),
        "affordance": ("str", "", "which declared affordance (e.g. grasp, handle)"),
        "turn_to_fraction": ("float", "", "the joint (hinge or slide) moves next to this fraction of its travel: a hand "
                                           "with room for it"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "grasp": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp grasp pose"),
        "pregrasp": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pre-grasp pose"),
    },
    ArticulateHinge: {
        "object": ("str", "", "articulated entity (its hinge is declared by the target or perceived)"),
        "delta_rad": ("float", "rad", "signed hinge rotation (or to_fraction)"),
        "to_fraction": ("float", "", "turn to this fraction of the hinge's travel from its reported position"),
        "step_rad": ("float", "rad", "rotation per tracked waypoint"),
        "velocity_scale": ("float", "", "fraction (0, 1] of the joint velocity limits"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
    },
    ArticulateSlide: {
        "object": ("str", "", "articulated entity (its slide is declared by the target or perceived: a drawer)"),
        "delta_m": ("float", "m", "signed motion along the slide's axis (or to_fraction)"),
        "to_fraction": ("float", "", "move to this fraction of the slide's travel from its reported position"),
        "step_m": ("float", "m", "motion per IK waypoint"),
        "velocity_scale": ("float", "", "fraction (0, 1] of the joint velocity limits"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "push_to_stop_m": ("float", "m", "with to_fraction 0: push on this far past shut into the drawer's stop; "
                                         "met within the reading's band, the perceiver reads it shut"),
        "lead_m": ("float", "m", "closed fingers against a face of the drawer, not holding it: the gap the hand "
                                 "closes first (and, pulled, on against the stop); to an end, only towards it"),
    },
    ToolMove: {
        "offset": ("[dx, dy, dz]", "m", "tcp displacement in the tool frame"),
        "velocity_scale": ("float", "", "fraction (0, 1] of the joint velocity limits"),
    },
    ComputePlaceAsHeld: {
        "object": ("str", "", "the held (hooked) object"),
        "region": ("str", "", "region to set it down in"),
        "approach_height_m": ("float", "m", "pre-place height above the place pose"),
        "clearance_m": ("float", "m", "gap kept between the object and the surface"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "place": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp place pose"),
        "preplace": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pre-place pose"),
    },
    ReadyConfiguration: {
        "out": (*_KEY[:2], "blackboard key written with the target's ready (home) configuration, (n,) rad"),
    },
    # Game primitives (kind: game targets, docs/crafter.md); budgets are in game steps.
    GameObserve: {
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GameExplore: {
        "steps": ("int", "steps", "game steps to walk toward unseen cells"),
        "until": ("str | null", "", "stop early once this material or creature is seen"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GameGoto: {
        "target": ("str", "", "material or creature to go next to (the nearest remembered one)"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GameCollect: {
        "material": ("str", "", "material to collect from (facing it, action do)"),
        "item": ("str", "", "inventory item (or vital) that must grow"),
        "count": ("int", "", "how many more of the item to collect"),
        "strikes": ("int", "", "extra do-actions per unit (0: as many as the item needs)"),
        "patience": ("int", "steps", "steps without progress before trying another cell"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GameHunt: {
        "creature": ("str", "", "cow, zombie, skeleton or plant_ripe"),
        "until": ("str | null", "", "stop once this achievement is unlocked"),
        "min_health": ("int", "", "give up and flee below this health (0..9)"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GamePlace: {
        "item": ("str", "", "table, furnace, stone or plant"),
        "near": ("str | null", "", "material the placed item must be next to"),
        "max_tries": ("int", "", "placement attempts"),
        "protect": ("bool", "", "plant: on a grass cell walled on three sides, then seal the fourth with stone"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GameMake: {
        "item": ("str", "", "tool to make (action make_<item>)"),
        "near": ("list | null", "", "stations the recipe needs (from memory; null: search)"),
        "max_tries": ("int", "", "make attempts"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GameSleep: {
        "shelter": ("bool", "", "sleep in a sealed shelter when the player can dig one"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    GameSurvive: {
        "drink_below": ("int", "", "drink when thirst falls below this level (0..9)"),
        "food_below": ("int", "", "eat when food falls below this level (0..9)"),
        "energy_below": ("int", "", "rest when energy falls below this level (0..9)"),
        "health_below": ("int", "", "retreat into a sealed shelter to heal below this health (0..9)"),
        "night_below": ("float", "", "daylight level below which night precautions start (0..1)"),
        "fight": ("bool", "", "fight creatures that attack (else flee)"),
        "topup_below": ("int", "", "fill up food / drink below this level when a cow or water is at hand, or at dusk"),
        "near": ("int", "cells", "how close a cow or water must be for a top-up"),
        "dusk_below": ("float", "", "daylight level, falling, at which the dusk top-up starts (0..1)"),
        "max_steps": ("int", "steps", "game-step budget of the leaf"),
    },
    Noop: {
        "ticks": ("int", "", "ticks before succeeding (touches no target)"),
    },
    GiveWay: {},
    ObjectSeen: {
        "object": ("str", "", "scene object the observation should name"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation"),
    },
    ComputeSearchLook: {
        "object": ("str", "", "the object looked for (named in the trace and the failure)"),
        "max_looks": ("int", "", "looks aimed at most in one session (0: none)"),
        "look_height_m": ("float", "m", "hand camera's height above the segment's top"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation"),
        "out": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp look pose"),
    },
    ComputePlaceAt: {
        "object": ("str", "", "the held object"),
        "region": ("str", "", "region to set it down in"),
        "offset_m": ("[dx, dy] | null", "m", "spot relative to the region's centre (give `offset_m` or `slot`)"),
        "slot": ("int", "", "0-based cell of the region's grid (placement.slot_offset: along the longer axis, then row by row)"),
        "slots": ("int", "", "number of cells the region is divided into (1: the centre)"),
        "approach_height_m": ("float", "m", "pre-place height above the place pose"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "place": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp place pose"),
        "preplace": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pre-place pose"),
    },
    ComputePush: {
        "object": ("str", "", "the object to push"),
        "direction": ("[dx, dy] | null", "", "world-frame push direction (normalised; with distance_m)"),
        "distance_m": ("float | null", "m", "how far the object should move (with direction)"),
        "landmark": ("str | null", "", "push the object beside this thing instead (with side)"),
        "side": ("str | null", "", "left / right / front (towards the viewer) / back of the landmark"),
        "strategy": ("str", "", "auto (a low object pressed from above, else from behind), behind or above"),
        "press_carry": ("float", "", "fraction (0, 1] of the hand's way a pressed object makes (its creep)"),
        "clearance_m": ("float", "m", "gap between the fingertips and the object at the start"),
        "approach_height_m": ("float", "m", "pre-start pose back from the start along the hand's axis"),
        "tip_clearance_m": ("float", "m", "fingertips above the surface the object stands on"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "start": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp start pose"),
        "prestart": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pre-start pose"),
        "goal": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pose where the push ends"),
        "press": (*_KEY[:2], "blackboard key written with the press from above (or null)"),
    },
    Push: {
        "to": ("str | null", "", "blackboard key of the (4, 4) world tcp pose where the push ends (or `offset`)"),
        "offset": ("[dx, dy, dz] | null", "m", "world-frame tcp displacement of the whole push"),
        "velocity_scale": ("float", "", "fraction (0, 1] of the joint velocity limits"),
        "tracking_tol_rad": ("float", "rad", "joint tracking error tolerated while pushing"),
        "max_force_n": ("float", "N", "effort limit: fail with contact.excessive_force above it"),
        "expect_contact": ("bool", "", "fail with contact.missing if nothing was touched"),
        "press": ("str | null", "", "blackboard key of a press from above (lower until it lands, then drag)"),
    },
    ComputeDoorPush: {
        "object": ("str", "", "the fixture whose door is shut (perceived: attributes.door and its hinge)"),
        "approach_height_m": ("float", "m", "the pose written above the push's start"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
    },
    ComputeDrawerHook: {
        "object": ("str", "", "the drawer (perceived: its slide, handle and, pulled, its floor out of the body)"),
        "pull": ("bool", "", "true: behind the inside of its front, to pull it out; false: before its handle, to "
                             "push it in"),
        "approach_height_m": ("float", "m", "the pose written above the fingers' place"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
    },
    PushDoor: {
        "step_rad": ("float", "rad", "the door's joint between consecutive IK poses of the sweep"),
        "velocity_scale": ("float", "", "fraction (0, 1] of the joint velocity limits"),
    },
    ComputeHandleGrasp: {
        "object": ("str", "", "the object taken by its handle (perceived: axis_xy, handle_xy, handle_reach_m)"),
        "pitch_rad": ("float", "rad", "the hand's axis below the horizontal"),
        "approach_height_m": ("float", "m", "the pre-grasp, back along the hand's axis"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
    },
    ComputePlaceInside: {
        "object": ("str", "", "the held object"),
        "region": ("str", "", "the room it goes into (perceived: attributes.mouth and roof_z_m)"),
        "clearance_m": ("float", "m", "gap left under the object"),
        "entry_m": ("float", "m", "how far outside the mouth the object's far side starts"),
        "snapshot": (*_KEY[:2], "blackboard key of the observation to use"),
        "place": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp place pose"),
        "preplace": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pre-place pose"),
        "view": (*_KEY[:2], "blackboard key written with the (4, 4) world tcp pose looking into the room"),
    },
    GuardedMove: {
        "offset": ("[dx, dy, dz]", "m", "world-frame tcp displacement: the farthest the motion goes"),
        "velocity_scale": ("float", "", "fraction (0, 1] of the joint velocity limits"),
        "tracking_tol_rad": ("float", "rad", "joint tracking error tolerated before the motion counts as blocked"),
        "max_contact_force_n": ("float", "N", "stop once the robot presses on anything with this much"),
        "expect_contact": ("bool", "", "fail with contact.missing if the whole offset touches nothing"),
    },
}


def _summary(cls: type) -> str:
    doc = inspect.getdoc(cls) or ""
    first = doc.split("\n\n", 1)[0].replace("\n", " ").strip()
    return first


def primitive_schema(name: str, cls: type) -> PrimitiveSchema:
    """The schema of primitive ``name`` (class ``cls``): its table merged with the
    defaults of ``cls.__init__``.

    Raises:
        KeyError: ``cls`` has no table (neither ``PARAMS`` nor an entry in :data:`TABLES`).
        ValueError: the table and the signature name different parameters.
    """
    table = getattr(cls, "PARAMS", None) or TABLES[cls]
    sig = [p for p in inspect.signature(cls.__init__).parameters.values()
           if p.name not in ("self", "name") and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)]
    names = [p.name for p in sig]
    if set(names) != set(table):
        raise ValueError(f"primitive {name!r} ({cls.__name__}): schema table {sorted(table)} does not match "
                         f"the parameters of __init__ {sorted(names)}")
    params = tuple(ParamSpec(name=p.name, type=table[p.name][0], unit=table[p.name][1],
                             default=REQUIRED if p.default is p.empty else p.default, description=table[p.name][2])
                   for p in sig)
    return PrimitiveSchema(name=name, cls=cls, summary=_summary(cls), params=params)


def primitive_schemas(primitives: Mapping[str, type] | None = None) -> list[PrimitiveSchema]:
    """Schemas of every registered primitive (default :data:`phyagentos.primitives.PRIMITIVES`), by name."""
    if primitives is None:
        from . import PRIMITIVES  # noqa: PLC0415

        primitives = PRIMITIVES
    return [primitive_schema(n, c) for n, c in sorted(primitives.items())]
