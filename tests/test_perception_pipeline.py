"""The perception pipeline on MuJoCo-rendered RGB-D frames, scored against the true poses.

One scene (the tabletop Franka plus a pool of static box / cylinder / sphere slots and two
extra cameras, :mod:`phyagentos.perception.synthetic`) is compiled once; each test places
its objects and renders with seeded camera noise.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from phyagentos.perception import ObjectDescriptor, PerceptionConfig, Perceiver
from phyagentos.perception.synthetic import (
    DEFAULT_CAMERAS,
    WRIST_CAMERA,
    CameraNoise,
    SyntheticObject,
    SyntheticScene,
)

pytestmark = pytest.mark.sim

RED, BLUE, GREEN, YELLOW = (0.85, 0.15, 0.12, 1), (0.15, 0.35, 0.85, 1), (0.15, 0.70, 0.25, 1), (0.95, 0.80, 0.10, 1)


@pytest.fixture(scope="module")
def scene():
    s = SyntheticScene([], cameras=DEFAULT_CAMERAS + (WRIST_CAMERA,), pool_per_shape=3)
    yield s
    s.close()


def _frames(scene, rng, cameras=("front", "side"), stamp_s=0.0):
    return [scene.capture(c, noise=CameraNoise(), rng=rng, stamp_s=stamp_s) for c in cameras]


def _desc(o: SyntheticObject, name=None, **kw):
    return ObjectDescriptor(name or o.name, shape=o.shape, colour_rgb=o.rgba[:3],
                            size_m=tuple(round(2 * h, 3) for h in o.half_extents), **kw)


def _entities(snap):
    return {e["name"]: e for e in snap["entities"]}


def _yaw(e):
    q = e["quat_wxyz"]
    return 2.0 * math.atan2(q[3], q[0])


def test_box_cylinder_and_sphere_poses_sizes_and_shapes_match_the_truth(scene):
    box = SyntheticObject("box", "box", (0.03, 0.015, 0.02), (0.48, -0.08), yaw=0.4, rgba=RED)
    can = SyntheticObject("can", "cylinder", (0.02, 0.02, 0.035), (0.60, 0.10), rgba=BLUE)
    ball = SyntheticObject("ball", "sphere", (0.025, 0.025, 0.025), (0.45, 0.15), rgba=GREEN)
    scene.place([box, can, ball])
    p = Perceiver(PerceptionConfig.default(), [_desc(o) for o in (box, can, ball)])
    snap = p.observe(_frames(scene, np.random.default_rng(1)), scene.proprioception())
    ents = _entities(snap)
    for o in (box, can, ball):
        e = ents[o.name]
        assert e["kind"] == "object" and e["attributes"]["shape"] == o.shape
        assert np.linalg.norm(np.subtract(e["position"], o.centre)) < 0.004, (o.name, e["position"], o.centre)
        size = sorted(2 * np.array(e["size"][:2])) + [2 * e["size"][2]]
        true = sorted(2 * np.array(o.half_extents[:2])) + [2 * o.half_extents[2]]
        assert np.max(np.abs(np.subtract(size, true))) < 0.006, (o.name, size, true)
        assert e["attributes"]["source"] == "perceived" and e["attributes"]["confidence"] > 0.5
        assert sorted(e["attributes"]["cameras"]) == ["front", "side"]
    # yaw of the rectangular box, modulo its half-turn symmetry
    d = (_yaw(ents["box"]) - 0.4 + math.pi / 2) % math.pi - math.pi / 2
    assert abs(d) < math.radians(3.0)
    assert ents["box"]["attributes"]["yaw_std_rad"] < 0.1
    assert ents["can"]["attributes"]["yaw_std_rad"] == pytest.approx(math.pi, abs=1e-3)  # yaw of a disc: meaningless
    assert snap["unseen"] == [] and snap["frame"] == "world"
    # the support plane was fitted, not assumed
    assert snap["support_plane"]["fitted"] and abs(snap["support_plane"]["offset_m"]) < 0.002


def test_colours_associate_despite_touching_distractors_of_other_colours(scene):
    red = SyntheticObject("red_cube", "box", (0.02, 0.02, 0.02), (0.50, 0.0), yaw=0.2, rgba=RED)
    # a yellow box pressed against the red cube, and a green box of the same size nearby
    yellow = SyntheticObject("d_yellow", "box", (0.02, 0.02, 0.02), (0.50, 0.0401), yaw=0.0, rgba=YELLOW)
    green = SyntheticObject("d_green", "box", (0.02, 0.02, 0.02), (0.62, -0.12), yaw=0.7, rgba=GREEN)
    blue = SyntheticObject("blue_can", "cylinder", (0.018, 0.018, 0.03), (0.42, -0.15), rgba=BLUE)
    scene.place([red, yellow, green, blue])
    p = Perceiver(PerceptionConfig.default(), [_desc(red), _desc(blue)])
    snap = p.observe(_frames(scene, np.random.default_rng(2)), scene.proprioception())
    ents = _entities(snap)
    assert np.linalg.norm(np.subtract(ents["red_cube"]["position"][:2], red.position)) < 0.004
    assert np.linalg.norm(np.subtract(ents["blue_can"]["position"][:2], blue.position)) < 0.004
    unknown = [e for e in snap["entities"] if e["kind"] == "unknown"]
    assert len(unknown) == 2 and all(e["name"].startswith("unknown_") for e in unknown)
    near = {min((yellow, green), key=lambda o: np.hypot(*np.subtract(e["position"][:2], o.position))).name
            for e in unknown}
    assert near == {"d_yellow", "d_green"}


def test_a_lookalike_pair_is_ambiguous_and_never_guessed(scene):
    a = SyntheticObject("a", "box", (0.02, 0.02, 0.02), (0.48, -0.10), yaw=0.1, rgba=RED)
    b = SyntheticObject("b", "box", (0.02, 0.02, 0.02), (0.58, 0.10), yaw=0.5, rgba=RED)
    scene.place([a, b])
    p = Perceiver(PerceptionConfig.default(), [_desc(a, name="red_cube")])
    snap = p.observe(_frames(scene, np.random.default_rng(3)), scene.proprioception())
    assert "red_cube" not in _entities(snap) and snap["unseen"] == ["red_cube"]
    unknown = [e for e in snap["entities"] if e["kind"] == "unknown"]
    assert len(unknown) == 2 and all(e["attributes"]["ambiguous"] for e in unknown)


def test_an_object_out_of_view_or_removed_is_unseen_not_guessed(scene):
    cube = SyntheticObject("cube", "box", (0.02, 0.02, 0.02), (0.55, 0.05), rgba=RED)
    ball = SyntheticObject("ball", "sphere", (0.02, 0.02, 0.02), (0.45, -0.1), rgba=GREEN)
    scene.place([cube, ball])
    p = Perceiver(PerceptionConfig.default(), [_desc(cube), _desc(ball)])
    rng = np.random.default_rng(4)
    first = p.observe(_frames(scene, rng, stamp_s=1.0), scene.proprioception(stamp_s=1.0))
    assert {"cube", "ball"} <= set(_entities(first))
    scene.move_object("cube", (0.55, 2.5, 0.02))  # far outside both cameras' view
    second = p.observe(_frames(scene, rng, stamp_s=2.0), scene.proprioception(stamp_s=2.0))
    assert "cube" not in _entities(second) and second["unseen"] == ["cube"]
    assert not any(r["object"] == "cube" or r["subject"] == "cube" for r in second["relations"])
    assert "ball" in _entities(second)


def test_a_second_camera_and_a_second_frame_shrink_the_uncertainty(scene):
    cube = SyntheticObject("cube", "box", (0.02, 0.025, 0.02), (0.52, 0.02), yaw=-0.3, rgba=BLUE)
    scene.place([cube])
    rng = np.random.default_rng(5)
    frames = _frames(scene, rng)
    one = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    s1 = _entities(one.observe(frames[:1], scene.proprioception()))["cube"]
    two = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    s2 = _entities(two.observe(frames, scene.proprioception()))["cube"]
    assert s2["attributes"]["position_std_m"] < s1["attributes"]["position_std_m"]
    for e in (s1, s2):
        assert np.linalg.norm(np.subtract(e["position"][:2], cube.position)) < 0.005
    # a second observation with fresh noise, fused into the track: smaller again
    s3 = _entities(two.observe(_frames(scene, rng, stamp_s=0.5), scene.proprioception(stamp_s=0.5)))["cube"]
    assert s3["attributes"]["position_std_m"] < s2["attributes"]["position_std_m"]
    assert s3["attributes"]["confidence"] >= s2["attributes"]["confidence"]
    assert np.linalg.norm(np.subtract(s3["position"][:2], cube.position)) < 0.004


def test_a_moved_object_restarts_its_track_instead_of_averaging(scene):
    cube = SyntheticObject("cube", "box", (0.02, 0.02, 0.02), (0.50, -0.05), rgba=RED)
    scene.place([cube])
    rng = np.random.default_rng(6)
    p = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    p.observe(_frames(scene, rng), scene.proprioception())
    scene.move_object("cube", (0.56, 0.06, 0.02))
    e = _entities(p.observe(_frames(scene, rng, stamp_s=1.0), scene.proprioception(stamp_s=1.0)))["cube"]
    assert np.linalg.norm(np.subtract(e["position"][:2], (0.56, 0.06))) < 0.004


def test_stacked_objects_and_regions_give_on_and_inside(scene):
    base = SyntheticObject("base", "box", (0.03, 0.03, 0.02), (0.52, 0.10), rgba=RED)
    top = SyntheticObject("top", "box", (0.015, 0.015, 0.015), (0.52, 0.10), yaw=0.3, rgba=BLUE, z_base_m=0.04)
    scene.place([base, top])
    p = Perceiver(PerceptionConfig.default(), [_desc(base), _desc(top)])
    snap = p.observe(_frames(scene, np.random.default_rng(7)), scene.proprioception(),
                     regions=[{"name": "goal", "center": [0.5, 0.12], "half_extents": [0.08, 0.08]},
                              {"name": "bin", "center": [0.5, -0.3], "half_extents": [0.05, 0.05]}])
    rels = {(r["subject"], r["relation"], r["object"]) for r in snap["relations"]}
    assert ("top", "on", "base") in rels and ("base", "on", "table") in rels
    assert ("base", "inside", "goal") in rels and ("top", "on", "table") not in rels
    assert not any(r[2] == "bin" for r in rels)
    e = _entities(snap)["top"]
    assert abs(e["position"][2] - top.centre[2]) < 0.004 and abs(e["size"][2] - 0.015) < 0.004


def test_holding_follows_the_tcp_from_proprioception_and_not_from_contacts(scene):
    tcp = scene.tcp_pose()
    cube = SyntheticObject("cube", "box", (0.02, 0.02, 0.02), (float(tcp[0, 3]), float(tcp[1, 3])), rgba=RED)
    scene.place([cube])
    scene.set_fingers(0.04)
    rng = np.random.default_rng(8)
    p = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    free = scene.proprioception(gripper_effort_n=0.0, wrist_force_n=(0.0, 0.0, -1.0), stamp_s=0.0)
    snap = p.observe(_frames(scene, rng), free)
    assert _entities(snap)["cube"]["attributes"]["source"] == "perceived"
    assert not any(r["relation"] == "holding" for r in snap["relations"])
    # grasped and lifted to the tcp: the fingers squeeze a 4 cm gap, the wrist carries a load
    scene.move_object("cube", tuple(tcp[:3, 3]))
    scene.set_fingers(0.02)
    held = scene.proprioception(gripper_effort_n=25.0, wrist_force_n=(0.0, 0.0, -2.0), stamp_s=1.0)
    snap = p.observe(_frames(scene, rng, stamp_s=1.0), held)
    ents = _entities(snap)
    e = ents["cube"]
    assert e["attributes"]["source"] == "proprioception" and e["attributes"]["held"]
    assert np.linalg.norm(np.subtract(e["position"], tcp[:3, 3])) < 0.01
    hold = [r for r in snap["relations"] if r["relation"] == "holding"]
    assert hold and hold[0]["object"] == "cube" and hold[0]["confidence"] > 0.5
    assert not any(x["kind"] == "unknown" for x in snap["entities"])  # the hand's content is not a cluster
    assert ents["gripper"]["attributes"]["opening_m"] == pytest.approx(0.02)
    # fingers closed on nothing (a missed grasp): the cube, still on the table, is not held
    scene.move_object("cube", (*cube.position, 0.02))
    scene.set_fingers(0.0)
    p2 = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    p2.observe(_frames(scene, rng), free)
    missed = scene.proprioception(gripper_effort_n=25.0, wrist_force_n=(0.0, 0.0, -1.0), stamp_s=2.0)
    snap = p2.observe(_frames(scene, rng, stamp_s=2.0), missed)
    assert not any(r["relation"] == "holding" for r in snap["relations"])
    assert _entities(snap)["cube"]["attributes"]["source"] == "perceived"


def test_a_hold_seen_only_after_the_lift_keeps_where_across_the_hand_it_closed_on_the_object(scene):
    """The hand closed 15 mm along its fingers off the cube's centre (and 5 mm below it), then
    lifted before anyone looked: the held cube is reported 15 mm off the tcp along the fingers,
    from the close's note, at the tcp's height (how high it sits keeps the centred rule), and
    the height at which the close found it along the tcp's z beside it (``grasp_z_tcp_m``)."""
    import dataclasses

    tcp = scene.tcp_pose()
    along = 0.015
    x_axis = tcp[:3, 0]  # along the fingers (tcp y is the closing direction)
    cube = SyntheticObject("cube", "box", (0.02, 0.02, 0.02), (float(tcp[0, 3]), float(tcp[1, 3])), rgba=RED)
    rng = np.random.default_rng(11)
    reports, seen_z = {}, {}
    for noted in (False, True):
        scene.place([cube])
        scene.set_fingers(0.04)
        p = Perceiver(PerceptionConfig.default(), [_desc(cube)])
        p.observe(_frames(scene, rng), scene.proprioception(stamp_s=0.0))
        T_close = tcp.copy()  # the tcp at the close: 15 mm along the fingers from the cube, 5 mm below its centre
        T_close[:3, 3] = np.array([*cube.position, 0.015]) - along * x_axis
        if noted:
            closed = scene.proprioception(gripper_effort_n=25.0, stamp_s=0.5)
            p.note_grasp_close(dataclasses.replace(closed, tcp_pose=T_close))
        # lifted to where the tcp stands now, the cube 15 mm along the fingers from it
        scene.move_object("cube", tuple(tcp[:3, 3] + along * x_axis))
        scene.set_fingers(0.02)
        snap = p.observe(_frames(scene, rng, stamp_s=1.0),
                         scene.proprioception(gripper_effort_n=25.0, wrist_force_n=(0.0, 0.0, -2.0), stamp_s=1.0))
        e = _entities(snap)["cube"]
        assert e["attributes"]["held"]
        reports[noted] = np.subtract(e["position"], tcp[:3, 3])
        seen_z[noted] = e["attributes"].get("grasp_z_tcp_m")
    assert np.linalg.norm(reports[True] - along * x_axis) < 0.003
    assert np.linalg.norm(reports[False]) < 0.003  # without the note: assumed centred, as before
    expected = float((np.linalg.inv(T_close) @ np.array([*cube.position, 0.02, 1.0]))[2])  # the cube's centre then
    assert abs(expected) > 0.004 and seen_z[True] == pytest.approx(expected, abs=0.003)
    assert seen_z[False] is None  # nothing seen at a close: nothing reported


