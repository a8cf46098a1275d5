"""A pick whose first observation does not name its object looks from nearer at what perception
saw but could not tell (``primitives/search.py``): which unnamed segment first, and a look pose
from which the hand camera really sees the point it aims at (a real model, a real render)."""

from __future__ import annotations

import numpy as np
import py_trees
import pytest

from phyagentos.motion.grasp import hand_yaw
from phyagentos.primitives import PRIMITIVES, PrimitiveFailure, SkillContext
from phyagentos.primitives.motion import clear_ik
from phyagentos.primitives.search import (
    LOOK_REVISIT_M,
    ComputeSearchLook,
    ObjectSeen,
    hand_camera_offset,
    look_pose,
    unnamed_segments,
)
from phyagentos.protocol.sensors import SensorSpec
from phyagentos.targets import MuJoCoTarget, SceneSpec

QUIET = {"depth_sigma_per_m2": 0.0, "rgb_sigma": 0.0, "lighting_jitter": 0.0}


def _ent(name, kind, xy, size=(0.03, 0.03, 0.04), cls=None):
    attrs = {"confidence": 0.8, **({"class": cls} if cls else {})}
    return {"name": name, "kind": kind, "position": [xy[0], xy[1], size[2]], "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "size": list(size), "attributes": attrs}


def _wrist(t):
    t.configure_sensors([SensorSpec(name="wrist", kind="rgbd_camera", frame_id="wrist_optical", rate_hz=10, width=320,
                                    height=240, mount={"body": "panda0_link7", "camera": "wrist"}, noise=QUIET)])


@pytest.fixture
def franka():
    t = MuJoCoTarget("search", seed=0)
    yield t
    t.close()


def test_a_segment_apart_from_everything_named_comes_before_a_piece_beside_a_named_object():
    snap = {"entities": [
        _ent("mug_1", "object", (0.50, -0.20), size=(0.045, 0.045, 0.05), cls="mug"),
        _ent("unknown_0", "unknown", (0.52, -0.16), size=(0.02, 0.01, 0.04)),  # its handle, beside it
        _ent("unknown_1", "unknown", (0.40, 0.20), size=(0.015, 0.02, 0.04)),  # a sliver on its own
        _ent("bowl_1", "unknown", (0.60, 0.00)),  # a declared object seen too weakly to be named keeps its name
        _ent("plate_1", "unknown", (0.30, -0.30), cls="plate"),  # or its class
        _ent("tcp", "robot", (0.40, 0.21)), _ent("gripper", "gripper", (0.40, 0.21)),  # the robot: neither
    ]}
    assert [e["name"] for e in unnamed_segments(snap, declared={"mug_1", "bowl_1", "plate_1"})] == ["unknown_1",
                                                                                                  "unknown_0"]
    # without the declared names the weak bowl is a segment too (it has no class to tell it by)
    assert "bowl_1" in [e["name"] for e in unnamed_segments(snap)]
    assert unnamed_segments({"entities": [_ent("mug_1", "object", (0.5, 0.0), cls="mug")]}) == []


def test_from_the_look_pose_the_hand_camera_sees_the_point_at_its_centre_from_the_look_height():
    with MuJoCoTarget("search", SceneSpec(objects=()), seed=0) as franka:
        _wrist(franka)
        T_tcp_cam = hand_camera_offset(franka)
        assert T_tcp_cam is not None and np.linalg.norm(T_tcp_cam[:3, 3]) > 0.05  # the camera is off the tcp
        point, height = np.array([0.45, 0.15, 0.02]), 0.30
        T = look_pose(point, yaw_rad=hand_yaw(franka.tcp_pose()), height_m=height, T_tcp_cam=T_tcp_cam)
        sol, pairs, _ = clear_ik(SkillContext(target=franka), T)
        assert not pairs
        assert franka.invoke_tool("move_joints", q=list(sol.q))["completed"]
        f = franka.capture("wrist")
    T_cw = np.linalg.inv(f.T_world_camera)
    p = T_cw[:3, :3] @ point + T_cw[:3, 3]
    u, v, w = f.intrinsics.matrix() @ p
    assert abs(u / w - 159.5) < 8 and abs(v / w - 119.5) < 8  # at the image centre (the arm tracks within 4 mm)
    assert f.T_world_camera[2, 3] - point[2] == pytest.approx(height, abs=0.01)  # from the look height
    # without the camera's offset the tcp, not the camera, is over the point
    plain = look_pose(point, yaw_rad=0.0, height_m=height, T_tcp_cam=None)
    assert np.allclose(plain[:3, 3], point + [0.0, 0.0, height]) and plain[2, 2] == pytest.approx(-1.0)


def _leaf(cls, target, board, **params):
    leaf = cls(cls.__name__, **params)
    leaf.setup(context=SkillContext(target=target))
    leaf.get = lambda key: board[key]
    leaf.set = board.__setitem__
    return leaf


def test_the_search_aims_at_each_segment_once_then_reports_the_object_not_found(franka):
    _wrist(franka)
    snap = {"entities": [_ent("plate_1", "object", (0.50, -0.25), size=(0.07, 0.07, 0.01), cls="plate"),
                         _ent("unknown_0", "unknown", (0.55, -0.17)), _ent("unknown_1", "unknown", (0.45, 0.20))]}
    board = {"snapshot": snap}
    leaf = _leaf(ComputeSearchLook, franka, board, object="mug_1", max_looks=3)
    aims = []
    for _ in range(2):
        assert leaf.step() is None
        aims.append(next(r for r in reversed(leaf.ctx.trace.records) if r["kind"] == "search_look"))
        assert board["look_pose"].shape == (4, 4) and board["look_pose"][2, 2] == pytest.approx(-1.0)
    assert [a["segment"] for a in aims] == ["unknown_1", "unknown_0"] and [a["look"] for a in aims] == [1, 2]
    # the snapshot after a look names the same segments again: none is aimed at twice
    with pytest.raises(PrimitiveFailure, match="no unnamed segment is left") as err:
        leaf.step()
    assert err.value.code == "perception.not_found" and "plate_1" in str(err.value)
    # a segment within LOOK_REVISIT_M of an aimed point is the same one seen again
    moved = {"entities": [_ent("unknown_3", "unknown", (0.45 + 0.5 * LOOK_REVISIT_M, 0.20))]}
    again = _leaf(ComputeSearchLook, franka, {"snapshot": moved}, object="mug_1", max_looks=3)
    again._aimed = [np.array([0.45, 0.20, 0.04])]
    with pytest.raises(PrimitiveFailure, match="no unnamed segment"):
        again.step()
    # max_looks bounds the looks; 0 takes none
    none = _leaf(ComputeSearchLook, franka, {"snapshot": snap}, object="mug_1", max_looks=0)
    with pytest.raises(PrimitiveFailure, match="after 0 look"):
        none.step()


def test_object_seen_fails_quietly_so_the_skill_reports_what_follows(franka):
    board = {"snapshot": {"entities": [_ent("mug_1", "object", (0.5, 0.0), cls="mug")]}}
    assert _leaf(ObjectSeen, franka, board, object="mug_1").step() == py_trees.common.Status.SUCCESS
    leaf = _leaf(ObjectSeen, franka, board, object="bowl_1")
    assert leaf.step() == py_trees.common.Status.FAILURE
    assert leaf.ctx.failure is None and leaf.ctx.trace.records == []
    assert PRIMITIVES["object_seen"] is ObjectSeen and PRIMITIVES["compute_search_look"] is ComputeSearchLook


def test_a_bad_search_parameter_is_refused_with_the_valid_range():
    with pytest.raises(ValueError, match="max_looks must be an integer >= 0"):
        ComputeSearchLook("L", object="mug_1", max_looks=-1)
    with pytest.raises(ValueError, match=r"look_height_m must be a number in \(0.05, 1\]"):
        ComputeSearchLook("L", object="mug_1", look_height_m=2.0)


def test_a_look_the_safety_guard_would_stop_is_not_aimed_at(franka):
    from phyagentos.protocol.schemas import SafetyConfig
    from phyagentos.runtime.safety_guard import EStopLatch, SafetyGuard

    _wrist(franka)
    snap = {"entities": [_ent("unknown_0", "unknown", (0.40, 0.25)), _ent("unknown_1", "unknown", (0.55, -0.15))]}
    # the box ends at y 0.1: the look over the segment at y 0.25 would leave it
    safety = SafetyConfig(workspace_box={"min": [-0.2, -0.8, 0.0], "max": [1.0, 0.1, 1.2]})
    board = {"snapshot": snap}
    leaf = _leaf(ComputeSearchLook, franka, board, object="mug_1", max_looks=2)
    leaf.ctx.guard = SafetyGuard.for_target(franka, safety, events=[], estop=EStopLatch())
    assert unnamed_segments(snap)[0]["name"] == "unknown_0"  # the first choice, were it not for the box
    leaf.step()
    [rec] = [r for r in leaf.ctx.trace.records if r["kind"] == "search_look"]
    assert rec["segment"] == "unknown_1" and board["look_pose"][1, 3] < 0.1 - 0.01
    with pytest.raises(PrimitiveFailure, match="no unnamed segment is left"):
        leaf.step()
