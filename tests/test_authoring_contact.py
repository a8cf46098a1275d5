"""Contact is expressible (issue 11, item 5): ``guarded_move`` stops on contact with a
force limit and its own tracking tolerance, and fails when contact it expects never
comes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import py_trees
import pytest

from phyagentos.cli import main
from phyagentos.motion.grasp import FRANKA_FINGERS
from phyagentos.primitives import SkillContext
from phyagentos.primitives.contact import GuardedMove
from phyagentos.targets import MuJoCoTarget
from phyagentos.targets.scene import SceneSpec

DATA = Path(__file__).resolve().parent / "data_authoring"
#: The tabletop Franka's finger bodies: what the contact leaves report as touched when the
#: closed hand presses with its fingertips.
FINGERS = ["panda0_leftfinger", "panda0_rightfinger"]
#: The tabletop Franka's fingertips below its tcp, m.
FRANKA_TIP_M = FRANKA_FINGERS[0]


def test_a_user_touch_skill_presses_on_the_cube_and_stops_at_the_force_limit(tmp_path, capsys):
    ws = tmp_path / "ws"
    (ws / "skills").mkdir(parents=True)
    (ws / "trees").mkdir()
    shutil.copy(DATA / "touch_skill.yaml", ws / "skills" / "touch.yaml")
    shutil.copy(DATA / "touch_tree.yaml", ws / "trees" / "touch.yaml")
    graph = DATA / "touch_graph.yaml"
    assert main(["run", str(graph), "--workspace", str(ws), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["succeeded"]
    [trace] = list((ws / "evidence").glob("*/trace.jsonl"))
    [contact] = [json.loads(line) for line in trace.read_text().splitlines() if '"contact"' in line]
    # the robot's own parts that touched (a real arm's force sensing names no other body)
    assert contact["touched"] == FINGERS and contact["force_n"] >= 5.0
    assert 0.03 < contact["travelled_m"] < 0.09  # stopped on the cube's top, not at the end of the offset


@pytest.fixture
def target():
    t = MuJoCoTarget("contact", SceneSpec.default(), seed=0)
    yield t
    t.close()


def _tick_until_done(leaf, ctx, limit: int = 400):
    py_trees.blackboard.Blackboard.clear()
    leaf.setup(context=ctx)
    for _ in range(limit):
        leaf.tick_once()
        if leaf.status != py_trees.common.Status.RUNNING:
            return leaf.status
    raise AssertionError("leaf never finished")


def test_a_guarded_move_through_free_space_fails_with_contact_missing(target):
    ctx = SkillContext(target=target)
    z0 = target.tcp_pose()[2, 3]
    status = _tick_until_done(GuardedMove("Up", offset=[0.0, 0.0, 0.05]), ctx)
    assert status == py_trees.common.Status.FAILURE and ctx.failure["code"] == "contact.missing"
    assert target.tcp_pose()[2, 3] == pytest.approx(z0 + 0.05, abs=0.01)


def test_a_guarded_move_that_may_miss_succeeds_without_contact(target):
    ctx = SkillContext(target=target)
    status = _tick_until_done(GuardedMove("Up", offset=[0.0, 0.0, 0.05], expect_contact=False), ctx)
    assert status == py_trees.common.Status.SUCCESS


def test_a_compliant_push_moves_the_cube_into_the_region_through_the_cli(tmp_path, capsys):
    ws = tmp_path / "ws"
    assert main(["run", str(DATA / "push_graph.yaml"), "--workspace", str(ws), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["succeeded"]  # the verifier found the cube inside the goal region 10 cm away
    [trace] = list((ws / "evidence").glob("*/trace.jsonl"))
    [push] = [json.loads(line) for line in trace.read_text().splitlines() if '"kind": "push"' in line]
    assert push["touched"] and set(push["touched"]) <= set(FINGERS) and 0.0 < push["max_force_n"] <= 40.0


def _touching(target, body: str) -> set[str]:
    """The bodies in contact with body ``body`` now, from the simulator's contact pairs (ground
    truth: the test's to read, never the skills')."""
    m, d = target.model, target.data
    b = m.body(body).id
    out = set()
    for i in range(d.ncon):
        pair = (int(m.geom_bodyid[d.contact[i].geom1]), int(m.geom_bodyid[d.contact[i].geom2]))
        if b in pair:
            other = pair[1] if pair[0] == b else pair[0]
            out.add(m.body(other).name)
    return out - {"world"}


def _record_steps(target):
    """Wrap ``target.track`` to record, after every call, the physics steps it took and
    the contact force then (N): what the primitive saw, step by step."""
    from phyagentos.primitives.contact import contact_force_n

    calls = []
    track = target.track

    def recording(traj, **kw):
        result = track(traj, **kw)
        force, _ = contact_force_n(target.model, target.data)
        calls.append((result.steps, float(target.data.time), force))
        return result

    target.track = recording
    return calls


def test_a_guarded_move_stops_within_one_physics_step_of_the_force_limit(target):
    """Pressing down on the cube at a fast speed: the force is measured after every
    physics step, and the motion stops at the very step the limit is first reached (the
    old per-control-period check let up to 50 steps of pressing pass unchecked)."""
    ctx = SkillContext(target=target)
    target.set_gripper(opening_m=0.0)  # a closed hand presses with its fingertips
    cube = target.object_pose("cube")[:3, 3]
    T = target.tcp_pose()
    down = cube[2] + 0.02 - 0.03 - T[2, 3]  # tcp 1 cm below the cube's top face
    # above the cube first (free space, no contact expected)
    over = [cube[0] - T[0, 3], cube[1] - T[1, 3], 0.0]
    assert _tick_until_done(GuardedMove("Over", offset=over, velocity_scale=0.5, expect_contact=False), ctx) \
        == py_trees.common.Status.SUCCESS
    calls = _record_steps(target)
    limit = 15.0
    status = _tick_until_done(GuardedMove("Press", offset=[0.0, 0.0, down], velocity_scale=0.3,
                                          max_contact_force_n=limit, tracking_tol_rad=0.5), ctx)
    assert status == py_trees.common.Status.SUCCESS, ctx.failure
    assert calls and all(steps <= 1 for steps, _, _ in calls)  # one physics step per force check
    first = next(i for i, (_, _, f) in enumerate(calls) if f >= limit)
    assert first == len(calls) - 1  # no physics step after the limit was reached
    reader = py_trees.blackboard.Client(name="reader")
    reader.register_key(key="contact", access=py_trees.common.Access.READ)
    assert reader.contact["force_n"] >= limit and reader.contact["touched"] == FINGERS
    # the simulator's contacts (ground truth, for this test): it was the cube the fingers pressed
    assert _touching(target, "cube") == set(FINGERS)
    assert reader.contact["sim_time_s"] - calls[first][1] <= target.model.opt.timestep + 1e-12


def _tick_with(leaf, ctx, board: dict, limit: int = 600):
    """:func:`_tick_until_done` with blackboard values written first (what earlier leaves
    of a tree would have written)."""
    py_trees.blackboard.Blackboard.clear()
    leaf.setup(context=ctx)
    for key, value in board.items():
        py_trees.blackboard.Blackboard.set(f"/{key}", value)
    for _ in range(limit):
        leaf.tick_once()
        if leaf.status != py_trees.common.Status.RUNNING:
            return leaf.status
    raise AssertionError("leaf never finished")


def _over(target, ctx, name: str, *, above_m: float):
    """The closed hand straight over object ``name``, its tcp (at the fingertips) ``above_m`` m
    above the object's top."""
    target.set_gripper(opening_m=0.0)
    T_obj = target.object_pose(name)
    top = T_obj[2, 3] + target.scene.object(name).half_extents[2]
    T = target.tcp_pose()
    over = [T_obj[0, 3] - T[0, 3], T_obj[1, 3] - T[1, 3], 0.0]
    assert _tick_until_done(GuardedMove("Over", offset=over, velocity_scale=0.5, expect_contact=False), ctx) \
        == py_trees.common.Status.SUCCESS
    down = top + above_m - target.tcp_pose()[2, 3]
    assert _tick_until_done(GuardedMove("Down", offset=[0.0, 0.0, down], velocity_scale=0.5, expect_contact=False),
                            ctx) == py_trees.common.Status.SUCCESS
    return T_obj[:3, 3].copy(), top


