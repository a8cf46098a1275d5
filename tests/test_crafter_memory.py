"""Memory that has to be earned: recipes from failed and successful makes, deaths from traces."""

from __future__ import annotations

import pytest
import yaml

pytest.importorskip("crafter")

from phyagentos.agent.memory.deaths import correction_acted, correction_for, diagnose_death  # noqa: E402
from phyagentos.agent.memory.recipes import hypothesis  # noqa: E402
from phyagentos.app.orchestrator import run_goal_graph  # noqa: E402
from phyagentos.protocol import Workspace  # noqa: E402

MAKE_FIRST = {
    "version": 1, "name": "crafter_make_first", "description": "try a pickaxe before any table exists",
    "defaults": {"target": "crafter", "limits": {"execution_timeout_s": 120}},
    "nodes": [{"id": "make_wood_pickaxe", "skill": "game_make", "params": {"item": "wood_pickaxe", "max_tries": 2},
               "accept": {"achieved": "make_wood_pickaxe"}}],
}
TABLE_THEN_MAKE = {
    "version": 1, "name": "crafter_table_then_make", "description": "wood, a table, then a pickaxe",
    "defaults": {"target": "crafter", "limits": {"execution_timeout_s": 120}},
    "nodes": [
        {"id": "collect_wood", "skill": "game_collect", "params": {"material": "tree", "item": "wood", "count": 3},
         "accept": {"has": {"item": "wood", "min": 3}}},
        {"id": "place_table", "skill": "game_place", "params": {"item": "table"}, "depends_on": ["collect_wood"],
         "accept": {"achieved": "place_table"}},
        {"id": "walk_away", "skill": "game_explore", "params": {"steps": 6}, "depends_on": ["place_table"],
         "accept": {"has": {"item": "wood", "min": 1}}},
        {"id": "make_wood_pickaxe", "skill": "game_make", "params": {"item": "wood_pickaxe"},
         "depends_on": ["walk_away"], "accept": {"achieved": "make_wood_pickaxe"}},
    ],
}


def _lessons(ws):
    return Workspace.open(ws).read("LESSONS").data


def test_a_failed_make_becomes_a_candidate_that_later_successes_verify(tmp_path):
    ws = tmp_path / "ws"
    first, second = tmp_path / "first.yaml", tmp_path / "second.yaml"
    first.write_text(yaml.safe_dump(MAKE_FIRST))
    second.write_text(yaml.safe_dump(TABLE_THEN_MAKE))

    # 1. no wood, no table: the make fails (inventory unchanged) -> a candidate, no lesson
    report = run_goal_graph(first, ws, seed=2)
    assert not report.succeeded
    doc = _lessons(ws)
    assert doc.lessons == []
    failed = [c for c in doc.candidates if c.objective == "make wood_pickaxe"]
    assert failed and failed[0].cause == "recipe.unknown" and failed[0].revision == {}

    # 2. after a table is placed the unknown recipe is searched for and found: a hypothesis,
    #    still a candidate (formed post hoc by the session that found it)
    report = run_goal_graph(second, ws, seed=2)
    assert report.succeeded, report.to_dict()
    doc = _lessons(ws)
    assert doc.lessons == []
    (cand,) = [c for c in doc.candidates if c.objective == "make wood_pickaxe"]
    # the stations (handed to the skill as ``near``) and what the recipe uses (to tell an
    # informative planned failure from one without the items in hand)
    assert cand.cause == "recipe.learned" and cand.revision == {"near": ["table"], "uses": {"wood": 1}}
    assert "uses 1 wood" in cand.correction
    assert set(failed[0].provenance) <= set(cand.provenance)  # the failure is part of its evidence

    # 3. another world: the ContextBuilder hands the hypothesis over, the planned make
    #    succeeds, and that session verifies it
    report = run_goal_graph(second, ws, seed=8)
    assert report.succeeded, report.to_dict()
    doc = _lessons(ws)
    (lesson,) = [entry for entry in doc.lessons if entry.objective == "make wood_pickaxe"]
    make = next(s for s in report.sessions if s.node == "make_wood_pickaxe")
    assert lesson.verified and lesson.verified_by == [make.session_id]
    assert lesson.id in make.memory
    assert "recipe" in Workspace.open(ws).path("KNOWLEDGE").read_text()


def test_recipe_hypothesis_is_what_the_success_had_and_the_failures_lacked():
    win = {"ok": True, "nearby": ["grass", "table", "tree"], "inventory_before": {"wood": 2, "stone": 1},
           "inventory_after": {"wood": 1, "stone": 1, "wood_pickaxe": 1}}
    lacks_both = {"ok": False, "nearby": ["grass", "water"], "inventory_before": {"wood": 1}}
    had_tree = {"ok": False, "nearby": ["grass", "tree"], "inventory_before": {"wood": 1}}
    no_wood = {"ok": False, "nearby": ["grass", "tree"], "inventory_before": {}}
    assert hypothesis([lacks_both, had_tree, win]) == (["table"], {"wood": 1})
    assert hypothesis([lacks_both, win]) == (["table", "tree"], {"wood": 1})  # ambiguous: ask for both
    assert hypothesis([no_wood, win]) == (["table", "tree"], {"wood": 1})     # uninformative failure
    assert hypothesis([lacks_both]) is None


