"""Ordinary phrasings an outside user types are read by class, and never over-read (issue 35, phrasing).

Requests written by someone who had not read the rules were refused for words that change nothing
of what is asked ("I'd like you to ...", "after that", "doesn't matter which", "keep holding it",
"the reds"). Each class is read by :mod:`phyagentos.agent.llm.phrasing`; each test beside it says
what the class must *not* be taken for. The phrasings here are written for these tests.
"""

from __future__ import annotations

import pytest
from planning import make_planner, seen

from phyagentos.agent.llm.meaning import read_request
from phyagentos.agent.llm.world import world_from_scene


def _cube(name, colour, half, x, y):
    rgba = {"red": [0.8, 0.1, 0.1, 1], "blue": [0.1, 0.2, 0.8, 1], "green": [0.1, 0.7, 0.2, 1],
            "yellow": [0.9, 0.8, 0.1, 1]}[colour]
    return {"name": name, "half_extents": [half] * 3, "position": [x, y], "rgba": rgba}


BINS = [{"name": "left_bin", "center": [0.42, 0.24], "half_extents": [0.07, 0.07], "rgba": [0.5, 0.5, 0.5, 0.3]},
        {"name": "right_bin", "center": [0.62, 0.24], "half_extents": [0.07, 0.07], "rgba": [0.95, 0.95, 0.95, 0.3]}]
# a 4 cm red, a 6 cm blue and a 3 cm green cube, two bins
SCENE = {"objects": [_cube("red_cube", "red", 0.02, 0.45, -0.2), _cube("blue_cube", "blue", 0.03, 0.6, -0.15),
                     _cube("green_cube", "green", 0.015, 0.52, -0.05)], "regions": BINS}
# two reds (big, small) and a blue
REDS = {"objects": [_cube("big_red_cube", "red", 0.025, 0.45, -0.2), _cube("small_red_cube", "red", 0.015, 0.58, -0.22),
                    _cube("blue_cube", "blue", 0.02, 0.52, -0.05)], "regions": BINS}
# one grey bin only
ONE_BIN = {**SCENE, "regions": BINS[:1]}
# a red and a blue region; the green cube has none of its colour
COLOUR_REGIONS = {"objects": SCENE["objects"], "regions": [
    {"name": "red_region", "center": [0.42, 0.22], "half_extents": [0.07, 0.07], "rgba": [0.8, 0.1, 0.1, 0.3]},
    {"name": "blue_region", "center": [0.62, 0.22], "half_extents": [0.07, 0.07], "rgba": [0.1, 0.2, 0.8, 0.3]}]}


def read(text, scene=SCENE):
    """(intents as (verb, movers, destinations), problem codes, nothing_to_do) of ``text`` over ``scene``."""
    m = read_request(text, world_from_scene(scene))
    return [(i.verb, i.movers(), i.destinations) for i in m.intents], [c for c, _ in m.problems], m.nothing_to_do


def same_as(plain, variants, scene=SCENE):
    want = read(plain, scene)
    assert not want[1], (plain, want)
    for text in variants:
        assert read(text, scene) == want, (text, read(text, scene), plain)


def refused(text, scene=SCENE, code=None):
    intents, problems, nothing = read(text, scene)
    assert problems and not nothing, (text, intents)
    if code is not None:
        assert problems[0] == code, (text, problems)


@pytest.fixture(scope="module")
def planner(tmp_path_factory):
    return make_planner(tmp_path_factory.mktemp("ws"))



# -- polite and indirect openers --------------------------------------------------------------------------------


def test_polite_openers_do_not_change_the_plan():
    same_as("put the red cube in the left bin", [
        "Could you please put the red cube in the left bin?", "can you put the red cube in the left bin",
        "I'd like you to put the red cube in the left bin.", "I want you to put the red cube in the left bin",
        "would you mind putting the red cube in the left bin?", "Please, put the red cube in the left bin",
        "okay, put the red cube in the left bin", "hey robot, put the red cube in the left bin",
        "I'd like the red cube placed in the left bin", "I want the red cube in the left bin",
        "the red cube should go in the left bin", "would it be possible to put the red cube in the left bin?",
        "put the red cube in the left bin, thanks", "let's put the red cube in the left bin"])
    same_as("set the blue cube onto the red cube", ["Can you set the blue cube onto the red cube?"])


