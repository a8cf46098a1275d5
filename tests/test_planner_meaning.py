"""Issue 35: a plan means the request, or the request is refused saying what could not be accounted for.

Requests nobody on the project wrote failed in classes: a hold became a move into a bin, "leave
the blocks where they are" moved one, a comparative failed to plan, a destination the scene does
not have was mapped to a bin, another language failed without saying why, and on a fresh
workspace the tie-break picked an arm whose reach the scene's declared positions already ruled out.
The offline model (SmolLM2-135M, temperature 0) plans where a model is needed; a scripted model
stands for one (an endpoint) that ignores the schema and answers something else than asked.
"""

from __future__ import annotations

import json

import pytest

from phyagentos.agent.llm.meaning import detect_language, read_request
from phyagentos.agent.llm.world import world_from_scene
from phyagentos.agent.planner import GoalPlanner
from phyagentos.app.orchestrator import skill_names
from phyagentos.cli import main
from phyagentos.llm import LLMCall, LLMReply, make_client
from phyagentos.protocol import Workspace
from phyagentos.untrusted import MAX_QUOTE_CHARS, quote

# a 4 cm red cube and a 6 cm blue cube, two bins
SCENE = {
    "objects": [
        {"name": "red_cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.45, -0.2], "rgba": [0.8, 0.1, 0.1, 1]},
        {"name": "blue_cube", "half_extents": [0.03, 0.03, 0.03], "position": [0.6, -0.15], "rgba": [0.1, 0.2, 0.8, 1]},
    ],
    "regions": [
        {"name": "left_bin", "center": [0.42, 0.24], "half_extents": [0.07, 0.07], "rgba": [0.5, 0.5, 0.5, 0.3]},
        {"name": "right_bin", "center": [0.62, 0.24], "half_extents": [0.07, 0.07], "rgba": [0.95, 0.95, 0.95, 0.3]},
    ],
}
SAME_SIZE = {**SCENE, "objects": [{**o, "half_extents": [0.02, 0.02, 0.02]} for o in SCENE["objects"]]}


def seen(scene):
    """ENVIRONMENT.md entities as a perception would have left them for ``scene``'s objects (test input)."""
    return [{"name": o["name"], "kind": "object", "position": [*o["position"][:2], 0.02], "rgba": o.get("rgba")}
            for o in scene["objects"]]


@pytest.fixture(scope="module")
def targets(tmp_path_factory):
    ws = Workspace.create(tmp_path_factory.mktemp("ws"))
    return [t.model_dump(mode="json") for t in ws.read("TARGETS").data.targets]


@pytest.fixture(scope="module")
def planner(targets):
    return GoalPlanner(make_client(), skills=skill_names(), targets=targets)


class _Scripted:
    """A model that answers from a list whatever it is asked (an endpoint that ignores the schema)."""

    provider, model = "scripted", "scripted"

    def __init__(self, answers):
        self.answers = list(answers)

    def complete(self, messages, *, schema=None, max_tokens=256, purpose="chat"):
        text = self.answers.pop(0)
        return LLMReply(text=text, call=LLMCall(self.provider, self.model, purpose, "0" * 16, 1, 1, 0.0, 0.0, 0, False))


def _answer(*steps):
    return json.dumps({"decision": "plan", "reason": "none",
                       "steps": [{"skill": s, "object": o, "destination": d or "none"} for s, o, d in steps]})


def _steps(result):
    return [(s.skill, s.object, s.destination) for s in result.steps]


# -- (b) the meaning is checked before anything moves ------------------------------------------------------


def test_pick_it_up_and_hold_it_is_a_pick_that_holds_not_a_move_into_a_bin(planner):
    result = planner.plan("pick up the red cube and hold it", scene=SCENE, environment=seen(SCENE))
    assert result.status == "planned", result.reason
    assert _steps(result) == [("pick", "red_cube", None)]
    (node,) = result.graph.nodes
    assert node.skill == "pick" and {"holding": "red_cube"} in node.accept
    assert result.context["meaning"][0]["verb"] == "hold"


def test_leave_the_blocks_where_they_are_plans_nothing_and_nothing_moves(planner, tmp_path, capsys):
    result = planner.plan("leave the blocks where they are", scene=SCENE, environment=seen(SCENE))
    assert result.status == "nothing_to_do" and result.graph is None and result.steps == ()
    assert result.calls == ()  # no model is asked to find something to move
    scene = tmp_path / "scene.yaml"
    scene.write_text(json.dumps(SCENE))
    code = main(["plan", "please do nothing", "--workspace", str(tmp_path / "ws"), "--scene", str(scene), "--run",
                 "--json"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and out["status"] == "nothing_to_do"
    assert not list((tmp_path / "ws" / "plans").glob("*/goal_graph.yaml"))
    assert not (tmp_path / "ws" / "runs").exists() or not any((tmp_path / "ws" / "runs").iterdir())


def test_a_move_with_a_leave_clause_moves_only_the_named_object(planner):
    result = planner.plan("put the red cube in the left bin and leave the blue one where it is", scene=SCENE,
                          environment=seen(SCENE))
    assert result.status == "planned", result.reason
    assert _steps(result) == [("pick_and_place", "red_cube", "left_bin")]
    # "but leave": the excepted object drops out of the quantified clause
    result = planner.plan("put all cubes in the right bin but leave the red one", scene=SCENE, environment=seen(SCENE))
    assert _steps(result) == [("pick_and_place", "blue_cube", "right_bin")]


def test_stacking_on_the_larger_one_is_a_stack_onto_that_object_chosen_by_size(planner):
    result = planner.plan("put the smaller cube on top of the larger one", scene=SCENE, environment=seen(SCENE))
    assert result.status == "planned", result.reason
    assert _steps(result) == [("pick_and_place", "red_cube", "blue_cube")]
    (node,) = result.graph.nodes
    assert {"on": {"object": "red_cube", "support": "blue_cube"}} in node.accept


def test_a_comparative_picks_the_object_by_its_declared_size_or_is_refused_when_sizes_are_equal(planner):
    result = planner.plan("put the bigger block in the left bin", scene=SCENE, environment=seen(SCENE))
    assert result.status == "planned", result.reason
    assert _steps(result) == [("pick_and_place", "blue_cube", "left_bin")]
    result = planner.plan("put the smallest block in the right bin", scene=SCENE, environment=seen(SCENE))
    assert _steps(result) == [("pick_and_place", "red_cube", "right_bin")]
    equal = planner.plan("put the bigger block in the left bin", scene=SAME_SIZE, environment=seen(SAME_SIZE))
    assert equal.status == "refused" and equal.refusal == "not_understood" and equal.calls == ()
    assert "'bigger'" in equal.reason and "same size" in equal.reason


def test_a_comparative_over_two_named_objects_moves_the_one_it_chooses_not_both():
    # "the X and the Y" names both (LIBERO's "put both ... and ..."); a comparative over the
    # same conjunction chooses one of them
    world = world_from_scene(SCENE)
    m = read_request("move the smaller of the red and blue cubes to the right bin", world)
    assert [(i.verb, i.movers(), i.destinations) for i in m.intents] == [("move", ("red_cube",), ("right_bin",))]
    m = read_request("put the bigger one of the red cube and the blue cube in the left bin", world)
    assert [(i.verb, i.movers(), i.destinations) for i in m.intents] == [("move", ("blue_cube",), ("left_bin",))]
    m = read_request("put the red cube and the blue cube in the left bin", world)
    assert [(i.verb, i.movers(), i.destinations) for i in m.intents] == [("move", ("red_cube", "blue_cube"),
                                                                          ("left_bin",))]


def test_counts_are_met_exactly_and_a_count_larger_than_the_scene_is_refused(planner):
    one = planner.plan("put one cube in the right bin", scene=SCENE, environment=seen(SCENE))
    assert one.status == "planned" and len(one.steps) == 1 and one.steps[0].destination == "right_bin"
    three = planner.plan("put three cubes in the right bin", scene=SCENE, environment=seen(SCENE))
    assert three.status == "refused" and three.refusal == "not_understood" and "asks for 3" in three.reason


def test_an_elided_verb_after_and_is_its_own_clause(planner):
    result = planner.plan("put the red cube in the left bin and the blue cube in the right bin", scene=SCENE,
                          environment=seen(SCENE))
    assert _steps(result) == [("pick_and_place", "red_cube", "left_bin"), ("pick_and_place", "blue_cube", "right_bin")]


def test_a_plan_that_does_something_other_than_asked_is_refused_with_what_is_unaccounted(targets):
    # an endpoint that ignores the schema: the hold becomes a move into a bin
    moved = GoalPlanner(_Scripted([_answer(("pick_and_place", "red_cube", "left_bin"))]), skills=skill_names(),
                        targets=targets)
    result = moved.plan("pick up the red cube and hold it", scene=SCENE, environment=seen(SCENE))
    assert result.status == "refused" and result.refusal == "not_understood" and result.refused_by == "meaning"
    assert "pick up and hold red_cube" in result.reason and result.graph is None
    assert result.records[-1].outcome == "refused"
    # a stack asked, a move into a region answered
    stacked = GoalPlanner(_Scripted([_answer(("pick_and_place", "red_cube", "right_bin"))]), skills=skill_names(),
                          targets=targets)
    result = stacked.plan("stack the red cube on the blue cube", scene=SCENE, environment=seen(SCENE))
    assert result.status == "refused" and "stack red_cube on blue_cube" in result.reason
    # steps nobody asked for, and an object asked to stay that a step moves
    from phyagentos.agent.planner import PlanStep

    world = world_from_scene(SCENE)
    meaning = read_request("put the red cube in the left bin and leave the blue one where it is", world)
    extra = [PlanStep("pick_and_place", "red_cube", "left_bin"), PlanStep("pick_and_place", "blue_cube", "left_bin")]
    misses = meaning.unaccounted(extra, world)
    assert any("asked by no part of the request" in m for m in misses)
    assert any("blue_cube stays where it is" in m for m in misses)
    assert meaning.unaccounted(extra[:1], world) == []


def test_a_modifier_of_no_declared_name_is_set_aside_and_said_only_before_a_noun_that_names_one_thing():
    world = world_from_scene(SCENE)
    meaning = read_request("put the shiny red cube in the left bin", world)
    assert not meaning.problems and [(i.verb, i.objects) for i in meaning.intents] == [("move", ("red_cube",))]
    assert meaning.assumed == ["'the shiny red cube': 'shiny' names nothing here; read as red_cube, the one cube"]
    # two cubes for "the shiny cube", a word before the article, an unknown noun: refused, nothing set aside
    for text, why in (("put the shiny cube in the left bin", "'shiny' names no object"),
                      ("polish the red cube in the left bin", "'polish' names no object"),
                      ("put the red kettle in the left bin", "'kettle' names no object")):
        meaning = read_request(text, world)
        assert meaning.problems and why in meaning.problems[0][1] and not meaning.assumed, (text, meaning.problems)


def test_what_the_rules_cannot_account_for_is_refused_before_any_model_call(planner):
    for text, why in [("put the cube in the left bin", "could be any of red_cube, blue_cube"),
                      ("tidy up the table", "'table' names no object"),
                      ("put the kettle in the left bin", "'kettle' names no object"),
                      ("sort the cubes", "no destination"),
                      ("stack the red cube on the left bin", "names no object to stack on")]:
        result = planner.plan(text, scene=SCENE, environment=seen(SCENE))
        assert result.status == "refused" and result.calls == (), (text, result.reason)
        assert why in result.reason, (text, result.reason)


def test_object_names_that_read_like_instructions_are_names_not_instructions(planner):
    scene = {"objects": [
        {"name": "leave_it_cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.45, -0.2],
         "rgba": [0.8, 0.1, 0.1, 1]},
        {"name": "put_in_left_bin", "half_extents": [0.02, 0.02, 0.02], "position": [0.6, -0.15],
         "rgba": [0.1, 0.2, 0.8, 1]}], "regions": SCENE["regions"]}
    result = planner.plan("put the leave_it_cube in the right bin", scene=scene, environment=seen(scene))
    assert result.status == "planned", result.reason
    assert _steps(result) == [("pick_and_place", "leave_it_cube", "right_bin")]
    result = planner.plan("hold the blue cube", scene=scene, environment=seen(scene))
    assert _steps(result) == [("pick", "put_in_left_bin", None)]


# -- (c) grounding that does not invent ---------------------------------------------------------------------


def test_a_destination_the_scene_does_not_have_is_refused_not_mapped_to_a_bin(planner):
    result = planner.plan("put the red cube in the kitchen sink", scene=SCENE, environment=seen(SCENE))
    assert result.status == "refused" and result.refusal == "unknown_destination"
    assert result.refused_by == "grounding" and result.calls == () and result.graph is None
    assert "'the kitchen sink'" in result.reason and "left_bin, right_bin" in result.reason
    middle = planner.plan("put the red cube in the middle bin", scene=SCENE, environment=seen(SCENE))
    assert middle.status == "refused" and middle.refusal == "unknown_destination" and "'middle'" in middle.reason
    green = planner.plan("put the red cube in the blue bin", scene=SCENE, environment=seen(SCENE))
    assert green.status == "refused" and green.refusal == "unknown_destination" and "no blue region" in green.reason
    shelf = planner.plan("stack the red cube on the green cube", scene=SCENE, environment=seen(SCENE))
    assert shelf.status == "refused" and shelf.calls == ()


# -- (d) other languages -------------------------------------------------------------------------------------


@pytest.mark.parametrize("text, language", [("mets le cube rouge dans le bac de gauche", "French"),
                                            ("pon el cubo rojo en la caja izquierda", "Spanish"),
                                            ("lege den roten Würfel in die linke Kiste", "German"),
                                            ("положи красный куб в левую корзину", "Cyrillic script"),
                                            ("把红色方块放进左边的箱子", "Chinese/Japanese script")])
def test_a_request_in_another_language_is_refused_saying_which_before_any_model_call(planner, text, language):
    assert detect_language(text) == language
    result = planner.plan(text, scene=SCENE, environment=seen(SCENE))
    assert result.status == "refused" and result.refusal == "unsupported_language"
    assert result.refused_by == "language" and result.calls == ()
    assert language in result.reason and "English only" in result.reason


def test_english_requests_and_scene_names_are_not_taken_for_another_language():
    for text in ["put the red cube in the left bin", "stack the red block on the blue one", "do nothing",
                 "put all cubes except the red one in the left bin", "pick up the red cube and hold it",
                 "put the la_tasse_rouge in the le_bac"]:
        assert detect_language(text, names=("la_tasse_rouge", "le_bac")) is None, text


def test_user_text_quoted_in_a_refusal_is_bounded_at_200_characters(planner):
    long = "mets le cube rouge dans le bac de gauche " * 20
    result = planner.plan(long, scene=SCENE)
    quoted = result.reason.split("the request ", 1)[1].split(" reads as", 1)[0]
    assert quoted == quote(long) and quoted.endswith(f"... ({len(long)} chars)")
    assert quote("x" * 500) == repr("x" * MAX_QUOTE_CHARS) + "... (500 chars)" and MAX_QUOTE_CHARS == 200


# -- the reading itself (no model) -----------------------------------------------------------------------------


def test_the_request_is_read_into_clauses_with_verb_objects_destination_and_quantifier():
    world = world_from_scene(SCENE)

    def read(text):
        m = read_request(text, world)
        return [(i.verb, i.movers(), i.destinations, i.excluded) for i in m.intents], [c for c, _ in m.problems]

    assert read("pick up the red cube and put it in the right bin") == (
        [("move", ("red_cube",), ("right_bin",), ())], [])
    assert read("put all cubes except the red one in the left bin") == (
        [("move", ("blue_cube",), ("left_bin",), ("red_cube",))], [])
    assert read("don't move the red cube") == ([("leave", ("red_cube",), (), ())], [])
    assert read("put each cube in the region of its colour")[1] == ["unknown_destination"]  # no coloured regions
    assert read("put the red cube in the bin on the left") == ([("move", ("red_cube",), ("left_bin",), ())], [])
    assert read("put a cube in the left bin") == ([("move", ("red_cube",), ("left_bin",), ())], [])
    assert read("stack the blue cube on it")[1] == ["not_understood"]  # "it": nothing earlier


# -- (a) the arm on a fresh workspace -------------------------------------------------------------------------


def test_with_nothing_perceived_the_target_is_chosen_from_the_declared_positions(targets):
    """The bin is near the SO-101's base, the cube half a metre away from it: before anything is
    perceived the tie-break between two 'unknown' reaches picked the SO-101 (its base is closest to
    the bin), and the pick failed ik_unreachable. The declared position rules it out."""
    scene = {"objects": [{"name": "red_cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.72, -0.3],
                          "rgba": [0.8, 0.1, 0.1, 1]}],
             "regions": [{"name": "left_bin", "center": [0.35, 0.2], "half_extents": [0.07, 0.07]}]}
    planner = GoalPlanner(_Scripted([_answer(("pick_and_place", "red_cube", "left_bin"))]), skills=skill_names(),
                          targets=targets)
    result = planner.plan("put the red cube in the left bin", scene=scene)
    assert result.status == "planned", result.reason
    assert [n.skill for n in result.graph.nodes] == ["observe", "pick_and_place"]  # still looks first
    assert {n.target for n in result.graph.nodes} == {"franka_tabletop"}
    reasons = result.selections["s1_pick_and_place_red_cube"]["reasons"]
    assert reasons["so101_tabletop"].startswith("out of reach") and "red_cube at 0.56 m (declared)" in \
        reasons["so101_tabletop"]
    assert "checked at the declared position" in reasons["franka_tabletop"]


def test_the_rule_ladder_moves_an_unreachable_node_to_a_target_that_reaches_it(tmp_path):
    from phyagentos.agent.recovery import RecoveryPlanner
    from phyagentos.agent.retarget import TargetChooser
    from phyagentos.protocol import Diagnosis, Revision, SessionRecord
    from phyagentos.protocol.lifecycle import utc_now

    now = utc_now()
    scene = {"objects": [{"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.72, -0.3]}]}
    rec = SessionRecord(session_id="r1-pick_cube-1", run_id="r1", node="pick_cube", skill="pick",
                        target="so101_tabletop", parameters={"object": "cube"}, scene=scene,
                        accept={"holding": "cube"}, created_at=now, updated_at=now)
    unreachable = Diagnosis(cause="ik_unreachable", category="planning", summary="IK did not converge")
    assert RecoveryPlanner().plan(rec, unreachable) is None  # without a chooser: the ladder ends, as before
    ladder = RecoveryPlanner(retarget=TargetChooser(Workspace.create(tmp_path / "ws")))
    rev = ladder.plan(rec, unreachable)
    assert rev is not None and rev.target == "franka_tabletop" and rev.cause == "ik_unreachable"
    assert rev.strategy == "switch_target_to_franka_tabletop" and rev.selection["so101_tabletop"].startswith("failed")
    # once along the lineage
    child = rec.model_copy(update={"session_id": "r1-pick_cube-2", "target": "franka_tabletop",
                                   "recovery": Revision(strategy=rev.strategy, cause="ik_unreachable", step=1,
                                                        target="franka_tabletop")})
    assert ladder.plan(child, unreachable, history=[rec]) is None


def test_a_node_after_a_look_first_observe_may_move_to_a_target_that_reaches_it(tmp_path):
    """A planned graph on a fresh workspace looks first (``s0_observe``) and every step depends on it.
    An observe moves nothing, so the step failing ik_unreachable on the SO-101 may still move to the
    Franka (measured: three planned steps on the SO-101 ended 'no recovery strategy left for
    ik_unreachable'); an upstream node that acted still keeps the node in its world."""
    from phyagentos.agent.recovery import RecoveryPlanner
    from phyagentos.agent.retarget import TargetChooser
    from phyagentos.protocol import Diagnosis, SessionRecord
    from phyagentos.protocol.lifecycle import utc_now

    now = utc_now()
    ws = Workspace.create(tmp_path / "ws")
    scene = {"objects": [{"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.72, -0.3]}],
             "regions": [{"name": "bin", "center": [0.36, 0.2], "half_extents": [0.07, 0.07]}]}

    def record(node, skill, depends_on=(), **params):
        return SessionRecord(session_id=f"r1-{node}-1", run_id="r1", node=node, skill=skill, target="so101_tabletop",
                             parameters=params, scene=scene, accept={"still": {"max_joint_motion_rad": 0.05}},
                             depends_on=list(depends_on), created_at=now, updated_at=now)

    ws.submit_session(record("s0_observe", "observe", samples=4))
    ws.submit_session(record("s0_pick", "pick", object="cube"))
    unreachable = Diagnosis(cause="ik_unreachable", category="planning", summary="IK did not converge")
    after_look = record("s1_pick_and_place_cube", "pick_and_place", ["s0_observe"], object="cube", region="bin")
    rev = RecoveryPlanner(retarget=TargetChooser(ws)).plan(after_look, unreachable)
    assert rev is not None and rev.target == "franka_tabletop"
    after_pick = record("s1_place_cube", "place", ["s0_pick"], object="cube", region="bin")
    chooser = TargetChooser(ws)
    assert RecoveryPlanner(retarget=chooser).plan(after_pick, unreachable) is None
    assert "depends on s0_pick" in chooser.choose(after_pick, cause="ik_unreachable").reasons["*"]


# -- the viewer's left and right among identical objects (LIBERO: "the left plate") ------------------------


def _mugs_and_plates(porcelain_colour):
    from phyagentos.agent.llm.world import Entity, World

    def e(name, colour=None):
        return Entity(name=name, kind="object", position=None, colour=colour)

    objects = (e("porcelain_mug_1", porcelain_colour), e("red_coffee_mug_1", "red"),
               e("white_yellow_mug_1", "white"), e("plate_1"), e("plate_2"))
    return World(objects=objects, regions=objects, source="test")


def test_the_left_and_the_right_plate_bind_the_twins_to_the_viewers_sides():
    m = read_request("put the white mug on the left plate and put the yellow and white mug on the right plate",
                     _mugs_and_plates("white"), relations=True)
    assert not m.problems
    assert [(i.objects, i.destinations) for i in m.intents] == [(("porcelain_mug_1",), ("plate_1",)),
                                                                 (("white_yellow_mug_1",), ("plate_2",))]
    assert m.where == {"plate_1": {"relation": "left"}, "plate_2": {"relation": "right"}}


def test_a_colour_named_that_an_object_of_unknown_colour_may_have_is_ambiguous():
    # the porcelain mug's colour is in no word of its name: "the white mug" may be it or the white-and-yellow one
    m = read_request("put the white mug on the left plate", _mugs_and_plates(None), relations=True)
    assert any("could be any of white_yellow_mug_1, porcelain_mug_1" in msg for _, msg in m.problems)
    m = read_request("put the yellow and white mug on the right plate", _mugs_and_plates(None), relations=True)
    assert not m.problems and m.intents[0].objects == ("white_yellow_mug_1",)


def test_a_side_word_reads_before_and_after_the_noun_and_only_among_twins():
    from phyagentos.agent.llm.world import world_from_declared

    world = world_from_declared(["akita_black_bowl_1", "akita_black_bowl_2", "wooden_tray_1"])
    for text in ("pick up the black bowl on the left and put it in the tray", "put the left bowl in the tray",
                 "move the leftmost black bowl into the tray"):
        m = read_request(text, world, relations=True)
        assert not m.problems, text
        assert m.intents[0].objects == ("akita_black_bowl_1",) and m.where == {"akita_black_bowl_1": {"relation": "left"}}
    # without relations (a caller that cannot hand one to perception) the side is not read
    assert read_request("put the left bowl in the tray", world).problems
    # regions named left and right are regions, not a side of twins
    m = read_request("put the red cube in the left bin", world_from_scene(SCENE), relations=True)
    assert not m.problems and m.intents[0].destinations == ("left_bin",) and not m.where


def test_a_porcelain_mug_is_the_white_mug_of_a_libero_scene():
    from phyagentos.agent.llm.world import world_from_declared

    world = world_from_declared(["porcelain_mug_1", "red_coffee_mug_1", "white_yellow_mug_1", "plate_1", "plate_2"])
    m = read_request("put the white mug on the left plate and put the yellow and white mug on the right plate", world,
                     relations=True)
    assert not m.problems
    assert [i.objects for i in m.intents] == [("porcelain_mug_1",), ("white_yellow_mug_1",)]
    assert m.where == {"plate_1": {"relation": "left"}, "plate_2": {"relation": "right"}}