def test_the_close_note_survives_export_and_is_forgotten_once_the_hand_opens(scene):
    import dataclasses
    import json

    cube = SyntheticObject("cube", "box", (0.02, 0.02, 0.02), (0.52, -0.04), rgba=RED)
    scene.place([cube])
    p = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    closed = scene.proprioception(gripper_effort_n=25.0, stamp_s=0.5)
    p.note_grasp_close(closed)
    state = json.loads(json.dumps(p.export_state()))
    assert state["closed_at"]["stamp_s"] == 0.5
    q = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    q.restore_state(state)
    assert q.export_state()["closed_at"] == state["closed_at"]
    q.update_proprioception(scene.proprioception(gripper_effort_n=0.0, stamp_s=1.0))  # the hand opened
    assert q.export_state()["closed_at"] is None
    from phyagentos.perception import PerceptionError

    bad = dict(state, closed_at={"tcp_pose": [[1.0, 0.0], [0.0, 1.0]], "stamp_s": 0.5})
    with pytest.raises(PerceptionError, match="closed_at"):
        q.restore_state(bad)
    with pytest.raises(PerceptionError, match="Proprioception"):
        p.note_grasp_close(dataclasses.asdict(closed))


def test_observe_rejects_frames_without_depth(scene):
    from phyagentos.perception import CameraFrame, PerceptionError

    scene.place([])
    f = scene.capture("front")
    rgb_only = CameraFrame(f.sensor, f.frame_id, f.stamp_s, f.intrinsics, f.T_world_camera, f.rgb, None)
    with pytest.raises(PerceptionError, match="no depth image"):
        Perceiver().observe([rgb_only], scene.proprioception())
    with pytest.raises(PerceptionError, match="at least one camera frame"):
        Perceiver().observe([], scene.proprioception())


