"""SO-101 ``hold`` drift (issue 11): the cause was the SO-101 starting inside the Franka
default scene's wall (its contacts pushed the held arm 0.02-0.5 rad). Through the CLI:
the hold now keeps the arm still, and a scene whose wall the home pose reaches into
is refused before anything moves."""

from __future__ import annotations

from pathlib import Path

import yaml

from phyagentos.cli import main
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

REPO = Path(__file__).resolve().parent.parent


def test_an_so101_hold_keeps_the_arm_still(tmp_path, capsys):
    ws = tmp_path / "ws"
    assert main(["run", str(goal_graphs_dir() / "hold.yaml"), "--workspace", str(ws), "--target", "so101_tabletop",
                 "--json"]) == 0
    capsys.readouterr()
    workspace = Workspace.open(ws)
    [rec] = workspace.list_sessions()
    evidence = ws / rec.attempts[-1].evidence

    def joints(name: str) -> list[float]:
        entities = yaml.safe_load((evidence / name).read_text(encoding="utf-8"))
        entities = entities.get("entities", entities) if isinstance(entities, dict) else entities
        [robot] = [e for e in entities if "joint_positions" in (e.get("attributes") or {})]
        return robot["attributes"]["joint_positions"]

    before, after = joints("initial.yaml"), joints("terminal.yaml")
    assert len(before) == 5
    assert max(abs(a - b) for a, b in zip(before, after)) < 0.002  # was 0.02-0.03 rad (0.49 over 12 s)


def test_a_scene_the_so101_starts_inside_of_is_refused_before_anything_moves(tmp_path, capsys):
    graph = tmp_path / "hold_wall.yaml"
    data = yaml.safe_load((goal_graphs_dir() / "hold.yaml").read_text(encoding="utf-8"))
    data["scene"] = {"obstacles": [{"name": "wall", "center": [0.5, 0.03, 0.15], "half_extents": [0.2, 0.01, 0.15]}]}
    graph.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    ws = tmp_path / "ws"
    Workspace.create(ws)
    before = {p: p.read_bytes() for p in ws.rglob("*") if p.is_file()}
    assert main(["run", str(graph), "--workspace", str(ws), "--target", "so101_tabletop"]) == 2
    err = capsys.readouterr().err
    assert "'so101_tabletop' starts in collision: its home pose reaches into obstacle(s) 'wall'" in err
    assert {p: p.read_bytes() for p in ws.rglob("*") if p.is_file()} == before
    assert main(["validate", str(graph)]) == 0  # the Franka starts clear of the same wall