@pytest.fixture
def tile_target():
    """A flat tile (10 by 10 by 2 cm, 50 g) where the default scene's cube stands, and the cube
    25 cm to its side."""
    from phyagentos.targets.scene import ObjectSpec

    spec = SceneSpec(objects=(ObjectSpec(name="tile", half_extents=(0.05, 0.05, 0.01), position=(0.5, -0.2),
                                         mass=0.05), ObjectSpec(name="cube", position=(0.5, 0.05))))
    t = MuJoCoTarget("contact", spec, seed=0)
    yield t
    t.close()


def test_a_push_pressed_from_above_lands_on_the_object_then_drags_it_along(tile_target):
    """The tabletop Franka's fingers (friction 1.5 over the table's 1.0) carry a 50 g tile when the
    press holds: here 8 mm below where the hand landed (its servos hold a shallower press with
    almost no force once the landing's bounce has passed)."""
    from phyagentos.primitives.contact import Push

    target = tile_target
    ctx = SkillContext(target=target)
    start, top = _over(target, ctx, "tile", above_m=0.03)
    press = {"contact_n": 2.0, "depth_m": 0.008, "descent_m": 0.05, "object": "tile", "top_m": top,
             "tip_m": FRANKA_TIP_M}
    status = _tick_with(Push("Drag", offset=[0.0, 0.06, 0.0], velocity_scale=0.2, press="push_press"), ctx,
                        {"push_press": press})
    assert status == py_trees.common.Status.SUCCESS, ctx.failure
    moved = target.object_pose("tile")[:3, 3] - start
    assert moved[1] > 0.03 and abs(moved[0]) < 0.01  # carried along under the fingertips, most of the way
    assert abs(moved[2]) < 0.003  # dragged along the table, not tipped or lifted
    [landed] = [r for r in ctx.trace.records if r["kind"] == "press"]
    assert landed["force_n"] >= 2.0 and landed["touched"] == FINGERS
    assert landed["landed_z"] == pytest.approx(top + 0.015, abs=0.006)  # the fingertips (1.5 cm below the tcp) on its top


