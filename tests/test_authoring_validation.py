"""Whole-graph validation before any motion, and one arm holding one object (issue 11,
items 1 and 2), through the ``phyagentos`` CLI.

Every rejected graph must exit 2 naming the user's file and line, register no run,
leave the workspace byte for byte as it was and leave the target's recorded state
(``targets/<name>/state.*``) absent: nothing moved.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from phyagentos.cli import main
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

REPO = Path(__file__).resolve().parent.parent

SCENE = """\
scene:
  objects:
    - {name: red_cube, half_extents: [0.02, 0.02, 0.02], position: [0.45, -0.2]}
    - {name: blue_cube, half_extents: [0.02, 0.02, 0.02], position: [0.6, -0.15]}
  regions:
    - {name: red_region, center: [0.45, 0.22], half_extents: [0.07, 0.07]}
    - {name: blue_region, center: [0.62, 0.22], half_extents: [0.07, 0.07]}
"""

PICK_PLACE = """\
version: 1
name: user_graph
defaults:
  target: franka_tabletop
{scene}nodes:
  - id: pick_red
    skill: pick
    params: {{object: red_cube}}
    accept: {{holding: red_cube}}
  - id: place_red
    skill: place
    params: {{object: red_cube, region: red_region}}
    accept:
      inside: {{object: red_cube, region: red_region}}
    depends_on: [pick_red]
"""


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` with its bytes (the workspace, byte for byte)."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture()
def ws(tmp_path) -> Path:
    root = tmp_path / "ws"
    Workspace.create(root)
    return root


def write(tmp_path: Path, text: str, name: str = "graph.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def line_of(text: str, needle: str) -> int:
    for i, line in enumerate(text.splitlines(), 1):
        if needle in line:
            return i
    raise AssertionError(needle)


def assert_refused_everywhere(graph: Path, ws: Path, capsys, *, expect: str, line: int) -> None:
    """``validate``, ``submit`` and ``run`` all exit 2 with ``graph:line`` and ``expect``;
    the workspace is unchanged and no target state was written."""
    before = snapshot(ws)
    for argv in (["validate", str(graph), "--workspace", str(ws)],
                 ["submit", str(graph), "--workspace", str(ws)],
                 ["run", str(graph), "--workspace", str(ws)]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert f"{graph}:{line}:" in err, (argv, err)
        assert re.search(expect, err), (argv, err)
        assert "Traceback" not in err
    assert snapshot(ws) == before
    assert not list((ws / "targets").rglob("state.*")) if (ws / "targets").exists() else True
    assert Workspace.open(ws).runs.active_ids() == []


def test_a_position_written_as_a_string_is_refused_with_file_and_line_before_anything_runs(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE.replace("position: [0.45, -0.2]", 'position: "0.45, -0.2"'))
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"position must be a list of 2 numbers.*got a string",
                              line=line_of(text, '"0.45, -0.2"'))


def test_a_position_with_three_numbers_is_refused(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE.replace("position: [0.6, -0.15]", "position: [0.6, -0.15, 0.1]"))
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"position must be a list of 2 numbers",
                              line=line_of(text, "[0.6, -0.15, 0.1]"))


def test_an_unknown_object_in_a_parameter_lists_the_scene_objects(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE).replace("params: {object: red_cube}", "params: {object: red_cub}")
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"unknown object 'red_cub'; valid objects: .*blue_cube.*red_cube",
                              line=line_of(text, "{object: red_cub}"))


def test_an_unknown_region_in_a_predicate_is_refused_at_the_accept_line(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE).replace("inside: {object: red_cube, region: red_region}",
                                                  "inside: {object: red_cube, region: red_regoin}")
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"predicate 'inside' names unknown region 'red_regoin'",
                              line=[i for i, ln in enumerate(text.splitlines(), 1) if ln.strip() == "accept:"][0])


def test_a_predicate_typo_is_found_before_the_first_session_not_after_three(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE).replace("inside: {object", "insde: {object")
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"unknown predicate 'insde'; valid predicates: .*inside",
                              line=[i for i, ln in enumerate(text.splitlines(), 1) if ln.strip() == "accept:"][0])


def test_an_unknown_skill_parameter_is_a_validation_error_not_a_preflight_reject(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE).replace("params: {object: red_cube}", "params: {object: red_cube, lift: 0.1}")
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"unknown parameter 'lift' \(declared: .*lift_m",
                              line=line_of(text, "lift: 0.1"))


def test_a_cube_three_metres_away_is_unreachable_before_the_arm_moves(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE.replace("position: [0.45, -0.2]", "position: [3.0, -0.2]"))
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"cannot reach 'red_cube' at \(3\.000, -0\.200\) m",
                              line=line_of(text, "params: {object: red_cube}"))


def test_a_scene_out_of_the_so101_reach_is_refused_for_the_so101_only(tmp_path, ws, capsys):
    graph = goal_graphs_dir() / "pick_and_place.yaml"
    text = graph.read_text(encoding="utf-8")
    before = snapshot(ws)
    assert main(["validate", str(graph), "--workspace", str(ws), "--target", "so101_tabletop"]) == 2
    err = capsys.readouterr().err
    assert f"{graph}:{line_of(text, 'region: goal}')}:" in err and "'so101_tabletop' cannot reach 'goal'" in err
    assert main(["submit", str(graph), "--workspace", str(ws), "--target", "so101_tabletop"]) == 2
    capsys.readouterr()
    assert snapshot(ws) == before
    # the same graph on the Franka, and the compact graph on the SO-101, are fine
    assert main(["validate", str(graph), "--workspace", str(ws)]) == 0
    compact = goal_graphs_dir() / "pick_and_place_compact.yaml"
    assert main(["validate", str(compact), "--workspace", str(ws), "--target", "so101_tabletop"]) == 0
    assert "4 pose(s) reachable" in capsys.readouterr().out


def test_a_yaml_alias_bomb_in_params_is_refused_in_milliseconds_with_file_and_line(tmp_path, ws, capsys):
    bomb = ["x0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    bomb += [f"      x{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    text = PICK_PLACE.format(scene=SCENE).replace("params: {object: red_cube}\n",
                                                  "params:\n      object: red_cube\n      " + "\n".join(bomb) + "\n", 1)
    assert len(text) < 2000
    graph = write(tmp_path, text)
    before = snapshot(ws)
    for argv in (["validate", str(graph)], ["submit", str(graph), "--workspace", str(ws)],
                 ["run", str(graph), "--workspace", str(ws)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert re.search(rf"{re.escape(str(graph))}:\d+: YAML aliases expand to more than", err), err
    assert snapshot(ws) == before


def test_two_independent_picks_on_one_arm_are_serialised_by_an_implicit_edge(tmp_path, capsys):
    text = PICK_PLACE.format(scene=SCENE) + """\
  - id: pick_blue
    skill: pick
    params: {object: blue_cube}
    accept: {holding: blue_cube}
  - id: place_blue
    skill: place
    params: {object: blue_cube, region: blue_region}
    accept: {inside: {object: blue_cube, region: blue_region}}
    depends_on: [pick_blue]