def test_polite_openers_plan_the_same_steps_as_the_plain_request(planner):
    plain = planner.plan("put the red cube in the left bin", scene=SCENE, environment=seen(SCENE))
    polite = planner.plan("Could you please put the red cube in the left bin for me?", scene=SCENE,
                          environment=seen(SCENE))
    assert polite.status == plain.status == "planned", polite.reason
    assert [(s.skill, s.object, s.destination) for s in polite.steps] == [("pick_and_place", "red_cube", "left_bin")]
    # "can" is a word for a tin can only when it is not "can you"
    stack = planner.plan("Can you set the blue cube onto the red cube?", scene=SCENE, environment=seen(SCENE))
    assert stack.status == "planned", stack.reason
    assert [(s.object, s.destination) for s in stack.steps] == [("blue_cube", "red_cube")]


def test_a_question_after_a_polite_opener_is_not_a_move():
    for text in ["can you see the red cube?", "could you tell me whether the red cube is in the left bin?",
                 "is the red cube in the left bin?", "the red cube is in the left bin", "I'd like the red cube",
                 "can you reach the blue cube?", "the red cube could be in the left bin",
                 "the red cube should not be in the left bin", "the red cube shouldn't go in the left bin"]:
        refused(text)


# -- filler -------------------------------------------------------------------------------------------------------


def test_filler_words_do_not_change_the_plan():
    same_as("move the green cube to the right bin", [
        "just move the green cube to the right bin", "go ahead and move the green cube to the right bin",
        "move the green cube to the right bin for me", "move the green cube over to the right bin pls",
        "actually, just move the green cube to the right bin", "simply move the green cube to the right bin"])
    # "off the table": the support every object starts on, not an object
    same_as("lift the smallest cube", ["lift the smallest cube off the table", "pick the smallest cube up from the table"])


def test_filler_does_not_hide_a_word_that_names_nothing():
    refused("just put the red cube in the kitchen sink for me", code="unknown_destination")
    refused("put the red cube in the gripper please", code="unknown_destination")  # no region at all
    refused("please put the red cube on the table", code="unknown_destination")
    refused("just put the kettle in the left bin", code="unknown_object")


# -- sequence connectives ----------------------------------------------------------------------------------------


def test_after_that_sequences_two_moves():
    two = [("move", ("red_cube",), ("left_bin",)), ("move", ("blue_cube",), ("right_bin",))]
    for text in ["put the red cube in the left bin, after that put the blue cube in the right bin",
                 "put the red cube in the left bin and after that put the blue cube in the right bin",
                 "put the red cube in the left bin; afterwards put the blue cube in the right bin",
                 "put the red cube in the left bin. Once that's done, put the blue cube in the right bin.",
                 "put the red cube in the left bin and when you're done put the blue cube in the right bin",
                 "first, put the red cube in the left bin. Next, put the blue cube in the right bin",
                 "put the red cube in the left bin and then the blue cube in the right bin",
                 "put the red cube in the left bin. Then put the blue cube in the right bin.",
                 "put the red cube in the left bin, and finally put the blue cube in the right bin"]:
        assert read(text) == (two, [], False), (text, read(text))


def test_once_youve_and_before_you_order_the_two_moves():
    first_red = [("move", ("red_cube",), ("left_bin",)), ("move", ("blue_cube",), ("right_bin",))]
    for text in ["put the blue cube in the right bin once you've moved the red cube to the left bin",
                 "put the blue cube in the right bin after you have put the red cube in the left bin",
                 "once you've placed the red cube in the left bin, put the blue cube in the right bin",
                 "put the red cube in the left bin before you move the blue cube to the right bin",
                 "before you put the blue cube in the right bin, put the red cube in the left bin"]:
        assert read(text) == (first_red, [], False), (text, read(text))


def test_a_sequence_word_with_nothing_after_it_is_refused(planner):
    for text in ["put the red cube in the left bin and after that", "put the red cube in the left bin, then",
                 "after that, put the red cube in the left bin", "put the red cube in the left bin and afterwards",
                 "then put the red cube in the left bin", "after you put the red cube in the left bin",
                 "once you've moved the red cube to the left bin"]:
        refused(text, code="not_understood")
    result = planner.plan("put the red cube in the left bin and after that", scene=SCENE, environment=seen(SCENE))
    assert result.status == "refused" and result.calls == () and "sequence word" in result.reason
    # "next to" and "the second" are not sequence words
    refused("put the red cube next to the blue cube")
    assert "then" not in read_request("put the red cube in the second bin", world_from_scene(SCENE)).text


