"""libero_spatial: the instruction tells two identical black bowls apart by a spatial relation;
the rule reader binds the bowl to one of the identical names and hands the relation to
perception (``where`` in the declared scene), never the BDDL goal or init placement."""

from __future__ import annotations

import pytest
import yaml

from phyagentos.agent.llm.meaning import read_request
from phyagentos.bench.libero import (FIRST_PICK_STILL_MAX_S, instruction_assumptions, instruction_nodes, instruction_plan,
                                     planner_world, prepare_libero_suite)
from phyagentos.errors import BenchError
from phyagentos.targets.libero import parse_bddl, resolve_task
from phyagentos.targets.libero.catalog import suite_tasks

BOWL, TWIN = "akita_black_bowl_1", "akita_black_bowl_2"
RAMEKIN, PLATE, COOKIES = "glazed_rim_porcelain_ramekin_1", "plate_1", "cookies_1"

#: LIBERO's ten libero_spatial instructions (task.language) and the reference each one reads to
EXPECTED = [
    ("pick up the black bowl between the plate and the ramekin and place it on the plate",
     {"relation": "between", "of": [PLATE, RAMEKIN]}),
    ("pick up the black bowl next to the ramekin and place it on the plate", {"relation": "next_to", "of": [RAMEKIN]}),
    ("pick up the black bowl from table center and place it on the plate", {"relation": "table_center"}),
    ("pick up the black bowl on the cookie box and place it on the plate", {"relation": "on", "of": [COOKIES]}),
    ("pick up the black bowl in the top drawer of the wooden cabinet and place it on the plate",
     {"relation": "in", "of": ["wooden_cabinet_1"], "part": "top drawer"}),
    ("pick up the black bowl on the ramekin and place it on the plate", {"relation": "on", "of": [RAMEKIN]}),
    ("pick up the black bowl next to the cookie box and place it on the plate", {"relation": "next_to", "of": [COOKIES]}),
    ("pick up the black bowl on the stove and place it on the plate", {"relation": "on", "of": ["flat_stove_1"]}),
    ("pick up the black bowl next to the plate and place it on the plate", {"relation": "next_to", "of": [PLATE]}),
    ("pick up the black bowl on the wooden cabinet and place it on the plate",
     {"relation": "on", "of": ["wooden_cabinet_1"]}),
]


def _problem(i=0):
    return parse_bddl(resolve_task("libero_spatial", i).bddl_path)


@pytest.mark.parametrize("i", range(10))
def test_every_libero_spatial_instruction_plans_a_pick_and_place_with_its_reference(i):
    task = suite_tasks("libero_spatial")[i]
    text, where = EXPECTED[i]
    assert task.instruction == text  # LIBERO's own wording, from its catalogue
    problem = parse_bddl(task.bddl_path)
    nodes, refs = instruction_plan(task.instruction, problem.objects, problem.fixtures)
    assert [(n["skill"], n["params"]) for n in nodes] == [("pick", {"still_max_s": FIRST_PICK_STILL_MAX_S, "object": BOWL}),
                                                          ("place", {"object": BOWL, "region": PLATE})]
    assert refs == {BOWL: where}
    assert instruction_nodes(task.instruction, problem.objects, problem.fixtures) == nodes


def test_the_reader_reads_relations_only_when_asked_and_the_plain_reading_is_unchanged():
    problem = _problem()
    world = planner_world(problem.objects, problem.fixtures)
    text = EXPECTED[1][0]
    plain = read_request(text, world)
    assert not plain.intents and any("could be any of akita_black_bowl_1, akita_black_bowl_2" in m
                                     for _, m in plain.problems)
    read = read_request(text, world, relations=True)
    assert not read.problems and read.where == {BOWL: {"relation": "next_to", "of": [RAMEKIN]}}
    # a bowl with no relation is still ambiguous; a relation is no destination
    with pytest.raises(BenchError, match="could be any of akita_black_bowl_1, akita_black_bowl_2: say which"):
        instruction_nodes("put the black bowl on the plate", problem.objects, problem.fixtures)
    # an object that is not one of several identical ones is read as before ("on" is its destination)
    nodes = instruction_nodes("pick up the ramekin and place it on the plate", problem.objects, problem.fixtures)
    assert [n["params"] for n in nodes] == [{"still_max_s": FIRST_PICK_STILL_MAX_S, "object": RAMEKIN},
                                              {"object": RAMEKIN, "region": PLATE}]