"""
    graph = write(tmp_path, text)
    assert main(["validate", str(graph)]) == 0
    out = capsys.readouterr().out
    assert "pick_blue: pick on franka_tabletop after place_red (implicit: one arm holds one object)" in out
    assert "implicit edge place_red -> pick_blue" in out


def test_the_run_graph_carries_the_implicit_edge_so_the_second_pick_waits_for_the_first_place(tmp_path, ws):
    from phyagentos.agent.agent_loop import load_run_graph
    from phyagentos.app.orchestrator import skill_names
    from phyagentos.protocol import RunRecord, utc_now_iso

    text = PICK_PLACE.format(scene=SCENE) + """\
  - id: pick_blue
    skill: pick
    params: {object: blue_cube}
    accept: {holding: blue_cube}
"""
    workspace = Workspace.open(ws)
    record = RunRecord(run_id="r1", goal_graph="g.yaml", graph_file="", seed=0, target=None,
                       submitted_at=utc_now_iso(), submitted_by="")
    workspace.register_run(record, text)
    graph = load_run_graph(workspace, "r1", skills=skill_names())
    assert graph.get_node("pick_blue").depends_on == ("place_red",)
    assert graph.get_node("pick_red").depends_on == ()


def test_a_pick_while_holding_what_is_never_released_is_refused(tmp_path, ws, capsys):
    text = PICK_PLACE.format(scene=SCENE).split("  - id: place_red")[0] + """\
  - id: pick_blue
    skill: pick
    params: {object: blue_cube}
    accept: {holding: blue_cube}
"""
    graph = write(tmp_path, text)
    assert_refused_everywhere(graph, ws, capsys, expect=r"node 'pick_blue' would pick 'blue_cube' on 'franka_tabletop' "
                                                        r"while the gripper holds another object",
                              line=line_of(text, "- id: pick_blue"))


def test_picks_on_two_arms_keep_their_parallelism(tmp_path, capsys):
    text = PICK_PLACE.format(scene=SCENE).split("  - id: place_red")[0] + """\
  - id: pick_blue
    skill: pick
    target: so101_tabletop
    params: {object: blue_cube}
    accept: {holding: blue_cube}
"""
    text = text.replace("position: [0.6, -0.15]", "position: [0.45, -0.1]")
    graph = write(tmp_path, text)
    assert main(["validate", str(graph)]) == 0
    out = capsys.readouterr().out
    assert "implicit" not in out
    assert "pick_blue: pick on so101_tabletop\n" in out