# -- indifference --------------------------------------------------------------------------------------------------


def test_indifference_leaves_the_choice_to_the_count():
    one = read("put one cube in the left bin")
    same_as("put one cube in the left bin", [
        "put a cube in the left bin, doesn't matter which", "put any cube in the left bin",
        "put whichever cube you like in the left bin", "put either of the cubes in the left bin",
        "put the cube in the left bin, it doesn't matter which", "put any one of the cubes in the left bin"])
    assert one[0][0][1] == ("red_cube",)  # the first candidate, in the scene's order
    m = read_request("put any two of the cubes in the right bin, no matter which", world_from_scene(SCENE))
    assert [(i.count, len(i.movers()), i.destinations) for i in m.intents] == [(2, 2, ("right_bin",))]


def test_indifference_does_not_relax_a_destination_a_count_or_a_named_object():
    refused("put any two of the cubes in the kitchen sink, doesn't matter which", code="unknown_destination")
    refused("put any four of the cubes in the left bin, doesn't matter which", code="not_understood")
    # a named object stays that object: indifference is not "any object"
    assert read("put the red cube in the left bin, doesn't matter which") == (
        [("move", ("red_cube",), ("left_bin",))], [], False)
    # "any" of a plural keeps its count of one; "the cubes" without it is every cube
    assert read("put the cubes in the left bin")[0][0][1] == ("red_cube", "blue_cube", "green_cube")


# -- exclusivity -------------------------------------------------------------------------------------------------


def test_nothing_else_and_only_add_nothing_to_the_plan():
    same_as("put the red cube in the left bin", [
        "put the red cube in the left bin, nothing else", "put only the red cube in the left bin",
        "put the red cube in the left bin and don't touch anything else",
        "put the red cube in the left bin, leave the rest where they are",
        "put the red cube in the left bin and leave the others alone", "just put the red cube in the left bin. Nothing else."])


def test_nothing_else_is_not_a_request_to_do_nothing_and_names_stay_named():
    intents, problems, nothing = read("put the red cube in the left bin, nothing else")
    assert not nothing and intents == [("move", ("red_cube",), ("left_bin",))]
    # an object named to stay is not "the rest": it is left where it is, and a plan moving it is refused
    m = read_request("put the red cube in the left bin but don't touch the blue cube", world_from_scene(SCENE))
    assert [(i.verb, i.objects) for i in m.intents] == [("move", ("red_cube",)), ("leave", ("blue_cube",))]
    refused("leave the rest")  # "the rest" of nothing: not a request to do nothing


# -- holding --------------------------------------------------------------------------------------------------------


def test_holding_variants_are_a_hold():
    same_as("pick up the red cube and hold it", [
        "pick up the red cube and keep holding it", "pick up the red cube and don't let go",
        "pick up the red cube and don't let go of it", "pick up the red cube and don't put it down",
        "grab the red cube and hold it in the air for me", "pick up and keep the red cube",
        "hold on to the red cube", "lift the red cube and keep it in the gripper", "hold onto the red cube",
        "pick up the red cube and keep a firm grip on it", "pick the red cube up and just keep it"])


def test_dont_put_it_down_is_a_hold_not_a_place(planner):
    result = planner.plan("pick up the blue cube and don't put it down", scene=SCENE, environment=seen(SCENE))
    assert result.status == "planned", result.reason
    assert [(s.skill, s.object, s.destination) for s in result.steps] == [("pick", "blue_cube", None)]
    # putting it down somewhere is a move; "hold onto" is not a stack; letting go is no hold
    assert read("pick up the red cube and put it down in the left bin")[0] == [("move", ("red_cube",), ("left_bin",))]
    assert read("hold onto the blue cube")[0] == [("hold", ("blue_cube",), ())]
    refused("let go of the red cube")
    refused("pick up the red cube and hold it and shake it")  # 'shake' is no part of a hold
    refused("pick up the red cube and don't put it down in the left bin")  # held and left at once: say which
    refused("pick up the red cube, keep holding it and put the blue cube in the left bin")  # a hold is last


# -- doing nothing -----------------------------------------------------------------------------------------------


def test_doing_nothing_variants_plan_nothing():
    for text in ["don't touch anything", "leave it all as is", "Never mind.", "leave everything untouched",
                 "the cubes should stay where they are", "please do not disturb anything",
                 "actually, never mind - leave everything exactly as it is", "leave them all where you found them"]:
        intents, problems, nothing = read(text)
        assert nothing and not problems, (text, intents, problems)