def test_other_wordings_of_the_relations_read_the_same():
    problem = _problem()
    for text, where in [
        ("lift the black bowl from the table center and put it on the plate", {"relation": "table_center"}),
        ("grab the bowl in the middle of the table and put it on the plate", {"relation": "table_center"}),
        ("take the black bowl beside the cookie box and set it on the plate", {"relation": "next_to", "of": [COOKIES]}),
        ("lift bowl from stove and put it on plate", {"relation": "on", "of": ["flat_stove_1"]}),
        ("pick up the black bowl on top of the ramekin and place it on the plate", {"relation": "on", "of": [RAMEKIN]}),
        ("put the black bowl next to the ramekin on the plate", {"relation": "next_to", "of": [RAMEKIN]}),
        ("pick up the black bowl on the left and place it on the plate", {"relation": "left"}),
        ("put the right black bowl on the plate", {"relation": "right"}),
        ("pick up the leftmost bowl and put it on the plate", {"relation": "left"}),
        # front and back as the scene camera sees the table (the front nearest it)
        ("pick up the black bowl at the back and place it on the plate", {"relation": "back"}),
        ("pick up the black bowl on the front and place it on the plate", {"relation": "front"}),
        ("put the front black bowl on the plate", {"relation": "front"}),
        # of two bowls, "in the middle" is the table's middle (a middle one is one of three or more)
        ("pick up the black bowl in the middle and place it on the plate", {"relation": "table_center"}),
        # a drawer named without its cabinet is the one thing with drawers's; "from" it is in it
        ("grab the black bowl from the middle drawer and set it on the plate",
         {"relation": "in", "of": ["wooden_cabinet_1"], "part": "middle drawer"}),
        ("fetch the black bowl in the top drawer and put it on the plate",
         {"relation": "in", "of": ["wooden_cabinet_1"], "part": "top drawer"}),
        ("pick the black bowl from the cabinet's bottom drawer and put it on the plate",
         {"relation": "in", "of": ["wooden_cabinet_1"], "part": "bottom drawer"}),
        ("lift the black bowl from the top drawer of the wooden cabinet and put it on the plate",
         {"relation": "in", "of": ["wooden_cabinet_1"], "part": "top drawer"}),
        # a level of a chest of drawers is its drawer (LIBERO-PRO's swap words it so)
        ("take the black bowl in the middle layer of the cabinet and put it on the plate",
         {"relation": "in", "of": ["wooden_cabinet_1"], "part": "middle drawer"}),
        ("pick the black bowl from the top tier of the wooden cabinet and set it on the plate",
         {"relation": "in", "of": ["wooden_cabinet_1"], "part": "top drawer"}),
    ]:
        nodes, refs = instruction_plan(text, problem.objects, problem.fixtures)
        assert refs == {BOWL: where}, text
        assert nodes[-1]["params"] == {"object": BOWL, "region": PLATE}, text


@pytest.mark.parametrize("text,why", [
    ("pick up the black bowl in the corner and place it on the plate", "a place relative to the viewer"),
    ("pick up the black bowl at the far end and place it on the plate", "not a relation the rules read"),
    ("pick up the black bowl next to the sink and place it on the plate", "'the sink' names nothing declared"),
    ("pick up the black bowl between the plate and place it on the plate", "'between' needs two landmarks"),
    ("pick up the black bowl next the plate and place it on the plate", "'next' without 'to'"),
    ("pick up the black bowl from the top drawer of the sink and place it on the plate", "'the sink' names nothing"),
    ("pick up the black bowl from the drawer thing and place it on the plate", "the drawer of what"),
])
def test_unreadable_relations_are_refused_with_the_reason(text, why):
    problem = _problem()
    with pytest.raises(BenchError, match=why):
        instruction_nodes(text, problem.objects, problem.fixtures)


