"""A sapling planted where nothing can trample it: walled in by stone on every side."""

from __future__ import annotations

import json

import pytest
import yaml

pytest.importorskip("crafter")

from phyagentos.app.orchestrator import run_goal_graph  # noqa: E402
from phyagentos.protocol import Workspace  # noqa: E402

PLANT = {
    "version": 1, "name": "crafter_protected_plant", "description": "a pickaxe, stone and a sapling, planted walled in",
    "defaults": {"target": "crafter", "limits": {"execution_timeout_s": 240}},
    "nodes": [
        {"id": "collect_wood", "skill": "game_collect", "params": {"material": "tree", "item": "wood", "count": 4},
         "accept": {"has": {"item": "wood", "min": 4}}},
        {"id": "place_table", "skill": "game_place", "params": {"item": "table"}, "depends_on": ["collect_wood"],
         "accept": {"achieved": "place_table"}},
        {"id": "make_wood_pickaxe", "skill": "game_make", "params": {"item": "wood_pickaxe"},
         "depends_on": ["place_table"], "accept": {"achieved": "make_wood_pickaxe"}},
        {"id": "collect_stone", "skill": "game_collect", "params": {"material": "stone", "item": "stone", "count": 5},
         "depends_on": ["make_wood_pickaxe"], "accept": {"has": {"item": "stone", "min": 5}}},
        {"id": "collect_sapling", "skill": "game_collect", "params": {"material": "grass", "item": "sapling"},
         "depends_on": ["collect_stone"], "accept": {"achieved": "collect_sapling"}},
        {"id": "place_plant", "skill": "game_place", "params": {"item": "plant", "protect": True},
         "depends_on": ["collect_sapling"], "accept": {"achieved": "place_plant"}},
    ],
}
_WALKABLE = {"grass", "sand", "path"}


def test_a_protected_plant_ends_walled_in_on_all_four_sides(tmp_path):
    ws = tmp_path / "ws"
    graph = tmp_path / "plant.yaml"
    graph.write_text(yaml.safe_dump(PLANT))
    report = run_goal_graph(graph, ws, seed=1)
    assert report.succeeded, report.to_dict()
    session = next(s for s in report.sessions if s.node == "place_plant")
    evidence = Workspace.open(ws).root / "evidence" / session.session_id
    trace = [json.loads(line) for line in (evidence / "trace.jsonl").read_text().splitlines()]
    assert [r["ok"] for r in trace if r["kind"] == "game_plant_protected"] == [True]
    # what the player sees at the end: the plant, and no walkable cell next to it
    player = yaml.safe_load((evidence / "terminal.yaml").read_text())["entities"][0]["attributes"]
    view = [row.split() if isinstance(row, str) else row for row in player["view"]]
    r0, c0 = len(view) // 2, len(view[0]) // 2
    (plant,) = [o for o in player["objects"] if o["name"] == "plant"]
    r, c = r0 + plant["dy"], c0 + plant["dx"]
    assert view[r][c] == "grass"
    neighbours = [view[r + dr][c + dc] for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1))]
    assert not set(neighbours) & _WALKABLE, neighbours
    assert "stone" in neighbours
