"""A place into an open container lowers the held object between its walls towards the floor
perception found, and lets it go there, not at the rim: LIBERO-10 task 0's soup can, let go
with its base at the basket's rim (12 cm over the floor), slid 3-5 cm towards the middle on
landing (inits 2 and 7), and the sauce set in the other corner then lay on it. The retreat
after the release rises as much further as the place went down, so the look down between the
walls is taken from where it was before."""

from __future__ import annotations

import numpy as np
import pytest
from place_leaf import compute_place

from phyagentos.primitives.execution import CartesianMove
from phyagentos.primitives.perception import LET_DOWN_STEP_M, SINK_CLEAR_M, Blocked

#: LIBERO's basket as perceived whole (half extents, m) on a table at z 0, its floor 12 cm down.
BASKET_HALF = (0.0814, 0.0871, 0.076)
BASKET_DEPTH_M = 0.12


@pytest.fixture(scope="module")
def franka():
    from phyagentos.targets import MuJoCoTarget
    from phyagentos.targets.scene import SceneSpec

    t = MuJoCoTarget("sink", SceneSpec.default(), seed=0)
    yield t
    t.close()


def _snapshot(tcp, *, depth=BASKET_DEPTH_M, seen_z=None):
    basket = {"name": "basket_1", "kind": "object", "position": [0.5, 0.0, BASKET_HALF[2]],
              "quat_wxyz": [1, 0, 0, 0], "size": list(BASKET_HALF),
              "attributes": {"confidence": 0.95, **({"open_depth_m": depth} if depth else {})}}
    can = {"name": "can", "kind": "object", "position": [float(tcp[0, 3]), float(tcp[1, 3]), float(tcp[2, 3]) - 0.02],
           "quat_wxyz": [1, 0, 0, 0], "size": [0.034, 0.034, 0.046],
           "attributes": {"confidence": 0.9, "shape": "cylinder",
                          **({"grasp_z_tcp_m": seen_z} if seen_z is not None else {})}}
    return {"entities": [basket, can], "viewer": {"right_xy": [0.0, -1.0]}}


def _hand_meets_the_walls_below(z_tcp):
    """Blocked where the tcp goes lower than ``z_tcp`` (m): the hand's palm meets the rim."""
    def blocked(T_pre, T_place):
        if T_place[2, 3] < z_tcp - 1e-9:
            return Blocked("place collides: hand-basket_1_g3", stage="place", collides=True)
        return None
    return blocked


def _can_base(board, tcp, snapshot):
    """World z of the held can's base at the place (its pose in the hand kept)."""
    can = next(e for e in snapshot["entities"] if e["name"] == "can")
    offset = float(can["position"][2]) - float(tcp[2, 3])
    return float(board["place_pose"][2, 3]) + offset - float(can["size"][2])


def test_an_object_set_into_a_basket_goes_down_to_just_over_its_floor(franka):
    tcp = np.asarray(franka.tcp_pose())
    snap = _snapshot(tcp)
    board, [rec] = compute_place(franka, snap, object="can", region="basket_1")
    top = 2 * BASKET_HALF[2]
    floor = top - BASKET_DEPTH_M
    base = _can_base(board, tcp, snap)
    assert floor + SINK_CLEAR_M - 1e-9 <= base <= floor + SINK_CLEAR_M + LET_DOWN_STEP_M
    assert rec["sunk_m"] == pytest.approx(board["place_sunk_m"])
    assert board["place_sunk_m"] > 0.08
    # the pre-place stays over the rim, where it was: the lowering is the longer
    assert board["preplace_pose"][2, 3] - board["place_pose"][2, 3] == pytest.approx(0.10 + board["place_sunk_m"])
    assert board["preplace_pose"][:2, 3] == pytest.approx(board["place_pose"][:2, 3])


def test_the_object_goes_only_as_low_as_the_hand_clears_the_walls(franka):
    tcp = np.asarray(franka.tcp_pose())
    snap = _snapshot(tcp)
    rim, _ = compute_place(franka, _snapshot(tcp, depth=None), object="can", region="basket_1")
    assert rim["place_sunk_m"] == 0.0  # a solid top: set on it, as before
    limit = float(rim["place_pose"][2, 3]) - 0.045
    board, [rec] = compute_place(franka, snap, _hand_meets_the_walls_below(limit), object="can", region="basket_1")
    assert board["place_pose"][2, 3] >= limit - 1e-9
    assert board["place_pose"][2, 3] < limit + LET_DOWN_STEP_M  # the lowest clear step
    assert board["place_sunk_m"] == pytest.approx(float(rim["place_pose"][2, 3] - board["place_pose"][2, 3]))
    # nothing below the rim clear: let go at the rim, as before
    board, [rec] = compute_place(franka, snap, _hand_meets_the_walls_below(float(rim["place_pose"][2, 3])),
                                 object="can", region="basket_1")
    assert board["place_sunk_m"] == 0.0 and "sunk_m" not in rec
    assert board["place_pose"][2, 3] == pytest.approx(float(rim["place_pose"][2, 3]))


def test_a_lowering_that_leaves_the_arms_reach_is_not_sunk_to(franka):
    tcp = np.asarray(franka.tcp_pose())
    rim, _ = compute_place(franka, _snapshot(tcp, depth=None), object="can", region="basket_1")
    limit = float(rim["place_pose"][2, 3]) - 0.03

    def line(T_pre, T_place):
        if T_place[2, 3] < limit - 1e-9:
            return Blocked("lowering: no IK solution", stage="preplace", collides=False)
        return None

    board, _ = compute_place(franka, _snapshot(tcp), object="can", region="basket_1", line_blocked=line)
    assert board["place_sunk_m"] == pytest.approx(0.03, abs=1e-6)


def test_the_object_goes_only_as_low_as_the_fingers_open_clear_of_the_container(franka):
    """libero_goal task 6: let down 2 cm into the black bowl, the cream cheese's fingers opened
    against the bowl's inside, and the retreat carried the bowl off the table."""
    tcp = np.asarray(franka.tcp_pose())
    rim, _ = compute_place(franka, _snapshot(tcp, depth=None), object="can", region="basket_1")
    limit = float(rim["place_pose"][2, 3]) - 0.02

    def release(T_place):
        if T_place[2, 3] < limit - 1e-9:
            return Blocked("release collides: gripper0_leftfinger-akita_black_bowl_1_main", stage="place",
                           collides=True)
        return None

    board, _ = compute_place(franka, _snapshot(tcp), object="can", region="basket_1", release_blocked=release)
    assert board["place_sunk_m"] == pytest.approx(0.02, abs=1e-6)
    board, _ = compute_place(franka, _snapshot(tcp), object="can", region="basket_1",
                             release_blocked=lambda T: Blocked("release collides", stage="place", collides=True))
    assert board["place_sunk_m"] == 0.0  # nowhere below the rim: let go there, as before


def test_the_fingers_open_check_finds_the_container_in_the_planning_world(franka):
    """The real check, on the tabletop's own model: the hand's fingers opened fully at a pose
    where one of them stands inside a box are refused; high over it, not."""
    from types import SimpleNamespace

    from phyagentos.primitives.perception import ComputePlace

    leaf = ComputePlace("ComputePlace", object="can", region="basket_1")
    leaf.ctx = SimpleNamespace(target=franka, perceiver=None)
    assert leaf._release_blocked(np.asarray(franka.tcp_pose())) is None  # the ready pose, in the air
    from phyagentos.primitives.motion import session_checker

    checker = session_checker(leaf.ctx)
    assert checker.full_opening_m == pytest.approx(0.04)  # the Franka Hand's, from its model's ranges
    low = np.asarray(franka.tcp_pose()).copy()
    low[2, 3] = 0.0  # the fingertips at the table's top: opened there they meet it
    why = leaf._release_blocked(low)
    assert why is not None and why.stage == "place"


def test_an_object_that_may_hang_lower_in_the_hand_stops_higher(franka):
    tcp = np.asarray(franka.tcp_pose())
    snap = _snapshot(tcp)
    carried, _ = compute_place(franka, snap, object="can", region="basket_1")
    hung = _snapshot(tcp, seen_z=0.02 + 0.035)  # seen 3.5 cm lower in the hand when it closed
    board, _ = compute_place(franka, hung, object="can", region="basket_1")
    assert board["place_pose"][2, 3] == pytest.approx(float(carried["place_pose"][2, 3]) + 0.035, abs=LET_DOWN_STEP_M)


def test_a_dish_shallower_than_the_clearance_and_a_place_beside_are_not_sunk(franka):
    tcp = np.asarray(franka.tcp_pose())
    board, _ = compute_place(franka, _snapshot(tcp, depth=0.015), object="can", region="basket_1")
    assert board["place_sunk_m"] == 0.0
    board, _ = compute_place(franka, _snapshot(tcp), object="can", region="basket_1", beside="left")
    assert board["place_sunk_m"] == 0.0


def test_the_retreat_rises_as_much_further_as_the_place_was_sunk():
    move = CartesianMove("Retreat", offset=[0.0, 0.0, 0.10], at_least_m=0.04, offset_plus="place_sunk_m")
    board = {"place_sunk_m": 0.07}
    move.get = board.__getitem__
    assert move._offset() == pytest.approx([0.0, 0.0, 0.17])
    board["place_sunk_m"] = 0.0
    assert move._offset() == pytest.approx([0.0, 0.0, 0.10])
    board["place_sunk_m"] = -0.01
    with pytest.raises(Exception, match="length >= 0"):
        move._offset()
    with pytest.raises(ValueError, match="offset_plus"):
        CartesianMove("Lower", to="place_pose", offset_plus="place_sunk_m")
