"""Placement inside a region (issue 11, item 5): ``place_at`` aims at a slot or an offset
instead of the region's centre, so two objects share a region side by side, and a spot
the object does not fit in is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import py_trees
import pytest

from phyagentos.cli import main
from phyagentos.primitives import SkillContext
from phyagentos.primitives.placement import ComputePlaceAt, slot_grid, slot_offset
from phyagentos.targets import MuJoCoTarget
from phyagentos.targets.scene import SceneSpec

GRAPH = """\
version: 1
name: two_in_one_region
defaults: {{target: franka_tabletop}}
scene:
  objects:
    - {{name: red_cube, half_extents: [0.02, 0.02, 0.02], position: [0.45, -0.2]}}
  regions:
    - {{name: bin, center: [0.52, 0.22], half_extents: [0.09, 0.05]}}
nodes:
  - id: pick_red
    skill: pick
    params: {{object: red_cube}}
    accept: {{holding: red_cube}}
  - id: place_red
    skill: place_at
    params: {{object: red_cube, region: bin, {where}}}
    accept: {{inside: {{object: red_cube, region: bin}}}}
    depends_on: [pick_red]
"""


def test_slots_split_the_longer_axis_evenly():
    assert slot_offset((0.09, 0.05), 0, 2) == pytest.approx([-0.045, 0.0])
    assert slot_offset((0.09, 0.05), 1, 2) == pytest.approx([0.045, 0.0])
    assert slot_offset((0.04, 0.10), 2, 3) == pytest.approx([0.0, 0.10 - 0.10 / 3])


@pytest.fixture
def target():
    t = MuJoCoTarget("placement", SceneSpec.default(), seed=0)
    yield t
    t.close()


def _place(target, leaf) -> np.ndarray:
    """World xy where the place pose computed by ``leaf`` puts the cube."""
    ctx = SkillContext(target=target)
    py_trees.blackboard.Blackboard.clear()
    writer = py_trees.blackboard.Client(name="test")
    writer.register_key(key="snapshot", access=py_trees.common.Access.WRITE)
    writer.snapshot = target.snapshot()
    leaf.setup(context=ctx)
    leaf.tick_once()
    if leaf.status != py_trees.common.Status.SUCCESS:
        return ctx.failure
    reader = py_trees.blackboard.Client(name="reader")
    reader.register_key(key="place_pose", access=py_trees.common.Access.READ)
    T_tcp_obj = np.linalg.inv(target.tcp_pose()) @ target.object_pose("cube")
    return (reader.place_pose @ T_tcp_obj)[:2, 3]


def test_place_at_a_slot_puts_the_object_off_centre_inside_the_region(target):
    goal = target.scene.region("goal")  # centre (0.5, 0.25), half extents (0.08, 0.08)
    xy0 = _place(target, ComputePlaceAt("P0", object="cube", region="goal", slot=0, slots=2))
    xy1 = _place(target, ComputePlaceAt("P1", object="cube", region="goal", slot=1, slots=2))
    assert xy0 == pytest.approx([goal.center[0] - 0.04, goal.center[1]], abs=1e-6)
    assert xy1 == pytest.approx([goal.center[0] + 0.04, goal.center[1]], abs=1e-6)
    xy = _place(target, ComputePlaceAt("P2", object="cube", region="goal", offset_m=[0.0, -0.03]))
    assert xy == pytest.approx([goal.center[0], goal.center[1] - 0.03], abs=1e-6)


def test_a_spot_the_object_does_not_fit_in_is_refused(target):
    failure = _place(target, ComputePlaceAt("P", object="cube", region="goal", offset_m=[0.07, 0.0]))
    assert failure["code"] == "place.outside_region"


def test_a_slot_out_of_range_is_a_validation_error_before_anything_moves(tmp_path, capsys):
    graph = tmp_path / "g.yaml"
    graph.write_text(GRAPH.format(where="slot: 2, slots: 2"), encoding="utf-8")
    assert main(["validate", str(graph)]) == 2
    err = capsys.readouterr().err
    assert f"{graph}:16:" in err and "slot must be a whole number in [0, 1]" in err
    graph.write_text(GRAPH.format(where="slot: 1, slots: 2"), encoding="utf-8")
    assert main(["validate", str(graph)]) == 0


def test_two_cubes_share_one_region_side_by_side_through_the_cli(tmp_path, capsys):
    import json

    import yaml

    graph = Path(__file__).resolve().parent / "data_authoring" / "two_in_one_region.yaml"
    ws = tmp_path / "ws"
    assert main(["run", str(graph), "--workspace", str(ws), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    last = [s for s in report["sessions"] if s["node"] == "place_blue"][-1]
    from phyagentos.protocol import Workspace

    rec = Workspace.open(ws).load_session(last["session_id"])
    terminal = yaml.safe_load((ws / rec.attempts[-1].evidence / "terminal.yaml").read_text(encoding="utf-8"))
    entities = terminal.get("entities", terminal) if isinstance(terminal, dict) else terminal
    pos = {e["name"]: e["position"] for e in entities if e["name"] in ("red_cube", "blue_cube")}
    assert abs(pos["red_cube"][2] - pos["blue_cube"][2]) < 0.01  # side by side, not stacked
    assert np.hypot(pos["red_cube"][0] - pos["blue_cube"][0], pos["red_cube"][1] - pos["blue_cube"][1]) > 0.06


STACK = """\
version: 1
name: stack
defaults: {target: franka_tabletop}
scene:
  objects:
    - {name: red_cube, half_extents: [0.02, 0.02, 0.02], position: [0.45, -0.2], rgba: [0.85, 0.2, 0.15, 1]}
    - {name: blue_cube, half_extents: [0.025, 0.025, 0.025], position: [0.55, 0.2], rgba: [0.15, 0.3, 0.85, 1]}
