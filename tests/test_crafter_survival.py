"""Survival and search decisions of the game primitives, on hand-built player maps.

Pure decisions (no game steps): which shelter is chosen, when the reflex tops up food and
drink, where an unknown recipe is tried next, when a hunt is already done. The player map
is a SeenMap written cell by cell, as observations would write it.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from phyagentos.agent.memory.deaths import correction_acted
from phyagentos.primitives.game.seen_map import MATERIALS, SeenMap
from phyagentos.primitives.game.shelter import Rest, find_shelter, water_at
from phyagentos.primitives.game.survival import GameSurvive
from phyagentos.primitives.game.tasks import GameHunt, GameMake

_CODE = {name: i for i, name in enumerate(MATERIALS)}


def _map(rows: list[str], origin=(0, 0)) -> SeenMap:
    """Rows of characters, x to the right, y down; ``origin`` is the cell of rows[0][0].
    g grass, s stone, w water, t table, f furnace, T tree, ? unknown."""
    chars = {"g": "grass", "s": "stone", "w": "water", "t": "table", "f": "furnace", "T": "tree", "?": "unknown",
             "p": "path"}
    m = SeenMap()
    for y, row in enumerate(rows):
        for x, ch in enumerate(row):
            m.grid[origin[0] + x + 128, origin[1] + y + 128] = _CODE[chars[ch]]
    return m


class _Trace:
    def __init__(self):
        self.records = []

    def record(self, kind, **data):
        self.records.append({"kind": kind, **data})


def _leaf(leaf, m: SeenMap, obs: dict, **notes):
    leaf.ctx = SimpleNamespace(target=SimpleNamespace(notes={"map": m, **notes}), trace=_Trace())
    leaf.obs = obs
    return leaf


def _obs(position=(0, 0), *, food=9, drink=9, health=9, energy=9, daylight=1.0, objects=(), achievements=()):
    return {"position": list(position), "vitals": {"health": health, "food": food, "drink": drink, "energy": energy},
            "inventory": {"wood_pickaxe": 1, "stone": 5}, "daylight": daylight, "sleeping": False, "facing": "down",
            "objects": [dict(o) for o in objects], "achievements": list(achievements), "step": 100,
            "view": [["grass"] * 9 for _ in range(7)]}


# ---------------------------------------------------------------- shelters with water


# Two dug-in shelters in a stone ridge: a dry one 2 steps from the player and a wet one
# (water beyond its inner cell) a few steps farther along the same row.
RIDGE = [
    "ssssssssssss",
    "ssssssssspss",
    "ssssssssspss",
    "gggggggggggg",
    "gggggggggggg",
]


def test_a_shelter_with_water_at_a_wall_is_preferred_within_the_detour():
    m = _map(RIDGE)
    m.grid[9 + 128, 0 + 128] = _CODE["water"]  # beyond the inner cell of the shelter at x = 9
    dry = find_shelter(m, (2, 4), can_dig=True, radius=12, water_detour=0)
    wet = find_shelter(m, (2, 4), can_dig=True, radius=12, water_detour=12)
    assert dry is not None and not water_at(m, dry)
    assert wet is not None and water_at(m, wet) == [(9, 0)]
    assert wet.o == (9, 3) and wet.d == (0, -1)


def test_a_sealed_player_drinks_from_inside_instead_of_leaving():
    m = _map(RIDGE)
    m.grid[9 + 128, 0 + 128] = _CODE["water"]
    rest = Rest(until_day=True)
    rest.plan = find_shelter(m, (9, 4), can_dig=True, radius=8)
    rest.state["phase"] = "sealed"
    leaf = _leaf(GameSurvive("s"), m, _obs((9, 2), drink=3, daylight=0.1))
    assert rest.can_drink(leaf)
    assert rest.drink_step(leaf) == "move_up"  # from the entry cell into the inner cell, next to the water
    leaf.obs = _obs((9, 1), drink=3, daylight=0.1)
    assert rest.drink_step(leaf) == "move_up"  # turns to the water (not walkable: the move only turns)
    leaf.obs = {**_obs((9, 1), drink=3, daylight=0.1), "facing": "up"}
    assert rest.drink_step(leaf) == "do"
    leaf.obs = {**_obs((9, 1), drink=8, daylight=0.1), "facing": "up"}
    assert rest.drink_step(leaf) is None  # not thirsty: sleep on
    # thirst does not end the night in such a shelter
    leaf.obs = {**_obs((9, 1), drink=1, food=5, daylight=0.1), "facing": "up"}
    rest.slept = True
    assert rest.step(leaf) == "do" and not rest.leaving


# ---------------------------------------------------------------- top-ups


def test_a_cow_in_view_tops_up_food_below_seven_as_its_own_reflex_mode():
    m = _map(["ggggggggg"] * 7, origin=(-4, -3))
    leaf = _leaf(GameSurvive("s"), m, _obs(food=6, objects=[{"name": "cow", "dx": 3, "dy": 2}]))
    assert leaf._topup(leaf.obs, falling=False)
    assert (leaf.mode, leaf._label) == ("eat", "topup_eat")
    full = _leaf(GameSurvive("s"), m, _obs(food=7, objects=[{"name": "cow", "dx": 1, "dy": 0}]))
    assert not full._topup(full.obs, falling=False)


def test_dusk_sends_the_player_to_remembered_water_before_night():
    m = _map(["ggggggggggggggggggggw"], origin=(0, 0))
    leaf = _leaf(GameSurvive("s"), m, _obs(drink=6, daylight=0.8))
    assert not leaf._topup(leaf.obs, falling=False)  # by day, water 20 cells away is no top-up
    assert leaf._topup(leaf.obs, falling=True)
    assert (leaf.mode, leaf._label) == ("drink", "dusk_drink")


def test_top_up_reflexes_are_no_evidence_for_a_corrected_threshold():
    # a death lesson raised food_below to 6; eating at food 5 because a cow walked by is
    # not the correction acting
    trace = [{"kind": "game_reflex", "mode": "topup_eat", "food": 5, "drink": 9, "health": 9, "energy": 9}]
    assert not correction_acted({"food_below": 6}, trace)
    trace = [{"kind": "game_reflex", "mode": "eat", "food": 5, "drink": 9, "health": 9, "energy": 9}]
    assert correction_acted({"food_below": 6}, trace)


# ---------------------------------------------------------------- recipe search


def test_the_recipe_search_goes_where_stations_it_built_stand_together():
    # table and furnace two cells apart; single tries next to each failed already
    m = _map(["ggggggg", "gtgfggg", "ggggggg", "gggggTg"], origin=(0, 0))
    leaf = _leaf(GameMake("m", item="iron_pickaxe"), m, _obs((0, 3)), placed={"table", "furnace", "stone"})
    leaf._failed = [{"grass", "table"}, {"grass", "furnace"}, {"grass", "tree"}]
    goals = leaf._new_combinations()
    assert goals == {(2, 0), (2, 1), (2, 2)}  # the cells with both the table and the furnace around them


@pytest.mark.parametrize("creature,until", [("zombie", "defeat_zombie"), ("skeleton", "defeat_skeleton"),
                                            ("plant_ripe", "eat_plant")])
def test_a_hunt_for_an_achievement_the_record_already_holds_is_done(creature, until):
    leaf = _leaf(GameHunt("h", creature=creature, until=until), SeenMap(), _obs(achievements=[until]))
    leaf._start = {"achievements": {until}, "food": 9}
    assert leaf._done()
    fresh = _leaf(GameHunt("h", creature=creature, until=until), SeenMap(), _obs())
    fresh._start = {"achievements": set(), "food": 9}
    assert not fresh._done()