def test_the_arm_reaching_down_to_the_table_leaves_no_spurious_object(scene):
    import mujoco

    from phyagentos.motion.ik import solve_ik
    from phyagentos.targets.scene import HOME_QPOS

    cube = SyntheticObject("cube", "box", (0.02, 0.02, 0.02), (0.62, 0.0), yaw=0.3, rgba=RED)
    scene.place([cube])
    T = scene.tcp_pose()
    T[:3, 3] = (0.50, 0.0, 0.025)  # fingertips at the table, 12 cm from the cube
    q = solve_ik(scene.model, q_seed=HOME_QPOS, target=T).q
    try:
        scene.data.qpos[:7] = q
        mujoco.mj_forward(scene.model, scene.data)
        p = Perceiver(PerceptionConfig.default(), [_desc(cube)])
        snap = p.observe(_frames(scene, np.random.default_rng(9)), scene.proprioception())
    finally:
        scene.data.qpos[:7] = HOME_QPOS
        mujoco.mj_forward(scene.model, scene.data)
    ents = _entities(snap)
    assert not any(e["kind"] == "unknown" for e in snap["entities"])
    assert np.linalg.norm(np.subtract(ents["cube"]["position"][:2], cube.position)) < 0.004


def test_exported_state_continues_the_tracks_in_a_new_perceiver(scene):
    import json

    cube = SyntheticObject("cube", "box", (0.02, 0.02, 0.02), (0.52, -0.04), rgba=RED)
    scene.place([cube])
    rng = np.random.default_rng(10)
    first = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    s1 = _entities(first.observe(_frames(scene, rng), scene.proprioception()))["cube"]
    state = json.loads(json.dumps(first.export_state()))  # plain data, survives a process boundary
    second = Perceiver(PerceptionConfig.default(), [_desc(cube)])
    second.restore_state(state)
    s2 = _entities(second.observe(_frames(scene, rng, stamp_s=1.0), scene.proprioception(stamp_s=1.0)))["cube"]
    assert s2["attributes"]["position_std_m"] < s1["attributes"]["position_std_m"]  # fused, not restarted
    other = Perceiver(PerceptionConfig.default(), [ObjectDescriptor("ball", shape="sphere")])
    other.restore_state(state)
    assert other.tracks == {}  # tracks of objects not declared any more are dropped


