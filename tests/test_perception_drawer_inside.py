"""A bowl standing in LIBERO's open top drawer, perceived from recorded camera frames (issue 28,
libero_spatial task 4: "the black bowl in the top drawer of the wooden cabinet").

``tests/data/libero_drawer_bowl_frames.npz``: both cameras' RGB-D frames and the arm's
proprioception at the start pose of one generated libero_spatial task-4 scene (LIBERO's placement
sampler, seed 90001: never an init state; ``akita_black_bowl_1`` then set in the open top drawer,
``akita_black_bowl_2`` on the cabinet's top), the declared scene as the LIBERO bench writes it
(looks measured on generated scenes, the reference read by the rule reader) and the bowls' true
centres (scoring only), recorded by ``bench/libero_drawer_refs.py --record``.

``tests/data/libero_drawer_bowl_back_frames.npz``: the same, of the scene LIBERO's sampler made
with seed 501 as the bench's ``--generated`` episodes see it (``--placement sampler``): the
bowl at the back of the open drawer, its far side under the cabinet's body.

``tests/data/libero_plate_under_drawer_frames.npz``: the first scene of ``bench/libero_drawer_refs.py
--seeds 90000-90003 --plate-under`` (the bowls as in the first file, the plate then set on the table
with its rim 2.5 cm in under the open top drawer's front).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from libero_clouds import recorded_frames

from phyagentos.perception import PerceptionConfig, Perceiver, RobotCapsule
from phyagentos.perception.frames import CameraFrame

DATA = Path(__file__).parent / "data" / "libero_drawer_bowl_frames.npz"
BACK = Path(__file__).parent / "data" / "libero_drawer_bowl_back_frames.npz"
PLATE_UNDER = Path(__file__).parent / "data" / "libero_plate_under_drawer_frames.npz"


def _recorded(path: Path = DATA):
    return recorded_frames(path)


def _observe(declared, meta, frames, proprio):
    p = Perceiver(PerceptionConfig.model_validate(meta["perception_config"]), declared)  # the target's
    capsules = [RobotCapsule(p0=tuple(a), p1=tuple(b), radius_m=r) for a, b, r in meta["robot_capsules"]]
    snap = p.observe(frames, proprio, robot_capsules=capsules)
    return {e["name"]: e for e in snap["entities"]}, snap


def test_the_bowl_in_the_open_drawer_is_seen_resting_on_its_floor_and_named_by_the_reference():
    frames, proprio, meta = _recorded()
    seen, snap = _observe(meta["declared"], meta, frames, proprio)
    truth = meta["truth"]
    ref = snap["references"]["akita_black_bowl_1"]
    assert ref["resolved"] and "inside wooden_cabinet_1_top_drawer" in ref["reason"], ref
    bowl = seen["akita_black_bowl_1"]
    assert np.linalg.norm(np.subtract(bowl["position"][:2], truth["akita_black_bowl_1"][:2])) < 0.015
    assert bowl["attributes"]["confidence"] >= 0.5
    # it rests on the drawer's floor (about 16 cm up), not on the table under the drawer
    assert bowl["position"][2] - bowl["size"][2] - meta["table_z"] == pytest.approx(0.164, abs=0.01)
    # the twin on the cabinet's top is the other one
    twin = seen["akita_black_bowl_2"]
    assert np.linalg.norm(np.subtract(twin["position"][:2], truth["akita_black_bowl_2"][:2])) < 0.03
    assert snap["entities"] and "wooden_cabinet_1_top_drawer" in seen


def test_a_bowl_at_the_back_of_the_open_drawer_cut_off_by_the_cabinets_body_is_named_as_seen():
    """The cabinet's body claims its points, so the bowl's far side under the body is cut off:
    the bowl is seen 11.2 by 6.4 cm. Its footprint then counts as a lower bound (at least half
    of each side shown, its height as measured), as at the image border: it is named, not left
    at 0.08 for a 6.4 cm box, and kept as seen (its rim taken near the ends of its long side)."""
    frames, proprio, meta = _recorded(BACK)
    seen, snap = _observe(meta["declared"], meta, frames, proprio)
    assert snap["references"]["akita_black_bowl_1"]["resolved"]
    bowl = seen["akita_black_bowl_1"]
    assert bowl["attributes"]["confidence"] >= 0.9, bowl["attributes"]
    assert min(bowl["size"][:2]) < 0.045 and max(bowl["size"][:2]) > 0.054  # as seen, not completed
    truth = meta["truth"]
    assert np.linalg.norm(np.subtract(bowl["position"][:2], truth["akita_black_bowl_1"][:2])) < 0.03
    assert "akita_black_bowl_2" in seen


def test_without_the_drawers_look_the_bowl_is_not_named_rather_than_guessed():
    """The cabinet declared without its drawers: no drawer is read, its inside is no landmark,
    and the bowl in it is no part of anything known: the reference stays unresolved and neither
    bowl is named (never the one on the top in its place)."""
    frames, proprio, meta = _recorded()
    declared = json.loads(json.dumps(meta["declared"]))
    for f in declared["fixtures"]:
        f.pop("drawers", None)
    seen, snap = _observe(declared, meta, frames, proprio)
    assert not snap["references"]["akita_black_bowl_1"]["resolved"]
    assert "akita_black_bowl_1" not in seen and "akita_black_bowl_2" not in seen


def test_a_plate_under_the_open_drawer_keeps_its_rim_and_is_named(monkeypatch):
    """The drawer's own points stop at its underside (15.5 cm up for the top drawer): the
    plate's rim on the table under it is the plate's. With no floor to the drawer's box (the
    behaviour before), the rim went with the drawer and the plate was not named."""
    from phyagentos.perception.fixtures import DrawerLook

    frames, proprio, meta = _recorded(PLATE_UNDER)
    seen, _ = _observe(meta["declared"], meta, frames, proprio)
    plate = seen.get("plate_1")
    assert plate is not None and plate["kind"] == "object" and plate["attributes"]["confidence"] >= 0.9, plate
    assert np.linalg.norm(np.subtract(plate["position"][:2], meta["truth"]["plate_1"][:2])) < 0.005
    assert "akita_black_bowl_1" in seen  # the bowl in the drawer as before
    monkeypatch.setattr(DrawerLook, "bottom_m", property(lambda self: 0.0))
    seen, _ = _observe(meta["declared"], meta, frames, proprio)
    assert "plate_1" not in seen or seen["plate_1"]["kind"] != "object", seen.get("plate_1")


def _hide(frames, centre, radius_m):
    """The frames with no depth return where the scene lies within ``radius_m`` of ``centre``
    (3,) world m: something standing between the cameras and it, as the arm's links do."""
    out = []
    for f in frames:
        K = f.intrinsics
        vv, uu = np.mgrid[0:K.height, 0:K.width]
        d = f.depth_m
        pc = np.stack([(uu - K.cx) / K.fx * d, (vv - K.cy) / K.fy * d, d], axis=-1)
        pw = pc @ f.T_world_camera[:3, :3].T + f.T_world_camera[:3, 3]
        depth = np.where(np.linalg.norm(pw - np.asarray(centre), axis=-1) < radius_m, 0.0, d).astype(np.float32)
        out.append(CameraFrame(f.sensor, f.frame_id, f.stamp_s, K, f.T_world_camera, f.rgb, depth))
    return out