def test_touch_without_a_negation_is_not_a_move_and_a_named_object_is_left_alone():
    refused("touch the red cube")
    refused("never mind the red cube")
    assert read("don't touch the red cube and put the blue cube in the right bin")[0] == [
        ("leave", ("red_cube",), ()), ("move", ("blue_cube",), ("right_bin",))]


# -- plurals and synonyms ------------------------------------------------------------------------------------


def test_plural_colour_words_and_ones_mean_every_object_of_that_colour():
    both = [("move", ("big_red_cube", "small_red_cube"), ("left_bin",))]
    for text in ["put the reds in the left bin", "put the red ones in the left bin", "put the red blocks in the left bin",
                 "put the red cubes in the left bin"]:
        assert read(text, REDS)[0] == both, (text, read(text, REDS))


def test_a_singular_colour_word_among_two_is_still_asked_to_say_which():
    refused("put the red one in the left bin", REDS, code="not_understood")
    refused("put the red cube in the left bin", REDS, code="not_understood")
    refused("put the greens in the left bin", REDS)


def test_region_synonyms_name_the_region_and_block_names_a_cube():
    same_as("put the red cube in the left bin", ["put the red block in the left bin", "put the red brick in the left bin"])
    for text in ["put the red cube in the container", "put the red cube in the box", "put the red cube in the bin",
                 "put the red cube in the tray"]:
        assert read(text, ONE_BIN)[0] == [("move", ("red_cube",), ("left_bin",))], (text, read(text, ONE_BIN))


def test_a_word_for_another_kind_of_place_is_no_synonym():
    refused("put the red cube in the basket", ONE_BIN, code="unknown_destination")
    refused("put the red cube in the drawer", ONE_BIN, code="unknown_destination")
    assert read("put the red cube on the box", ONE_BIN)[0] != [("move", ("red_cube",), ("left_bin",))]


def test_the_object_called_x_is_x():
    scene = {"objects": [_cube("dont_touch", "blue", 0.02, 0.6, -0.18), _cube("red_cube", "red", 0.02, 0.5, -0.02)],
             "regions": BINS}
    same_as("move dont_touch into the left bin", ["move the object called dont_touch into the left bin",
                                                  "move the cube named 'dont_touch' into the left bin"], scene)
    refused("move the cube called kettle into the left bin", scene, code="unknown_object")
    # a name that reads like an instruction stays a name
    assert read("don't touch the cube called dont_touch", scene)[0] == [("leave", ("dont_touch",), ())]


# -- where possible, comparatives over a named set -------------------------------------------------------------


def test_if_there_is_one_leaves_objects_without_a_region_of_their_colour():
    m = read_request("put each cube in the region of its colour, if there is one", world_from_scene(COLOUR_REGIONS))
    assert not m.problems
    (it,) = m.intents
    assert it.by_colour and it.movers() == ("red_cube", "blue_cube") and it.excluded == ("green_cube",)


def test_without_if_there_is_one_a_missing_colour_region_is_still_refused():
    refused("put each cube in the region of its colour", COLOUR_REGIONS, code="unknown_destination")
    refused("put the green cube in the region of its colour, if there is one", COLOUR_REGIONS,
            code="unknown_destination")


def test_the_smaller_of_the_two_compares_within_the_two():
    assert read("take the smaller of the two red cubes and put it in the right bin", REDS)[0] == [
        ("move", ("small_red_cube",), ("right_bin",))]
    refused("take the smaller of the three red cubes and put it in the right bin", REDS, code="not_understood")


# --------------------------------------------------------------------------- a definite region among several


def test_the_bin_among_two_bins_is_asked_about_not_guessed():
    for text in ("put the red cube in the bin", "move the blue cube into the tray", "drop the green cube in the box"):
        refused(text, code="not_understood")
    intents, problems, _ = read("put the red cube in the bin", ONE_BIN)
    assert not problems and intents == [("move", ("red_cube",), ("left_bin",))]


def test_a_bin_either_bin_or_a_named_bin_leaves_no_question():
    for text in ("put the red cube in a bin", "put the red cube in either bin", "put the red cube in any bin"):
        intents, problems, _ = read(text)
        assert not problems and intents[0][2] == ("left_bin", "right_bin"), (text, intents, problems)
    intents, problems, _ = read("put the red cube in the left bin")
    assert not problems and intents[0][2] == ("left_bin",)