def test_perception_and_the_reader_know_the_same_relations():
    from phyagentos.agent.llm.meaning import RELATIONS
    from phyagentos.perception.descriptors import WHERE_RELATIONS

    assert set(RELATIONS) == set(WHERE_RELATIONS)


def test_two_references_bind_the_two_identical_names():
    problem = _problem()
    text = ("pick up the black bowl next to the ramekin and place it on the plate, then pick up the black bowl "
            "on the cookie box and place it on the ramekin")
    nodes, refs = instruction_plan(text, problem.objects, problem.fixtures)
    assert refs == {BOWL: {"relation": "next_to", "of": [RAMEKIN]}, TWIN: {"relation": "on", "of": [COOKIES]}}
    assert [n["id"] for n in nodes] == [f"pick_{BOWL}", f"place_{BOWL}", f"pick_{TWIN}", f"place_{TWIN}"]


def _workspace_with_looks(tmp_path):
    """A bench workspace whose looks caches (objects' and fixtures') are given (measuring them
    needs the simulator), so that preparing the suite builds nothing."""
    ws = tmp_path / "ws"
    (ws / "libero").mkdir(parents=True)
    look = {"shape": "cylinder", "colour": [0.1, 0.1, 0.1], "size_m": [0.12, 0.12, 0.05]}
    cats = set(_problem().objects.values())
    from phyagentos.bench.libero import _FIXTURE_LOOKS_METHOD, _LOOKS_METHOD, _fixture_world

    cache = {"_method": _LOOKS_METHOD, "_measured_tasks": [f"libero_spatial/{i}" for i in range(10)],
             **{c: look for c in cats}}
    (ws / "libero" / "descriptors.yaml").write_text(yaml.safe_dump(cache))
    fixture_look = {"size_m": [0.26, 0.22, 0.23], "place": {"offset_m": [0.0, -0.015], "half_extents_m": [0.125, 0.094],
                                                            "height_m": 0.227}}
    worlds = {}
    for i in range(10):  # libero_spatial's worlds (one cabinet pose for all ten, as it happens)
        problem = parse_bddl(resolve_task("libero_spatial", i).bddl_path)
        worlds[_fixture_world(problem)] = {"measured_as": f"libero_spatial/{i}",
                                           "looks": {c: fixture_look for c in problem.fixtures.values() if c != "table"}}
    (ws / "libero" / "fixture_looks.yaml").write_text(yaml.safe_dump({"_method": _FIXTURE_LOOKS_METHOD, "worlds": worlds}))
    return ws


def test_the_suite_declares_the_reference_on_the_bowl_and_never_an_init_placement(tmp_path):
    """prepare_libero_suite writes the reference into the episode's declared scene."""
    ws = _workspace_with_looks(tmp_path)
    suite, ids, seeds = prepare_libero_suite("libero_spatial", ws, tasks=("0", "4"), seeds=(0,))
    assert ids == ("t0", "t4")
    g0 = yaml.safe_load((suite.parent / "t0.yaml").read_text())
    objects = {o["name"]: o for o in g0["scene"]["objects"]}
    assert objects[BOWL]["where"] == {"relation": "between", "of": [PLATE, RAMEKIN]}
    assert "where" not in objects[TWIN] and {PLATE, RAMEKIN, COOKIES} <= set(objects)
    # the fixtures carry their measured looks (perception finds them), the table none
    fixtures = {f["name"]: f for f in g0["scene"]["fixtures"]}
    assert fixtures["wooden_cabinet_1"]["place"]["height_m"] == 0.227 and "size_m" not in fixtures["main_table"]
    text = (suite.parent / "t0.yaml").read_text()
    assert "region" not in str(g0["scene"]) and ":init" not in text and "goal" not in g0["scene"]
    # the table scene's tcp box (the template's would hold the arm's start pose outside)
    box = yaml.safe_load(suite.read_text())["tasks"][0]["safety"]["workspace_box"]
    assert box["min"][0] < -0.21 < box["max"][0] and box["min"][2] < 0.9 < 1.17 < box["max"][2]
    planning = yaml.safe_load((suite.parent / "planning.yaml").read_text())
    assert planning["planned"] == [0, 4] and planning["refused"] == {}
    assert planning["spatial_references"][4] == {BOWL: {"relation": "in", "of": ["wooden_cabinet_1"], "part": "top drawer"}}
    # the perceiver reads the declared reference through the target's declared objects
    from phyagentos.perception import ObjectDescriptor

    assert ObjectDescriptor.from_dict(objects[BOWL]).where.relation == "between"


