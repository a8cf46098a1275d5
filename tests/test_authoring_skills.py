"""Skills from the user's own folders, and primitives documented from the code (issue 11,
item 4), through the CLI."""

from __future__ import annotations

import inspect
import json
from pathlib import Path

from phyagentos.cli import main
from phyagentos.cli.skills import primitives_markdown
from phyagentos.primitives import PRIMITIVES
from phyagentos.primitives.schema import TABLES, primitive_schemas
from phyagentos.resources import skills_dir

REPO = Path(__file__).resolve().parent.parent

TREE = """\
version: 1
name: nudge
description: Open the gripper, move above an object, touch down and come back up.
params:
  object: {required: true, description: the object to nudge}
  height_m: {default: 0.10, description: "approach height above the grasp, m"}
root:
  sequence:
    name: Nudge
    children:
      - primitive: gripper
        params: {command: open}
      - primitive: observe
      - primitive: compute_grasp
        params: {object: "${object}", approach_height_m: "${height_m}"}
      - subtree: move_to
        params: {pose: pregrasp_pose}
      - primitive: cartesian_move
        params: {to: grasp_pose, velocity_scale: 0.2}
      - primitive: cartesian_move
        params: {offset: [0.0, 0.0, "${height_m}"]}
      - primitive: observe
"""

MANIFEST = """\
version: 1
name: {name}
description: Touch an object from above and come back up.
runtime: builtin
tree: nudge
requires:
  capabilities: [arm, parallel_gripper]
  observations: [joint_positions, object_poses]
params:
  object: {{required: true, description: the object to nudge, example: cube}}
  height_m: {{description: approach height above the object in m (default 0.10)}}
"""

GRAPH = """\
version: 1
name: nudge_cube
defaults: {target: franka_tabletop}
nodes:
  - id: nudge
    skill: nudge
    params: {object: cube}
    accept: {released: cube}
"""


def user_skill(root: Path, *, name: str = "nudge", tree: str = TREE) -> None:
    from phyagentos.protocol import Workspace

    Workspace.create(root) if root.name == "ws" else None
    (root / "skills").mkdir(parents=True, exist_ok=True)
    (root / "trees").mkdir(parents=True, exist_ok=True)
    (root / "skills" / f"{name}.yaml").write_text(MANIFEST.format(name=name), encoding="utf-8")
    (root / "trees" / "nudge.yaml").write_text(tree, encoding="utf-8")


def test_a_skill_in_the_workspace_is_found_by_validate_and_listed(tmp_path, capsys):
    ws = tmp_path / "ws"
    user_skill(ws)
    graph = tmp_path / "g.yaml"
    graph.write_text(GRAPH, encoding="utf-8")
    assert main(["validate", str(graph)]) == 2  # not on the search path without the workspace
    assert "unknown skill 'nudge'" in capsys.readouterr().err
    assert main(["validate", str(graph), "--workspace", str(ws)]) == 0
    assert "nudge: nudge on franka_tabletop" in capsys.readouterr().out
    assert main(["skills", "list", "--workspace", str(ws), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    [row] = [r for r in data["skills"] if r["name"] == "nudge"]
    assert row["path"] == str(ws / "skills" / "nudge.yaml") and data["search_path"][0] == str(ws / "skills")
    assert {"pick", "place", "hold"} <= {r["name"] for r in data["skills"]}  # the shipped ones stay


def test_a_skills_path_folder_is_searched_after_the_workspace(tmp_path, capsys):
    lib = tmp_path / "lib"
    user_skill(lib)
    graph = tmp_path / "g.yaml"
    graph.write_text(GRAPH, encoding="utf-8")
    assert main(["--skills-path", str(lib), "validate", str(graph)]) == 0
    capsys.readouterr()
    assert main(["--skills-path", str(lib), "skills", "show", "nudge"]) == 0
    out = capsys.readouterr().out
    assert f"from {lib / 'skills' / 'nudge.yaml'}" in out and "Nudge" in out


def test_a_user_skill_shadowing_a_shipped_one_is_announced_with_which_wins(tmp_path, capsys, caplog):
    ws = tmp_path / "ws"
    user_skill(ws, name="pick")
    assert main(["skills", "list", "--workspace", str(ws)]) == 0
    captured = capsys.readouterr()
    wins = f"skill 'pick': {ws / 'skills' / 'pick.yaml'} wins over {skills_dir() / 'pick.yaml'}"
    assert wins in captured.out
    assert "is shadowed by" in caplog.text  # the warning every command logs


def test_a_misspelt_primitive_parameter_in_a_user_tree_is_a_validation_error_with_the_tree_line(tmp_path, capsys):
    ws = tmp_path / "ws"
    bad = TREE.replace("params: {to: grasp_pose, velocity_scale: 0.2}", "params: {to: grasp_pose, velocity: 0.2}")
    user_skill(ws, tree=bad)
    graph = tmp_path / "g.yaml"
    graph.write_text(GRAPH, encoding="utf-8")
    assert main(["validate", str(graph), "--workspace", str(ws)]) == 2
    err = capsys.readouterr().err
    line = next(i for i, ln in enumerate(bad.splitlines(), 1) if "velocity: 0.2" in ln) - 1  # the leaf's line
    assert f"{graph}:" in err and f"nudge.yaml:{line}" in err and "velocity" in err
    assert main(["submit", str(graph), "--workspace", str(ws)]) == 2
    capsys.readouterr()
    assert not list((ws / "runs").glob("r*"))  # no run registered


def test_every_primitive_has_a_schema_table_matching_its_signature():
    assert set(TABLES) >= set(PRIMITIVES.values())
    for schema in primitive_schemas():
        names = [p for p in inspect.signature(schema.cls.__init__).parameters if p not in ("self", "name")]
        assert [p.name for p in schema.params] == names
        assert all(p.type and p.description for p in schema.params)


def test_primitives_prints_every_parameter_with_type_unit_and_default(capsys):
    assert main(["primitives", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == set(PRIMITIVES)
    [approach] = [p for p in data["compute_grasp"]["params"] if p["name"] == "approach_height_m"]
    assert approach == {"name": "approach_height_m", "type": "float", "unit": "m", "required": False, "default": 0.1,
                        "description": "pre-grasp height above the grasp"}
    [obj] = [p for p in data["compute_grasp"]["params"] if p["name"] == "object"]
    assert obj["required"] is True


def test_docs_primitives_md_is_current():
    committed = (REPO / "docs" / "primitives.md").read_text(encoding="utf-8")
    assert committed == primitives_markdown(), (
        "docs/primitives.md is stale; regenerate with: phyagentos primitives --markdown > docs/primitives.md")
