"""Shipped example goal graphs by name: ``phyagentos run pick_and_place`` from any directory."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from phyagentos.cli import main
from phyagentos.errors import PhyAgentOSError
from phyagentos.resources import ExampleNotFoundError, example_graphs, goal_graph_path, goal_graphs_dir


def test_a_bare_example_name_resolves_to_the_shipped_graph(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert goal_graph_path("pick_and_place") == goal_graphs_dir() / "pick_and_place.yaml"
    assert example_graphs()["hold"] == goal_graphs_dir() / "hold.yaml"


def test_an_existing_file_wins_over_an_example_of_the_same_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "hold").write_text("version: 1\n", encoding="utf-8")
    assert goal_graph_path("hold") == Path("hold")


def test_a_path_with_a_folder_or_suffix_is_never_taken_for_an_example(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert str(goal_graph_path("pick_and_place.yaml")) == "pick_and_place.yaml"
    assert str(goal_graph_path("graphs/pick_and_place")) == "graphs/pick_and_place"


def test_an_unknown_name_is_an_error_that_lists_the_examples(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ExampleNotFoundError, match="nor a shipped example.*pick_and_place") as info:
        goal_graph_path("pick_and_plaice")
    assert isinstance(info.value, PhyAgentOSError)


def test_the_cli_refuses_an_unknown_example_name_with_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(["validate", "pick_and_plaice"])
    assert info.value.code == 2
    assert "nor a shipped example" in capsys.readouterr().err


def test_examples_lists_every_shipped_graph_with_its_path(capsys):
    assert main(["examples", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed == {p.stem: str(p) for p in sorted(goal_graphs_dir().glob("*.yaml"))}
    assert {"pick_and_place", "hold", "sort_two_cubes"} <= set(listed)


def test_validate_takes_an_example_name(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["validate", "hold"]) == 0
    assert "valid, 1 node(s)" in capsys.readouterr().out