def test_a_press_that_lands_on_another_object_fails_before_it_drags_anything(tile_target):
    from phyagentos.primitives.contact import Push

    target = tile_target
    ctx = SkillContext(target=target)
    cube, _ = _over(target, ctx, "cube", above_m=0.03)
    tile = target.object_pose("tile")[:3, 3].copy()
    tile_top = float(tile[2]) + target.scene.object("tile").half_extents[2]  # as perceived: 2 cm below the cube's
    press = {"contact_n": 2.0, "depth_m": 0.008, "descent_m": 0.05, "object": "tile", "top_m": tile_top,
             "tip_m": FRANKA_TIP_M}
    status = _tick_with(Push("Drag", offset=[0.0, 0.06, 0.0], press="push_press"), ctx, {"push_press": press})
    assert status == py_trees.common.Status.FAILURE and ctx.failure["code"] == "execution.collision"
    assert "above tile's perceived top" in ctx.failure["message"]
    assert np.linalg.norm(target.object_pose("cube")[:2, 3] - cube[:2]) < 0.005  # pressed, never dragged
    assert np.linalg.norm(target.object_pose("tile")[:3, 3] - tile) < 1e-3


def test_the_same_push_without_a_press_passes_over_the_tile_and_moves_nothing(tile_target):
    from phyagentos.primitives.contact import Push

    target = tile_target
    ctx = SkillContext(target=target)
    start, _ = _over(target, ctx, "tile", above_m=0.03)
    status = _tick_with(Push("Drag", offset=[0.0, 0.06, 0.0], velocity_scale=0.2, press="push_press"), ctx,
                        {"push_press": None})
    assert status == py_trees.common.Status.FAILURE and ctx.failure["code"] == "contact.missing"
    assert np.linalg.norm(target.object_pose("tile")[:3, 3] - start) < 1e-3


def test_a_press_from_above_that_lands_on_nothing_fails_with_contact_missing(target):
    from phyagentos.primitives.contact import Push

    ctx = SkillContext(target=target)
    z0 = target.tcp_pose()[2, 3]
    press = {"contact_n": 2.0, "depth_m": 0.002, "descent_m": 0.03}
    status = _tick_with(Push("Drag", offset=[0.0, 0.06, 0.0], press="push_press"), ctx, {"push_press": press})
    assert status == py_trees.common.Status.FAILURE and ctx.failure["code"] == "contact.missing"
    assert target.tcp_pose()[2, 3] == pytest.approx(z0 - 0.03, abs=0.005)  # lowered, never dragged