@pytest.mark.parametrize("damage, death, cause", [
    ({"adjacent": ["zombie"], "sleeping": True, "daylight": 0.1}, {"drink": 5, "food": 5}, "death.zombie_asleep"),
    ({"adjacent": ["zombie"], "sleeping": False, "daylight": 0.1}, {"drink": 5, "food": 5}, "death.zombie_night"),
    ({"adjacent": [], "standing_on": "lava"}, {"drink": 5, "food": 5}, "death.lava"),
    ({"adjacent": []}, {"drink": 0, "food": 3}, "death.thirst"),
    ({"adjacent": []}, {"drink": 3, "food": 0}, "death.starvation"),
])
def test_deaths_are_diagnosed_from_the_trace(damage, death, cause):
    trace = [{"kind": "game_damage", **damage}, {"kind": "game_death", "step": 9, "energy": 5, **death}]
    assert diagnose_death(trace)[0] == cause
    assert diagnose_death([{"kind": "game_damage", **damage}]) is None
    assert correction_for("death.thirst", {"drink_below": 4}) == {"drink_below": 6}


def test_a_death_lesson_counts_only_when_its_correction_changed_what_the_player_did():
    lesson = {"drink_below": 6}
    # the raised threshold sent the player to drink at 5 (the default 4 would have waited)
    assert correction_acted(lesson, [{"kind": "game_reflex", "mode": "drink", "drink": 5, "health": 9}])
    # a drink at 3 would have happened without the lesson; a rest is another reflex
    assert not correction_acted(lesson, [{"kind": "game_reflex", "mode": "drink", "drink": 3},
                                         {"kind": "game_reflex", "mode": "rest", "drink": 5}])
    # zombie deaths raise the retreat threshold; a retreat at health 6 is the lesson acting
    assert correction_for("death.zombie", {})["health_below"] == 7
    # one cause, one fixed correction: a death under a corrected threshold does not ratchet it
    assert correction_for("death.thirst", {"drink_below": 6}) == {"drink_below": 6}
    assert correction_acted({"health_below": 7}, [{"kind": "game_reflex", "mode": "retreat", "health": 6}])
    assert not correction_acted({"health_below": 7}, [{"kind": "game_reflex", "mode": "retreat", "health": 4}])


def test_an_arrow_seen_just_before_the_fatal_hit_is_a_skeleton_death():
    # the arrow hits and vanishes in the same step: it is in the view before, not next to the player after
    trace = [{"kind": "game_damage", "step": 321, "health": 0, "lost": 4, "adjacent": [], "close_before": ["arrow", "arrow"],
              "daylight": 0.94, "sleeping": False, "food": 1, "drink": 8, "energy": 8, "standing_on": "grass"},
             {"kind": "game_death", "step": 322, "health": 0, "food": 1, "drink": 8, "energy": 8, "adjacent": []}]
    assert diagnose_death(trace)[0] == "death.skeleton"
    # a point lost to hunger with an arrow around is not the arrow's
    trace[0].update(lost=1, food=0)
    trace[1].update(food=0)
    assert diagnose_death(trace)[0] == "death.starvation"


BUILD_FOR_RECIPE = {
    "version": 1, "name": "crafter_build_for_recipe", "description": "a known recipe, no table in the world",
    "defaults": {"target": "crafter", "limits": {"execution_timeout_s": 120}},
    "nodes": [
        {"id": "collect_wood", "skill": "game_collect", "params": {"material": "tree", "item": "wood", "count": 4},
         "accept": {"has": {"item": "wood", "min": 4}}},
        # the recipe as memory hands it over (parameter ``near``); no table was ever placed
        {"id": "make_wood_pickaxe", "skill": "game_make", "params": {"item": "wood_pickaxe", "near": ["table"]},
         "depends_on": ["collect_wood"], "accept": {"achieved": "make_wood_pickaxe"}},
    ],
}


def _run_make(graph: dict, tmp_path, *, seed: int):
    """Run ``graph`` (it must succeed); ``(workspace dir, trace of its make_wood_pickaxe session)``."""
    path = tmp_path / "graph.yaml"
    path.write_text(yaml.safe_dump(graph))
    ws = tmp_path / "ws"
    report = run_goal_graph(path, ws, seed=seed)
    assert report.succeeded, report.to_dict()
    make = next(s for s in report.sessions if s.node == "make_wood_pickaxe")
    lines = (ws / "evidence" / make.session_id / "trace.jsonl").read_text().splitlines()
    return ws, [yaml.safe_load(line) for line in lines]