def test_the_wrist_camera_alone_finds_objects_and_masks_its_own_fingers(scene):
    cube = SyntheticObject("cube", "box", (0.02, 0.015, 0.02), (0.50, 0.03), yaw=0.3, rgba=RED)
    ball = SyntheticObject("ball", "sphere", (0.02, 0.02, 0.02), (0.40, -0.05), rgba=GREEN)
    scene.place([cube, ball])
    frame = scene.capture("wrist", noise=CameraNoise(), rng=np.random.default_rng(11))
    assert np.mean(frame.depth_m[frame.depth_m > 0] < 0.3) > 0.05  # the fingers are in view
    snap = Perceiver(PerceptionConfig.default(), [_desc(cube), _desc(ball)]).observe([frame], scene.proprioception())
    ents = _entities(snap)
    assert not any(e["kind"] == "unknown" for e in snap["entities"])
    for o in (cube, ball):
        assert ents[o.name]["attributes"]["shape"] == o.shape
        assert np.linalg.norm(np.subtract(ents[o.name]["position"], o.centre)) < 0.004
        assert ents[o.name]["attributes"]["cameras"] == ["wrist"]


@pytest.mark.parametrize("swap", [False, True])
def test_a_spatial_reference_names_the_lookalike_its_relation_picks_out(scene, swap):
    """Two identical red boxes, declared red_cube_1 ("the one next to the blue can") and
    red_cube_2: rendered and perceived, red_cube_1 is the box beside the can, whichever of the
    two slots holds it; the twin is the other; a later observation keeps both by their tracks."""
    near_xy, far_xy = (0.50, 0.06), (0.56, -0.16)
    if swap:  # the same boxes, the other slot order: index order cannot decide it
        near_xy, far_xy = far_xy, near_xy
    a = SyntheticObject("a", "box", (0.02, 0.02, 0.02), near_xy, yaw=0.2, rgba=RED)
    b = SyntheticObject("b", "box", (0.02, 0.02, 0.02), far_xy, yaw=0.6, rgba=RED)
    can_xy = (near_xy[0] + 0.0, near_xy[1] + 0.07)
    can = SyntheticObject("can", "cylinder", (0.02, 0.02, 0.03), can_xy, rgba=BLUE)
    scene.place([a, b, can])
    p = Perceiver(PerceptionConfig.default(), [
        _desc(a, name="red_cube_1", where={"relation": "next_to", "of": ["can"]}), _desc(b, name="red_cube_2"),
        _desc(can)])
    rng = np.random.default_rng(21)
    snap = p.observe(_frames(scene, rng), scene.proprioception())
    ents = _entities(snap)
    assert snap["references"]["red_cube_1"]["resolved"], snap["references"]
    assert np.linalg.norm(np.array(ents["red_cube_1"]["position"][:2]) - near_xy) < 0.015
    assert np.linalg.norm(np.array(ents["red_cube_2"]["position"][:2]) - far_xy) < 0.015
    # the can moves beside the other box: the tracked boxes keep their names
    scene.move_object("can", (far_xy[0], far_xy[1] + 0.07, 0.03))
    again = _entities(p.observe(_frames(scene, rng, stamp_s=1.0), scene.proprioception(stamp_s=1.0)))
    assert np.linalg.norm(np.array(again["red_cube_1"]["position"][:2]) - near_xy) < 0.015


def test_an_unresolvable_spatial_reference_leaves_both_lookalikes_unnamed(scene):
    a = SyntheticObject("a", "box", (0.02, 0.02, 0.02), (0.50, 0.06), yaw=0.2, rgba=RED)
    b = SyntheticObject("b", "box", (0.02, 0.02, 0.02), (0.56, -0.16), yaw=0.6, rgba=RED)
    scene.place([a, b])  # the landmark (a blue can) is declared but nowhere to be seen
    can = SyntheticObject("can", "cylinder", (0.02, 0.02, 0.03), (0.5, 0.13), rgba=BLUE)
    p = Perceiver(PerceptionConfig.default(), [
        _desc(a, name="red_cube_1", where={"relation": "next_to", "of": ["can"]}), _desc(b, name="red_cube_2"),
        _desc(can)])
    snap = p.observe(_frames(scene, np.random.default_rng(22)), scene.proprioception())
    assert not snap["references"]["red_cube_1"]["resolved"]
    assert "not perceived" in snap["references"]["red_cube_1"]["reason"]
    assert {"red_cube_1", "red_cube_2"} <= set(snap["unseen"])
    assert sum(e["kind"] == "unknown" for e in snap["entities"]) == 2