def test_an_open_drawer_is_a_floor_to_set_things_in_and_the_bowl_in_it_rests_on_it():
    """The open top drawer's entity is its floor out of the cabinet's body (its top the floor,
    16 cm up), ``support`` true: a place the place primitive sets a held thing into; the bowl
    standing in it is judged on it by the verifier's ``on`` on this observation alone."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    frames, proprio, meta = _recorded()
    seen, snap = _observe(meta["declared"], meta, frames, proprio)
    drawer = seen["wooden_cabinet_1_top_drawer"]
    attrs = drawer["attributes"]
    assert attrs["support"] is True and attrs["source"] == "perceived" and attrs["joint_position"] > 0.1
    top = drawer["position"][2] + drawer["size"][2] - meta["table_z"]
    assert top == pytest.approx(0.164, abs=0.01)
    # turned with the cabinet: its long side across the opening axis, the handle's centre 3.0 cm past the
    # floor's front, the inside of the drawer's front (the model: 2.95 cm; 3.7 cm before the twenty-eighth pass)
    axis = np.asarray(attrs["axis"][:2])
    w, _, _, z = drawer["quat_wxyz"]
    long_side = np.array([np.cos(2 * np.arctan2(z, w)), np.sin(2 * np.arctan2(z, w))])
    assert abs(long_side @ axis) < 0.01
    half_along = drawer["size"][1]
    handle = (np.asarray(attrs["grasp"]["position"][:2]) - drawer["position"][:2]) @ axis
    assert handle - half_along == pytest.approx(0.030, abs=0.005)
    (on,) = parse_criteria([{"on": {"object": "akita_black_bowl_1", "support": "wooden_cabinet_1_top_drawer"}}])
    judged = evaluate(on, snap, snap)
    assert judged.status == "satisfied", judged.reason
    # the bowl on the cabinet's top is on no drawer
    (twin,) = parse_criteria([{"on": {"object": "akita_black_bowl_2", "support": "wooden_cabinet_1_top_drawer"}}])
    assert evaluate(twin, snap, snap).status == "unsatisfied"


def test_a_drawer_whose_handle_is_hidden_is_remembered_as_a_place_never_as_a_reading():
    """Its handle hidden (no depth return there: a held bowl or the arm in front of it), the open
    drawer is reported where it was last read, ``remembered``, still a place to set things in, but
    without ``joint_position``: the ``articulated`` criterion cannot judge an opening on it. The
    memory crosses sessions with the perceiver's state."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    frames, proprio, meta = _recorded()
    p = Perceiver(PerceptionConfig.model_validate(meta["perception_config"]), meta["declared"])
    capsules = [RobotCapsule(p0=tuple(a), p1=tuple(b), radius_m=r) for a, b, r in meta["robot_capsules"]]
    first = {e["name"]: e for e in p.observe(frames, proprio, robot_capsules=capsules)["entities"]}
    read = first["wooden_cabinet_1_top_drawer"]
    later = Perceiver(PerceptionConfig.model_validate(meta["perception_config"]), meta["declared"])
    later.restore_state(p.export_state())
    hidden = _hide(frames, read["attributes"]["grasp"]["position"], 0.2)
    snap = later.observe(hidden, proprio, robot_capsules=capsules)
    drawer = {e["name"]: e for e in snap["entities"]}["wooden_cabinet_1_top_drawer"]
    attrs = drawer["attributes"]
    assert attrs["source"] == "remembered" and attrs["support"] is True and "joint_position" not in attrs
    assert drawer["position"] == pytest.approx(read["position"], abs=1e-3)  # (its height from the table fit again)
    (opened,) = parse_criteria([{"articulated": {"object": "wooden_cabinet_1_top_drawer", "min_fraction": 0.8}}])
    judged = evaluate(opened, snap, snap)
    assert judged.status == "unknown" and "no joint_position" in judged.reason
