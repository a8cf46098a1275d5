"""A short seeded Crafter episode through `phyagentos run`, and the Crafter metrics."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
import yaml

pytest.importorskip("crafter")

from phyagentos.agent.criteria import evaluate, parse_criteria  # noqa: E402
from phyagentos.bench.crafter_metrics import crafter_score, crafter_score_interval, episode_metrics  # noqa: E402
from phyagentos.resources import goal_graphs_dir  # noqa: E402

CLI = [sys.executable, "-m", "phyagentos.cli"]


def test_a_seeded_run_collects_wood_and_places_a_table(tmp_path):
    ws = tmp_path / "ws"
    graph = goal_graphs_dir() / "crafter_first_table.yaml"
    proc = subprocess.run([*CLI, "run", str(graph), "--workspace", str(ws), "--seed", "1", "--json"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(proc.stdout)
    assert report["nodes"] == {"collect_wood": "succeeded", "place_table": "succeeded"}
    # the game's own ground truth agrees with the verdicts
    truth = yaml.safe_load((ws / "targets" / "crafter" / "ground_truth.yaml").read_text())
    assert truth["achievements"]["collect_wood"] >= 1 and truth["achievements"]["place_table"] == 1
    metrics = episode_metrics(ws)
    assert {"collect_wood", "place_table"} <= set(metrics["achievements"])
    assert metrics["unlocked_in"]["place_table"].endswith("place_table-1")  # traceable to its session
    assert metrics["death_cause"] == "alive"


def test_inventory_and_achievement_predicates_judge_the_player_record():
    snap = {"entities": [{"name": "player", "kind": "player", "position": [0, 0, 0],
                          "attributes": {"inventory": {"wood": 2}, "vitals": {"drink": 9},
                                         "achievements": ["collect_wood"], "step": 5}}]}
    has, achieved, drink, missing = parse_criteria(
        [{"has": {"item": "wood", "min": 3}}, {"achieved": "collect_wood"}, {"has": "drink"}, {"achieved": "eat_cow"}])
    assert evaluate(has, snap, snap).status == "unsatisfied"
    assert evaluate(achieved, snap, snap).status == "satisfied"
    assert evaluate(drink, snap, snap).status == "satisfied"
    assert evaluate(missing, snap, snap).status == "unsatisfied"
    assert evaluate(achieved, {}, {"entities": []}).status == "unknown"


def test_crafter_score_is_the_geometric_mean_of_one_plus_the_rates():
    assert crafter_score([100.0] * 22) == pytest.approx(100.0)
    assert crafter_score([0.0] * 22) == pytest.approx(0.0)
    rates = [50.0, 10.0, 0.0]
    assert crafter_score(rates) == pytest.approx(math.exp((math.log(51) + math.log(11) + 0) / 3) - 1)


def test_the_score_interval_brackets_the_score_and_narrows_with_more_worlds():
    names = ("a", "b", "c")
    few = [["a", "b"], ["a"], ["a", "c"], ["a", "b"]]
    rates = [100.0 * sum(n in e for e in few) / len(few) for n in names]
    low, high = crafter_score_interval(few, names=names, resamples=4000)
    assert low <= crafter_score(rates) <= high and high - low > 5.0
    many = few * 25  # the same rates over 100 worlds
    low100, high100 = crafter_score_interval(many, names=names, resamples=4000)
    assert low100 <= crafter_score(rates) <= high100
    assert high100 - low100 < (high - low) / 3
    # a rare achievement (unlocked once) makes the lower end fall well below the score
    rare = [["a"]] * 19 + [["a", "b"]]
    r_low, r_high = crafter_score_interval(rare, names=("a", "b"))
    assert r_low < crafter_score([100.0, 5.0]) - 1.0 and crafter_score_interval([], names=names) == (0.0, 0.0)