nodes:
  - id: pick_red
    skill: pick
    params: {object: red_cube}
    accept: {holding: red_cube}
  - id: stack_red
    skill: place
    params: {object: red_cube, region: blue_cube}
    accept: {on: {object: red_cube, support: blue_cube}}
    depends_on: [pick_red]
"""


def test_place_on_another_object_stacks_it_through_the_cli(tmp_path, capsys):
    """``place`` with ``region`` naming an object sets the held one down on its top face;
    the predicate ``on`` is written unquoted (YAML 1.1 would read it as ``true``)."""
    import json

    graph = tmp_path / "stack.yaml"
    graph.write_text(STACK, encoding="utf-8")
    ws = tmp_path / "ws"
    assert main(["run", str(graph), "--workspace", str(ws), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert {s["node"]: s["status"] for s in report["sessions"]} == {"pick_red": "succeeded", "stack_red": "succeeded"}
    qpos = np.load(ws / "targets" / "franka_tabletop" / "state.npz")["qpos"]
    red, blue = qpos[9:12], qpos[16:19]  # free joints after 7 arm + 2 finger joints, in scene order
    assert red[2] == pytest.approx(2 * 0.025 + 0.02, abs=0.005)  # resting on the blue cube's top face
    assert np.hypot(*(red[:2] - blue[:2])) < 0.02


def test_three_or_four_cells_of_a_square_region_stand_two_by_two_and_a_strip_keeps_one_row():
    assert slot_grid((0.07, 0.07), 2) == (2, 1)
    assert slot_grid((0.07, 0.07), 3) == (2, 2) and slot_grid((0.07, 0.07), 4) == (2, 2)
    assert slot_grid((0.04, 0.10), 3) == (3, 1)
    assert slot_offset((0.07, 0.07), 2, 3) == pytest.approx([-0.035, 0.035])
    assert slot_offset((0.07, 0.07), 1, 3) == pytest.approx([0.035, -0.035])


def test_the_fit_is_checked_on_the_footprint_the_object_will_have(target):
    # a 4 cm cube 5.9 cm off the centre of an 8 cm half-extent region: its side reaches 7.9 cm
    # (inside), where the circle around it (2.8 cm) would reach 8.7 cm
    xy = _place(target, ComputePlaceAt("P", object="cube", region="goal", offset_m=[0.059, 0.0]))
    assert isinstance(xy, np.ndarray), xy