def test_a_generated_run_seeds_libero_s_sampler_instead_of_naming_init_states(tmp_path):
    """``--generated``: the same graphs with ``scene.generated`` and no init state, in a suite
    of their own (never mistaken for the measured one); any non-negative seed is valid, an init
    index is not required."""
    from phyagentos.bench.compiler import plan_episodes
    from phyagentos.bench.suite import load_suite

    ws = _workspace_with_looks(tmp_path)
    suite, ids, seeds = prepare_libero_suite("libero_spatial", ws, tasks=("7",), seeds=(500, 70001), generated=True)
    assert suite.parent.name == "libero_spatial_generated" and seeds == (500, 70001)
    doc = yaml.safe_load(suite.read_text())
    assert "seed_to_scene" not in doc["tasks"][0] and "placement sampler" in doc["description"]
    eps = plan_episodes(load_suite(suite), bench_id="b", seeds=seeds, split="generated", memory="off",
                        protocol="measurement")
    assert [(e.seed, e.scene["generated"], "init" in e.scene) for e in eps] == [(500, True, False), (70001, True, False)]
    with pytest.raises(BenchError, match="has no init state 70001"):
        prepare_libero_suite("libero_spatial", ws, tasks=("7",), seeds=(70001,))
    with pytest.raises(BenchError, match="sampler seed -1 out of range"):
        prepare_libero_suite("libero_spatial", ws, tasks=("7",), seeds=(-1,), generated=True)


def test_a_fixture_look_serves_only_the_world_it_was_measured_in(tmp_path):
    """A fixture's look holds world-frame directions (a drawer's axis, its place patch's
    offset): libero_goal's cabinet (yaw pi) and libero_spatial_swap task 3's (moved to the
    plate's region, unrotated) are not libero_spatial's, so each gets its own look; a
    reworded suite shares its standard suite's world."""
    from phyagentos.bench.libero import _fixture_looks, _fixture_world

    ws = _workspace_with_looks(tmp_path)
    spatial = _fixture_world(_problem(0))
    goal = _fixture_world(parse_bddl(resolve_task("libero_goal", 0).bddl_path))
    swapped = _fixture_world(parse_bddl(resolve_task("libero_spatial_swap", 3).bddl_path))
    assert len({spatial, goal, swapped}) == 3
    assert _fixture_world(parse_bddl(resolve_task("libero_spatial_lan", 0).bddl_path)) == spatial
    path = ws / "libero" / "fixture_looks.yaml"
    cache = yaml.safe_load(path.read_text())
    goal_look = {"size_m": [0.26, 0.22, 0.23], "drawers": [{"name": "top", "axis": [-1.0, 0.0]}]}
    cache["worlds"][goal] = {"measured_as": "libero_goal/0",
                             "looks": {"wooden_cabinet": goal_look, "flat_stove": {}, "wine_rack": {}}}
    path.write_text(yaml.safe_dump(cache))
    looks = _fixture_looks(ws, "libero_goal", [0, 1])  # both measured: nothing is built
    assert looks[0]["wooden_cabinet"] == looks[1]["wooden_cabinet"] == goal_look
    assert _fixture_looks(ws, "libero_spatial_lan", [0])[0]["wooden_cabinet"]["place"]["height_m"] == 0.227


