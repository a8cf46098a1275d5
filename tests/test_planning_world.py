"""The motion planner's world is what the robot perceived, not the simulator's state (issue 28:
the true object poses and initial placements of an external benchmark are ground truth, and the
Runtime plane planned around them; DESIGN.md, "What each plane may know").

On a generated scene of libero_goal task 8 (LIBERO's placement sampler, never an init state)
with the objects and fixtures declared with their looks: the checker's world holds each object
where the perceiver saw it (moved in the simulator afterwards, it stays there), nothing that was
not perceived, each fixture's model where the perceiver puts its frame, each drawer at its read
opening; the held object rides in the hand where the look saw it and stays where the hand opens.
The simulator's state is read here only to score those placements.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
from test_libero_goal_pick import FIXTURE_LOOKS, LOOKS

from phyagentos.perception.errors import PerceptionError
from phyagentos.perception.fixtures import FixtureLook, RootLook
from phyagentos.primitives import planning_world
from phyagentos.primitives.motion import session_checker
from phyagentos.primitives.observation import make_perceiver, perceive_now
from phyagentos.targets.contract import PlansInPerceivedWorld
from phyagentos.targets.libero import LiberoScene, LiberoTarget, parse_bddl, resolve_task

pytestmark = pytest.mark.sim

SEED = 102  # a generated scene of "put the bowl on the plate"
# the cabinet's drawers as the bench measures them in libero_goal's world (generated_alone_v8)
DRAWERS = [{"name": name, "handle_offset_m": [0.0053, 0.1019], "height_m": height, "half_length_m": 0.0444,
            "axis_xy": [0.0, 1.0], "travel_m": [-0.01, 0.16], "face_m": 0.008, "half_width_m": 0.1093, "top_m": top,
            "back_m": 0.111}
           for name, height, top in (("top", 0.1889, 0.2223), ("middle", 0.1154, 0.1526), ("bottom", 0.0461, 0.084))]


@pytest.fixture(scope="module")
def goal_world():
    problem = parse_bddl(resolve_task("libero_goal", 8).bddl_path)
    scene = LiberoScene(suite="libero_goal", task=8, generated=True,
                        objects=tuple({"name": n, "class": c, **LOOKS[c]} for n, c in problem.objects.items()),
                        fixtures=tuple({"name": n, "class": c, **FIXTURE_LOOKS.get(c, {}),
                                        **({"drawers": DRAWERS} if c == "wooden_cabinet" else {})}
                                       for n, c in problem.fixtures.items()))
    with LiberoTarget("planning_world", scene, seed=SEED) as target:
        yield target


def _fresh(target):
    target.generate_scene(SEED)
    target.runtime_notes.clear()
    return make_perceiver(target)


def _body_xy(checker_or_target, target, name: str) -> np.ndarray:
    data = checker_or_target.data
    return np.array(data.xpos[target.model.body(target.object_body(name)).id][:2])


def _teleport(target, name: str, xyz) -> None:
    m, d = target.model, target.data
    adr = int(m.jnt_qposadr[int(m.body_jntadr[m.body(target.object_body(name)).id])])
    d.qpos[adr:adr + 3] = xyz
    mujoco.mj_forward(m, d)


def test_libero_plans_in_the_perceived_world_and_names_every_thing_it_may_place(goal_world):
    assert isinstance(goal_world, PlansInPerceivedWorld) and planning_world.plans_in_perceived_world(goal_world)
    bodies = goal_world.planning_bodies()
    assert set(bodies.objects) == {"akita_black_bowl_1", "plate_1", "cream_cheese_1", "wine_bottle_1"}
    assert set(bodies.fixtures) == {"wooden_cabinet_1", "flat_stove_1", "wine_rack_1"}  # not the table
    assert set(bodies.slides) == {f"wooden_cabinet_1_{d}_drawer" for d in ("top", "middle", "bottom")}
    assert all(j.startswith(("robot0_", "gripper0_")) for j in bodies.robot_joints) and len(bodies.robot_joints) == 9


def test_an_object_moved_after_the_look_stays_where_it_was_seen_in_the_planners_world(goal_world):
    target = goal_world
    perceiver = _fresh(target)
    perceive_now(target, perceiver)
    ctx = SimpleNamespace(target=target)
    seen = _body_xy(target, target, "akita_black_bowl_1")
    checker = session_checker(ctx)
    mujoco.mj_kinematics(checker.model, checker.data)
    assert np.linalg.norm(_body_xy(checker, target, "akita_black_bowl_1") - seen) < 0.01  # perceived within 1 cm
    _teleport(target, "akita_black_bowl_1", (3.0, 3.0, 1.2))  # the simulator moves it; nobody looked
    checker = session_checker(ctx)
    mujoco.mj_kinematics(checker.model, checker.data)
    assert np.linalg.norm(_body_xy(checker, target, "akita_black_bowl_1") - seen) < 0.01


def test_nothing_is_in_the_planners_world_before_it_is_perceived(goal_world):
    target = goal_world
    _fresh(target)
    checker = session_checker(SimpleNamespace(target=target))
    mujoco.mj_kinematics(checker.model, checker.data)
    m = target.model
    for body in [*target.planning_bodies().objects.values(), *target.planning_bodies().fixtures.values()]:
        assert checker.data.xpos[m.body(body).id][2] < -10.0, body
    # the robot is where its encoders say
    np.testing.assert_allclose(checker.data.xpos[m.body("robot0_link7").id], target.data.xpos[m.body("robot0_link7").id],
                               atol=1e-9)


def test_each_fixtures_model_stands_where_the_perceiver_puts_its_frame(goal_world):
    target = goal_world
    perceive_now(target, _fresh(target))
    checker = session_checker(SimpleNamespace(target=target))
    mujoco.mj_kinematics(checker.model, checker.data)
    m, d = target.model, target.data
    for name, body in target.planning_bodies().fixtures.items():
        b = m.body(body).id
        assert np.linalg.norm(checker.data.xpos[b] - d.xpos[b]) < 0.015, name  # scored against the truth
        R, Rt = checker.data.xmat[b].reshape(3, 3), d.xmat[b].reshape(3, 3)
        turned = math.degrees(math.acos(np.clip((np.trace(Rt.T @ R) - 1.0) / 2.0, -1.0, 1.0)))
        assert turned < 3.0, (name, turned)
    # the target's own model is never moved
    assert target.model is not checker.model


def test_a_drawer_stands_at_its_read_opening_and_keeps_it_while_its_handle_is_hidden(goal_world):
    target = goal_world
    perceiver = _fresh(target)
    m, d = target.model, target.data
    joint, sign = target.planning_bodies().slides["wooden_cabinet_1_top_drawer"]
    adr = int(m.jnt_qposadr[m.joint(joint).id])
    d.qpos[adr] = sign * 0.12  # opened 12 cm (the scene generator's hand)
    mujoco.mj_forward(m, d)
    target.hold(duration_s=0.2)
    snap = perceive_now(target, perceiver)
    read = next(e for e in snap["entities"] if e["name"] == "wooden_cabinet_1_top_drawer")["attributes"]["joint_position"]
    assert abs(read - 0.12) < 0.02
    checker = session_checker(SimpleNamespace(target=target))
    assert checker.data.qpos[adr] == pytest.approx(sign * read)
    # a look that reads no opening (the handle hidden) keeps the last reading
    hidden = {"entities": [e for e in snap["entities"] if e["name"] != "wooden_cabinet_1_top_drawer"]}
    planning_world.note_observation(target, hidden)
    assert session_checker(SimpleNamespace(target=target)).data.qpos[adr] == pytest.approx(sign * read)
    # the hand pulled it further (articulate_slide tells the world how far its handle travelled)
    planning_world.note_slide(target, "wooden_cabinet_1_top_drawer", 0.16)
    assert session_checker(SimpleNamespace(target=target)).data.qpos[adr] == pytest.approx(sign * 0.16)
    d.qpos[adr] = 0.0
    mujoco.mj_forward(m, d)


def test_a_held_object_rides_where_the_look_saw_it_in_the_hand_and_stays_where_the_hand_opens(goal_world):
    target = goal_world
    perceive_now(target, _fresh(target))
    T_tcp = np.asarray(target.tcp_pose())
    bowl = {"name": "akita_black_bowl_1", "kind": "object", "size": [0.056, 0.056, 0.025],
            "position": (T_tcp[:3, 3] - np.array([0.0, 0.0, 0.03])).tolist(), "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "attributes": {"held": True}}
    planning_world.note_observation(target, {"entities": [bowl]})
    rel = planning_world.in_hand(target, "akita_black_bowl_1")
    centre, _ = planning_world._root_geometry(target, target.object_body("akita_black_bowl_1"))
    np.testing.assert_allclose((T_tcp @ rel)[:3, 3] + centre, bowl["position"], atol=1e-9)
    planning_world.note_release(target)  # the hand opens here
    assert planning_world.in_hand(target, "akita_black_bowl_1") is not None  # where it was left, from the hand now
    o = target.runtime_notes[planning_world.WORLD_NOTE]["objects"]["akita_black_bowl_1"]
    assert o["in_hand"] is None
    np.testing.assert_allclose(np.asarray(o["T"]).reshape(4, 4)[:3, 3] + centre, bowl["position"], atol=1e-9)
    # a look that misses it (the wrist camera straight above it) leaves it where the hand let it go ...
    planning_world.note_observation(target, {"entities": []})
    o = target.runtime_notes[planning_world.WORLD_NOTE]["objects"]["akita_black_bowl_1"]
    np.testing.assert_allclose(np.asarray(o["T"]).reshape(4, 4)[:3, 3] + centre, bowl["position"], atol=1e-9)
    checker = session_checker(SimpleNamespace(target=target))
    mujoco.mj_kinematics(checker.model, checker.data)
    assert checker.data.xpos[target.model.body(target.object_body("akita_black_bowl_1")).id][2] > 0.5  # not parked
    # ... until a look reports it: then where that look saw it, and once gone from a look, gone
    seen = {**bowl, "position": [0.05, 0.1, bowl["position"][2]], "attributes": {}}
    planning_world.note_observation(target, {"entities": [seen]})
    assert not target.runtime_notes[planning_world.WORLD_NOTE]["objects"]["akita_black_bowl_1"].get("let_go")
    planning_world.note_observation(target, {"entities": []})
    assert "akita_black_bowl_1" not in target.runtime_notes[planning_world.WORLD_NOTE]["objects"]


def test_a_long_object_is_turned_so_its_models_long_side_lies_along_the_perceived_box(goal_world):
    target = goal_world
    body = target.object_body("cream_cheese_1")
    centre, half = planning_world._root_geometry(target, body)
    assert half[0] > half[1] * 1.5  # the model's long side is its x
    # a box seen with its long side along the world's y, its yaw reported as 0 (size x the short side)
    seen = {"position": [0.1, 0.2, 0.95], "quat_wxyz": [1.0, 0.0, 0.0, 0.0], "size": [half[1], half[0], half[2]]}
    T = planning_world.object_root_pose(target, body, seen)
    assert abs(abs(T[1, 0]) - 1.0) < 1e-9  # the model's x turned onto the world's y
    np.testing.assert_allclose(T[:3, 3] + T[:3, :3] @ centre, seen["position"], atol=1e-9)


def test_a_model_made_lying_is_stood_on_the_axis_that_fits_the_perceived_height():
    # LIBERO's bottles and cartons are modelled lying: their frame's x stands up as the sampler sets them
    assert planning_world._standing(np.array([0.09, 0.03, 0.025]), np.array([0.025, 0.03, 0.09])) == 0
    # a model that stands on its z is kept so, and so is one whose fits tie (a cube)
    assert planning_world._standing(np.array([0.04, 0.02, 0.01]), np.array([0.02, 0.04, 0.01])) == 2
    assert planning_world._standing(np.array([0.03, 0.03, 0.03]), np.array([0.03, 0.03, 0.03])) == 2


def test_a_root_look_turns_with_the_fixture_and_takes_its_height_from_the_support():
    root = RootLook((0.1, 0.0, 0.005), 0.0, 0.0)
    origin, yaw = root.pose(np.array([1.0, 2.0, 0.9]), 0.0, math.pi, 0.2)
    np.testing.assert_allclose(origin, [0.9, 2.0, 0.9 - 0.1 + 0.005], atol=1e-12)
    assert abs(abs(yaw) - math.pi) < 1e-12
    # a long side read 90 degrees off (a nearly square footprint swapping sides) is not a turn
    origin, _ = root.pose(np.array([1.0, 2.0, 0.9]), 0.5 * math.pi - 0.01, 0.0, 0.2)
    np.testing.assert_allclose(origin[:2], [1.1, 2.0], atol=1e-12)


def test_a_malformed_root_look_is_refused_with_its_keys():
    with pytest.raises(PerceptionError, match="root must be a mapping with keys"):
        FixtureLook.from_dict({"name": "cab", "size_m": [0.2, 0.1, 0.2], "root": {"offset_m": [0, 0, 0]}})
    with pytest.raises(PerceptionError, match="root.offset_m"):
        FixtureLook.from_dict({"name": "cab", "size_m": [0.2, 0.1, 0.2],
                               "root": {"offset_m": [0, 0], "yaw_rad": 0.0, "body_yaw_rad": 0.0}})


def test_the_tabletop_plans_around_its_objects_where_it_saw_them_and_its_declared_workcell():
    from phyagentos.targets import DEFAULT_SCENE, MuJoCoTarget

    with MuJoCoTarget("tabletop", DEFAULT_SCENE, seed=0) as target:
        assert isinstance(target, PlansInPerceivedWorld)
        bodies = target.planning_bodies()
        assert set(bodies.objects) == set(DEFAULT_SCENE.object_names) and not bodies.fixtures and not bodies.slides
        assert len(bodies.robot_joints) == 9 and all(j.startswith("robot:panda0_") for j in bodies.robot_joints)
        ctx = SimpleNamespace(target=target)
        checker = session_checker(ctx)  # nothing seen yet: no cube in the planner's world
        mujoco.mj_kinematics(checker.model, checker.data)
        cube = target.model.body("cube").id
        assert checker.data.xpos[cube][2] < -10.0
        perceive_now(target, make_perceiver(target))
        seen = target.data.xpos[cube].copy()
        checker = session_checker(ctx)
        mujoco.mj_kinematics(checker.model, checker.data)
        assert np.linalg.norm(checker.data.xpos[cube] - seen) < 0.01  # where the cameras put it, within 1 cm
        adr = int(target.model.jnt_qposadr[int(target.model.body_jntadr[cube])])
        target.data.qpos[adr:adr + 3] = (0.3, 0.3, 0.5)  # the simulator moves it; nobody looked
        mujoco.mj_forward(target.model, target.data)
        checker = session_checker(ctx)
        mujoco.mj_kinematics(checker.model, checker.data)
        assert np.linalg.norm(checker.data.xpos[cube] - seen) < 0.01
        # the declared workcell (the wall) is the model's, where the user declared it
        wall = next(g for g in range(target.model.ngeom) if target.model.geom(g).name.startswith("obstacle"))
        np.testing.assert_allclose(checker.data.geom_xpos[wall], target.data.geom_xpos[wall], atol=1e-9)


def test_unnamed_segments_are_boxes_in_the_tabletop_planners_world_but_not_pieces_of_objects_or_the_held():
    from phyagentos.targets import DEFAULT_SCENE, MuJoCoTarget
    from phyagentos.targets.scene import UNSEEN_SLOTS

    def ent(name, kind, xyz, half):
        return {"name": name, "kind": kind, "position": list(xyz), "size": list(half), "quat_wxyz": [1, 0, 0, 0]}

    tcp = np.array([0.4, 0.0, 0.3])
    entities = [ent("cube", "object", (0.5, -0.2, 0.02), (0.02, 0.02, 0.02)),
                ent("unknown_0", "unknown", (0.5, -0.143, 0.025), (0.02, 0.03, 0.025)),  # 0.7 cm clear of the cube
                ent("unknown_1", "unknown", (0.5, -0.171, 0.02), (0.01, 0.01, 0.02)),  # touching it: a piece of it
                ent("unknown_2", "unknown", (0.4, 0.0, 0.29), (0.02, 0.02, 0.02)),  # in the hand
                ent("unknown_3", "unknown", (0.3, 0.3, 0.01), (0.01, 0.01, 0.01))]
    unseen = planning_world._unseen(entities, tcp, 8)
    assert [u["position"] for u in unseen] == [[0.5, -0.143, 0.025], [0.3, 0.3, 0.01]]  # the larger first
    assert len(planning_world._unseen(entities, tcp, 1)) == 1 and planning_world._unseen(entities, tcp, 0) == []
    with MuJoCoTarget("tabletop", DEFAULT_SCENE, seed=0) as target:
        assert len(target.planning_bodies().unseen_slots) == UNSEEN_SLOTS
        ctx = SimpleNamespace(target=target)
        link5 = target.data.xpos[target.model.body("panda0_link5").id]
        q = target.arm_qpos()
        assert session_checker(ctx).is_valid(q)
        planning_world._record(target)["unseen"] = [{"position": link5.tolist(), "size": [0.06, 0.06, 0.06],
                                                     "yaw": 0.3}]
        pairs = session_checker(ctx).colliding_pairs(q)  # a box the cameras saw where the arm stands
        assert ("panda0_link5", "unseen_slot0") in pairs
        # the simulation never meets the spare boxes, wherever the planner put them
        target.hold(duration_s=0.2)
        m, d = target.model, target.data
        slots = {m.body(f"unseen_slot{i}").id for i in range(UNSEEN_SLOTS)}
        assert not any(int(m.geom_bodyid[d.contact[i].geom1]) in slots or int(m.geom_bodyid[d.contact[i].geom2]) in slots
                       for i in range(d.ncon))


def test_a_drawn_objects_planning_model_takes_the_perceived_shape_and_size_not_the_simulators():
    from phyagentos.targets import DEFAULT_SCENE, MuJoCoTarget

    with MuJoCoTarget("tabletop", DEFAULT_SCENE, seed=0) as target:
        assert target.planning_bodies().perceived_shapes
        snapshot = perceive_now(target, make_perceiver(target))
        (cube,) = [e for e in snapshot["entities"] if e["name"] == "cube"]
        checker = session_checker(SimpleNamespace(target=target))
        g = target.model.geom("cube").id
        np.testing.assert_allclose(checker.model.geom_size[g], np.maximum(cube["size"], 1e-3))
        assert np.allclose(target.model.geom_size[g], 0.02)  # the simulation's cube is untouched
        planning_world._record(target)["objects"]["cube"].update(shape="sphere", size=[0.03, 0.03, 0.03])
        checker = session_checker(SimpleNamespace(target=target))
        assert checker.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE and checker.model.geom_size[g][0] == 0.03
        assert target.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX
