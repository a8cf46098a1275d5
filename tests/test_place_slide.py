"""A place onto a fixture's top slid across it when something beside the fixture blocks its
centre (libero_goal_swap task 1: the wine rack's side over the stove's back half), never off
the top's footprint, and never onto an object's top (LIBERO counts a thing on another only
within 3 cm of its centre)."""

from __future__ import annotations

import numpy as np
import pytest
from place_leaf import compute_place

from phyagentos.primitives.perception import SLIDE_EDGE_MARGIN_M, SLIDE_STEPS_M, Blocked


@pytest.fixture(scope="module")
def franka():
    from phyagentos.targets import MuJoCoTarget
    from phyagentos.targets.scene import SceneSpec

    t = MuJoCoTarget("slide", SceneSpec.default(), seed=0)
    yield t
    t.close()


def _snapshot(tcp, *, kind="fixture", half=0.075):
    stove = {"name": "stove", "kind": kind, "position": [0.5, 0.0, 0.01], "quat_wxyz": [1, 0, 0, 0],
             "size": [half, half, 0.01], "attributes": {"confidence": 0.99}}
    held = {"name": "bowl", "kind": "object", "position": [float(tcp[0, 3]), float(tcp[1, 3]), float(tcp[2, 3]) - 0.03],
            "quat_wxyz": [1, 0, 0, 0], "size": [0.056, 0.056, 0.025], "attributes": {"confidence": 0.9}}
    return {"entities": [stove, held]}


def _rack_over_the_back(reach_m):
    """Blocked where the held object's centre (the tcp's xy here) stands less than ``reach_m``
    in front (+x) of the stove's centre: a rack over its back half."""
    def blocked(T_pre, T_place):
        if T_place[0, 3] < 0.5 + reach_m - 1e-9:
            return Blocked("place collides: bowl-wine_rack_1_g2", stage="place", collides=True)
        return None
    return blocked


def test_a_place_blocked_at_the_tops_centre_slides_the_nearest_way_clear(franka):
    tcp = np.asarray(franka.tcp_pose())
    centred, _ = compute_place(franka, _snapshot(tcp), object="bowl", region="stove")
    board, [rec] = compute_place(franka, _snapshot(tcp), _rack_over_the_back(0.045), object="bowl", region="stove")
    # 2 and 3.5 cm are not clear of it, 5 cm straight forward is the nearest spot that is
    assert rec["slid_m"] == pytest.approx([SLIDE_STEPS_M[2], 0.0], abs=1e-4)
    shift = board["place_pose"][:3, 3] - centred["place_pose"][:3, 3]
    assert shift == pytest.approx([0.05, 0.0, 0.0], abs=1e-4)
    assert board["preplace_pose"][:2, 3] == pytest.approx(board["place_pose"][:2, 3])
    assert len(rec["rejected_yaws"]) >= 1


def test_a_slide_keeps_the_objects_centre_inside_the_tops_footprint(franka):
    tcp = np.asarray(franka.tcp_pose())
    # a top 8 cm across leaves 2 cm of room each way: the 5 cm step is shortened to it, and a
    # blocker 3 cm out leaves no spot at all: the centre's yaw 0 stands (the planner says why)
    board, [rec] = compute_place(franka, _snapshot(tcp, half=0.04), _rack_over_the_back(0.015), object="bowl",
                                 region="stove")
    assert rec["slid_m"] == pytest.approx([0.04 - SLIDE_EDGE_MARGIN_M, 0.0], abs=1e-4)
    board, [rec] = compute_place(franka, _snapshot(tcp, half=0.04), _rack_over_the_back(0.03), object="bowl",
                                 region="stove")
    assert "slid_m" not in rec and rec["yaw_rad"] == pytest.approx(0.0)
    assert board["place_pose"][0, 3] == pytest.approx(0.5, abs=1e-3)


def test_onto_an_object_or_where_only_reach_fails_the_place_does_not_slide(franka):
    tcp = np.asarray(franka.tcp_pose())
    _, [rec] = compute_place(franka, _snapshot(tcp, kind="object"), _rack_over_the_back(0.045), object="bowl",
                             region="stove")
    assert "slid_m" not in rec

    def out_of_reach(T_pre, T_place):
        return Blocked("no IK solution for the place", stage="place", collides=False)

    _, [rec] = compute_place(franka, _snapshot(tcp), out_of_reach, object="bowl", region="stove")
    assert "slid_m" not in rec