def _libero_90(i):
    task = suite_tasks("libero_90")[i]
    return task.instruction, parse_bddl(task.bddl_path)


BOWL3 = "akita_black_bowl_3"


@pytest.mark.parametrize("i,where,moves", [
    # LIBERO-90 KITCHEN_SCENE2 (three identical black bowls and a plate): the bowls are told apart as the
    # scene camera sees the table, the front one nearest it, the middle one between the other two
    (12, {BOWL: {"relation": "back"}}, [(BOWL, PLATE)]),
    (13, {BOWL: {"relation": "front"}}, [(BOWL, PLATE)]),
    (14, {BOWL: {"relation": "middle"}}, [(BOWL, PLATE)]),
    (15, {BOWL: {"relation": "middle"}}, [(BOWL, "wooden_cabinet_1")]),
    (16, {BOWL: {"relation": "front"}, TWIN: {"relation": "middle"}}, [(BOWL, TWIN)]),
    (17, {BOWL: {"relation": "middle"}, TWIN: {"relation": "back"}}, [(BOWL, TWIN)]),  # on the back black bowl
])
def test_liberos_front_back_and_middle_bowls_are_read_as_references_for_perception(i, where, moves):
    text, problem = _libero_90(i)
    nodes, refs = instruction_plan(text, problem.objects, problem.fixtures)
    assert refs == where, text
    assert [(n["params"]["object"], n["params"]["region"]) for n in nodes if n["skill"] == "place"] == moves, text


def test_a_side_word_that_is_no_side_of_the_object_phrase_is_not_read_as_one():
    text, problem = _libero_90(12)
    objects, fixtures = problem.objects, problem.fixtures
    # "back" as an adverb, not the object's side: refused, never read as the bowl at the back
    with pytest.raises(BenchError, match="'back' names no object"):
        instruction_nodes("put the black bowl back on the plate", objects, fixtures)
    # "the back compartment" is a part of a destination, never a side of the object moved
    _, two = _libero_90(3)  # two butters beside a black bowl and a pudding
    with pytest.raises(BenchError, match="could be any of butter_1, butter_2"):
        instruction_nodes("put the butter in the back of the cabinet", two.objects, two.fixtures)
    nodes, refs = instruction_plan(suite_tasks("libero_90")[3].instruction, two.objects, two.fixtures)
    assert refs == {"butter_1": {"relation": "back"}}
    assert [n["skill"] for n in nodes] == ["hook_drawer", "pick", "place", "push_drawer"]


def test_the_frying_pan_is_the_declared_frypan():
    text, problem = _libero_90(18)
    assert text == "put the frying pan on the stove"
    nodes = instruction_nodes(text, problem.objects, problem.fixtures)
    assert [(n["skill"], n["params"].get("object")) for n in nodes] == [("pick", "chefmate_8_frypan_1"),
                                                                        ("place", "chefmate_8_frypan_1")]
    # a refusal quotes the words the request said, not the one word the names write
    with pytest.raises(BenchError, match="'the frying pan under the shelf': 'under', 'shelf' names no") as refused:
        instruction_nodes("put the frying pan under the shelf on the stove", problem.objects, problem.fixtures)
    assert "frypan under" not in str(refused.value)
    # ... and so does a word set aside: "the one frying pan"
    assert instruction_assumptions("put the cast iron frying pan on the stove", problem.objects,
                                   problem.fixtures) == [
        "'the cast iron frying pan': 'cast', 'iron' name nothing here; read as chefmate_8_frypan_1, the one frying pan"]


def test_a_landmark_named_by_the_colour_its_name_implies_is_that_thing():
    # LIBERO-90 task 34: "the white mug" is the porcelain mug, the only mug left once the one moved is set aside
    text, problem = _libero_90(34)
    assert text == "put the yellow and white mug to the front of the white mug"
    nodes = instruction_nodes(text, problem.objects, problem.fixtures)
    assert nodes[-1]["accept"][0] == {"beside": {"landmark": "porcelain_mug_1", "object": "white_yellow_mug_1",
                                                 "side": "front"}}
