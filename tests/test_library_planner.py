"""A request as one goal of a task library: "get a stone pickaxe" on Crafter's tech tree."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import yaml

pytest.importorskip("crafter")

from phyagentos.agent.goal_graph import load_goal_graph  # noqa: E402
from phyagentos.agent.library_planner import LibraryPlanner, goal_candidates  # noqa: E402
from phyagentos.app.orchestrator import skill_names  # noqa: E402
from phyagentos.llm import make_client  # noqa: E402
from phyagentos.resources import goal_graphs_dir  # noqa: E402

TECH_TREE = goal_graphs_dir() / "crafter_tech_tree.yaml"
CLI = [sys.executable, "-m", "phyagentos.cli"]


def test_the_request_words_narrow_the_goals_the_model_may_choose():
    lib = load_goal_graph(TECH_TREE, skills=skill_names(), targets=["crafter"])
    assert goal_candidates("get a stone pickaxe", lib) == ["make_stone_pickaxe"]
    assert goal_candidates("find me a diamond", lib) == ["collect_diamond"]
    assert goal_candidates("drink some water", lib) == ["collect_drink"]
    assert goal_candidates("build a rocket to the moon", lib) == []


def test_a_goal_is_planned_with_everything_it_depends_on_in_file_order_and_nothing_else():
    planner = LibraryPlanner(make_client(), skills=skill_names(), targets=["crafter"])
    result = planner.plan("get an iron pickaxe", library=TECH_TREE)
    assert result.status == "planned", result.reason
    assert [n.id for n in result.graph.nodes] == [
        "collect_wood", "place_table", "make_wood_pickaxe", "make_wood_sword", "collect_stone", "place_stone",
        "make_stone_pickaxe", "place_furnace", "collect_coal", "collect_iron", "make_iron_pickaxe"]
    assert result.graph.schedule == "file_order"
    graph = yaml.safe_load(result.graph_yaml)
    assert graph["provenance"]["goal"] == "make_iron_pickaxe"
    assert graph["provenance"]["model_calls"][0]["outcome"] == "accepted"
    # nothing the library cannot give: refused before any model call
    refused = planner.plan("build a rocket to the moon", library=TECH_TREE)
    assert (refused.status, refused.refused_by, refused.refusal, refused.calls) == ("refused", "grounding",
                                                                                   "impossible", ())


def test_get_a_stone_pickaxe_is_planned_and_run_and_the_game_agrees(tmp_path):
    ws = tmp_path / "ws"
    proc = subprocess.run([*CLI, "plan", "get a stone pickaxe", "--workspace", str(ws), "--library", str(TECH_TREE),
                           "--run", "--seed", "1", "--json"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout)
    assert set(report["nodes"]) == {"collect_wood", "place_table", "make_wood_pickaxe", "make_wood_sword",
                                    "collect_stone", "make_stone_pickaxe"}
    assert set(report["nodes"].values()) == {"succeeded"}
    truth = yaml.safe_load((ws / "targets" / "crafter" / "ground_truth.yaml").read_text())
    assert truth["achievements"]["make_stone_pickaxe"] >= 1