def test_a_known_recipe_whose_station_is_nowhere_places_it_and_makes_the_tool(tmp_path):
    ws, trace = _run_make(BUILD_FOR_RECIPE, tmp_path, seed=2)
    built = [r for r in trace if r.get("kind") == "game_place"]
    assert [(r["item"], r["ok"], r["for_recipe"]) for r in built] == [("table", True, "wood_pickaxe")]
    makes = [r for r in trace if r.get("kind") == "game_make"]
    assert makes[-1]["ok"] and "table" in makes[-1]["nearby"] and makes[-1]["recipe_known"]
    assert not any(r.get("kind") == "game_recipe_abandoned" for r in trace)  # no search was needed
    truth = yaml.safe_load((ws / "targets" / "crafter" / "ground_truth.yaml").read_text())
    assert truth["achievements"]["place_table"] == 1 and truth["achievements"]["make_wood_pickaxe"] == 1


def test_a_recipe_station_the_player_cannot_build_falls_back_to_the_search(tmp_path):
    # an over-specified hypothesis from memory: "stone and table"; the player has no stone
    # and (in world 3) remembers no stone next to its table
    graph = dict(BUILD_FOR_RECIPE, name="crafter_cannot_build")
    graph["nodes"] = [dict(n) for n in BUILD_FOR_RECIPE["nodes"]]
    graph["nodes"].insert(1, {"id": "place_table", "skill": "game_place", "params": {"item": "table"},
                              "depends_on": ["collect_wood"], "accept": {"achieved": "place_table"}})
    graph["nodes"][2] = {**graph["nodes"][2], "depends_on": ["place_table"],
                         "params": {"item": "wood_pickaxe", "near": ["stone", "table"]}}
    _, trace = _run_make(graph, tmp_path, seed=3)
    kinds = [r["kind"] for r in trace if r["kind"] in ("game_place", "game_recipe_abandoned", "game_make")]
    assert kinds[:2] == ["game_place", "game_recipe_abandoned"] and kinds[-1] == "game_make"
    assert [r for r in trace if r["kind"] == "game_place"][0]["item"] == "stone"
    assert [r for r in trace if r["kind"] == "game_make"][-1]["ok"]


def test_a_recipe_is_judged_by_its_planned_attempts_not_by_the_sessions_verdict(tmp_path):
    from phyagentos.agent.memory.recipes import RecipeBook, recipe_id  # noqa: PLC0415
    from phyagentos.protocol import ContextItem, Lesson, SessionContext, SessionRecord, Verdict  # noqa: PLC0415
    from phyagentos.protocol.lifecycle import utc_now  # noqa: PLC0415

    ws = Workspace.create(tmp_path / "ws")
    book = RecipeBook(ws)
    rid = recipe_id("stone_pickaxe", ["table"])
    scope = {"embodiment": "crafter", "skill": "game_make", "object_class": "item:stone_pickaxe", "risk_factors": []}
    ws.update("LESSONS", lambda doc: doc.model_copy(update={"lessons": [Lesson(
        id=rid, objective="make stone_pickaxe", evidence=[], cause="recipe.learned", correction="needs table",
        scope=scope, strategy="recipe", revision={"near": ["table"], "uses": {"wood": 1, "stone": 1}}, verified=True,
        confirmations=1)]}))

    def session(sid, verdict):
        now = utc_now()
        ctx = SessionContext(built_at=now, items=[ContextItem(kind="lesson", id=rid, summary="recipe",
                                                              applied={"near": ["table"]})])
        return SessionRecord(session_id=sid, run_id="r", node="make_stone_pickaxe", skill="game_make", target="crafter",
                             parameters={"item": "stone_pickaxe", "near": ["table"]}, context=ctx, created_at=now,
                             updated_at=now), Verdict(verdict=verdict, reason=verdict, at=now)

    def make(ok, inv, nearby=("grass", "table")):
        return {"kind": "game_make", "item": "stone_pickaxe", "ok": ok, "nearby": list(nearby), "recipe_known": True,
                "inventory_before": inv, "inventory_after": {**inv, "stone_pickaxe": int(ok)}}

    def lesson():
        return next(entry for entry in ws.read("LESSONS").data.lessons if entry.id == rid)

    # a planned try without the stone it uses fails: no evidence about the stations
    book.learn(*session("s-1", "failure"), [make(False, {"wood": 3, "stone": 0})])
    assert (lesson().confirmations, lesson().refutations) == (1, 0)
    # a planned success confirms it and mints no new hypothesis ("table and tree" from one success)
    book.learn(*session("s-2", "success"), [make(True, {"wood": 3, "stone": 2}, ("grass", "table", "tree"))])
    doc = ws.read("LESSONS").data
    assert (lesson().confirmations, lesson().verified_by) == (2, ["s-2"])
    assert [c for c in doc.candidates if c.revision.get("near")] == []
    # a planned failure with the items in hand refutes it
    book.learn(*session("s-3", "failure"), [make(False, {"wood": 3, "stone": 2})])
    assert (lesson().refutations, lesson().refuted_by) == (1, ["s-3"])
