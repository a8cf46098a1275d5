"""Pushing an object to a side of a landmark ("push the plate to the front of the stove":
libero_goal task 5), and the sides a landmark has as the viewer sees the table: the reader,
the LIBERO plan's node, the verifier's ``beside`` and ``ComputePush``'s start and goal."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from phyagentos.agent.criteria import SIDES, evaluate, parse_criteria
from phyagentos.agent.llm.meaning import read_request
from phyagentos.agent.llm.world import world_from_declared
from phyagentos.bench.libero import instruction_plan
from phyagentos.geometry import VIEWER_SIDES, viewer_side_xy

GOAL_OBJECTS = {"akita_black_bowl_1": "akita_black_bowl", "cream_cheese_1": "cream_cheese",
                "wine_bottle_1": "wine_bottle", "plate_1": "plate"}
GOAL_FIXTURES = {"main_table": "table", "wooden_cabinet_1": "wooden_cabinet", "flat_stove_1": "flat_stove",
                 "wine_rack_1": "wine_rack"}
WORLD = world_from_declared(list(GOAL_OBJECTS), list(GOAL_FIXTURES))


def test_the_viewers_front_is_towards_the_camera_and_the_sides_follow_its_right():
    # LIBERO's agentview camera looks along -x: its right on the table is +y, towards it is +x
    assert viewer_side_xy([0.0, 2.0], "front") == pytest.approx([1.0, 0.0])
    assert viewer_side_xy([0.0, 2.0], "back") == pytest.approx([-1.0, 0.0])
    assert viewer_side_xy([0.0, 2.0], "left") == pytest.approx([0.0, -1.0])
    assert viewer_side_xy([0.0, 2.0], "right") == pytest.approx([0.0, 1.0])
    assert SIDES == VIEWER_SIDES
    with pytest.raises(ValueError, match="left, right, front, back"):
        viewer_side_xy([0.0, 1.0], "behind")
    with pytest.raises(ValueError, match="not both 0"):
        viewer_side_xy([0.0, 0.0], "front")


@pytest.mark.parametrize("text,side", [
    ("push the plate to the front of the stove", "front"),
    ("Push the plate in front of the stove", "front"),
    ("shove the plate to the left of the stove", "left"),
    ("nudge the plate to the back of the stove", "back"),
])
def test_a_push_to_a_side_of_a_landmark_is_read_as_a_push_beside_it(text, side):
    m = read_request(text, WORLD, relations=True)
    assert not m.problems
    [it] = m.intents
    assert (it.verb, it.objects, it.destinations, it.beside) == ("push", ("plate_1",), ("flat_stove_1",), side)


@pytest.mark.parametrize("text", ["push the plate", "push the plate onto the stove"])
def test_a_push_that_names_no_side_of_a_thing_is_refused_with_the_reason(text):
    m = read_request(text, WORLD, relations=True)
    assert not m.intents and "a push goes to a side of one thing" in m.problems[0][1]


def test_a_move_to_the_front_of_a_landmark_is_a_place_beside_it_on_the_viewers_side():
    m = read_request("put the cream cheese in front of the bowl", WORLD, relations=True)
    [it] = m.intents
    assert (it.verb, it.destinations, it.beside) == ("move", ("akita_black_bowl_1",), "front")
    # "at the front on the plate" names a place on the plate, not a side of it: not read as beside
    assert not read_request("put the bowl at the front on the plate", WORLD, relations=True).intents


def test_the_libero_plan_pushes_to_the_side_and_accepts_on_beside():
    nodes, refs = instruction_plan("push the plate to the front of the stove", GOAL_OBJECTS, GOAL_FIXTURES)
    [node] = nodes
    assert node["skill"] == "push" and node["depends_on"] == []
    assert node["params"] == {"object": "plate_1", "landmark": "flat_stove_1", "side": "front"}
    assert node["accept"] == [{"beside": {"object": "plate_1", "landmark": "flat_stove_1", "side": "front"}}]
    assert refs == {}


def _scene(plate_xy, *, plate_half=0.069):
    stove = {"name": "flat_stove_1", "kind": "fixture", "position": [-0.30, 0.20, 0.92], "quat_wxyz": [1, 0, 0, 0],
             "size": [0.15, 0.095, 0.02], "attributes": {"confidence": 0.9, "position_std_m": 0.004}}
    plate = {"name": "plate_1", "kind": "object", "position": [plate_xy[0], plate_xy[1], 0.91],
             "quat_wxyz": [1, 0, 0, 0], "size": [plate_half, plate_half, 0.01],
             "attributes": {"confidence": 0.9, "position_std_m": 0.004}}
    return {"entities": [stove, plate], "relations": [], "viewer": {"right_xy": [0.0, 1.0]}}


def _beside(snapshot, side="front"):
    [c] = parse_criteria({"beside": {"object": "plate_1", "landmark": "flat_stove_1", "side": side}})
    return evaluate(c, snapshot, snapshot)


def test_beside_counts_its_reach_from_the_objects_near_face_so_a_plate_fits_in_front():
    # the stove's front edge at x = -0.15; a plate 13.8 cm across, its near face 1.5 cm beyond that edge
    assert _beside(_scene([-0.15 + 0.015 + 0.069, 0.20])).status == "satisfied"
    # its near face 6 cm beyond the edge: still next to it (its centre 12.9 cm beyond); 8 cm, the reach
    # itself: undecided within 2 sigma (LIBERO's region for this plate ends at 8.3 cm); 11 cm: across the table
    assert _beside(_scene([-0.15 + 0.06 + 0.069, 0.20])).status == "satisfied"
    assert _beside(_scene([-0.15 + 0.08 + 0.069, 0.20])).status == "unknown"
    assert _beside(_scene([-0.15 + 0.11 + 0.069, 0.20])).status == "unsatisfied"
    # across: in the middle half of the stove's front (its half width 9.5 cm), not towards its corner
    assert _beside(_scene([-0.15 + 0.03 + 0.069, 0.20 + 0.03])).status == "satisfied"
    assert _beside(_scene([-0.15 + 0.03 + 0.069, 0.20 - 0.075])).status == "unsatisfied"
    # behind the stove (away from the viewer), or off to its side: not in front of it
    assert _beside(_scene([-0.45 - 0.015 - 0.069, 0.20])).status == "unsatisfied"
    assert _beside(_scene([-0.45 - 0.015 - 0.069, 0.20]), side="back").status == "satisfied"
    assert _beside(_scene([-0.15 + 0.015 + 0.069, 0.20 + 0.15])).status == "unsatisfied"


def _compute_push(snapshot, blocked=None, way_blocked=None, tips=1.0, **params):
    from phyagentos.primitives.contact import ComputePush

    leaf = ComputePush("ComputePush", object="plate_1", **params)
    board = {"snapshot": snapshot}
    records = []
    leaf.ctx = SimpleNamespace(trace=SimpleNamespace(record=lambda kind, **f: records.append({"kind": kind, **f})),
                               target=SimpleNamespace(fingertip_friction=tips))  # LIBERO's Panda's fingertips
    leaf.get = board.__getitem__
    leaf.set = board.__setitem__
    leaf._blocked = blocked or (lambda T_pre, T_start: None)  # reach is the planner's; here the poses
    leaf._way_blocked = way_blocked or (lambda T_land, T_start, T_end, T_above: None)
    leaf.step()
    return board, records[0]


def test_compute_push_aims_the_plate_at_the_landmarks_side_and_starts_behind_its_face():
    from phyagentos.motion.grasp import FINGERTIP_BELOW_TCP_M
    from phyagentos.primitives.contact import FINGER_HALF_THICKNESS_M, PUSH_BESIDE_GAP_M

    board, record = _compute_push(_scene([0.05, -0.03]), landmark="flat_stove_1", side="front", strategy="behind", clearance_m=0.02)
    # its footprint the push's gap clear of the stove (mid the verifier's reach), centred across (nothing there)
    goal = np.array([-0.15 + 0.069 + PUSH_BESIDE_GAP_M, 0.20])
    assert record["shift_m"] == 0.0
    move = goal - [0.05, -0.03]
    d = move / np.linalg.norm(move)
    assert record["direction"] == pytest.approx(d, abs=1e-4)
    assert record["distance_m"] == pytest.approx(np.linalg.norm(move), abs=1e-4)
    start, end = board["push_start_pose"], board["push_goal_pose"]
    face = 0.069 * (abs(d[0]) + abs(d[1]))  # the plate's box along the diagonal push
    assert start[:2, 3] == pytest.approx(np.array([0.05, -0.03]) - (face + 0.02 + FINGER_HALF_THICKNESS_M) * d, abs=1e-6)
    # the closed fingertips 5 mm above the table the plate stands on (0.90), not at the plate's centre height
    assert start[2, 3] == pytest.approx(0.90 + FINGERTIP_BELOW_TCP_M + 0.005, abs=1e-9)
    # the face ends where the plate's face must be: the hand travels the gap and the distance
    assert (end[:2, 3] - start[:2, 3]) == pytest.approx((0.02 + np.linalg.norm(move)) * d, abs=1e-6)
    assert board["push_prestart_pose"][2, 3] == pytest.approx(start[2, 3] + 0.10)
    # the fingers (tcp y) across the push
    assert abs(float(start[:3, 1] @ np.array([d[0], d[1], 0.0]))) < 1e-9


def test_compute_push_takes_a_direction_and_distance_or_a_landmark_and_side_not_both():
    from phyagentos.primitives.contact import ComputePush

    with pytest.raises(ValueError, match="either direction and distance_m, or landmark and side"):
        ComputePush("p", object="plate_1")
    with pytest.raises(ValueError, match="either direction and distance_m, or landmark and side"):
        ComputePush("p", object="plate_1", direction=[1, 0], distance_m=0.1, landmark="flat_stove_1", side="front")
    with pytest.raises(ValueError, match="either direction and distance_m, or landmark and side"):
        ComputePush("p", object="plate_1", landmark="flat_stove_1")
    with pytest.raises(ValueError, match="side must be one of left, right, front, back"):
        ComputePush("p", object="plate_1", landmark="flat_stove_1", side="under")


def test_compute_push_leans_the_hand_over_the_object_when_the_upright_hand_would_collide():
    from phyagentos.primitives.contact import PUSH_LEANS_RAD

    tried = []

    def blocked(T_pre, T_start):  # the upright hand's body meets what stands behind the plate
        lean = float(np.arccos(np.clip(-T_start[2, 2], -1.0, 1.0)))
        tried.append(round(lean, 6))
        return None if lean > 0.2 else "push prestart collides: gripper-cabinet"

    board, record = _compute_push(_scene([0.05, -0.03]), blocked=blocked, landmark="flat_stove_1", side="front", strategy="behind")
    assert tried == [0.0, round(PUSH_LEANS_RAD[1], 6)] and record["lean_rad"] == PUSH_LEANS_RAD[1]
    assert record["rejected"][0]["why"].startswith("push prestart collides") and not record["edge_on"]
    d = np.array([*record["direction"], 0.0])
    start, pre = board["push_start_pose"], board["push_prestart_pose"]
    approach = start[:3, 2]  # the hand's axis, towards the fingertips: down and back from the push
    assert approach @ d == pytest.approx(-np.sin(PUSH_LEANS_RAD[1]), abs=1e-3)
    assert approach[2] == pytest.approx(-np.cos(PUSH_LEANS_RAD[1]), abs=1e-9)
    # the fingers still close across the push; the pre-start stands back along the hand's axis, over the plate
    assert abs(float(start[:3, 1] @ d)) < 1e-4  # the traced direction is rounded to 0.1 mm
    assert pre[:3, 3] - start[:3, 3] == pytest.approx(-0.10 * approach, abs=1e-9)
    # everything blocked: upright, fingers across, and the planner reports the collision
    board, upright = _compute_push(_scene([0.05, -0.03]), blocked=lambda a, b: "collides",
                                   landmark="flat_stove_1", side="front", strategy="behind")
    assert upright["lean_rad"] == 0.0 and not upright["edge_on"]
    assert len(upright["rejected"]) == 2 * 2 * len(PUSH_LEANS_RAD)  # two clearances, across and edge-on
    assert upright["clearance_m"] == 0.02
    assert abs(float(board["push_start_pose"][:3, 1] @ d)) < 1e-4


def test_compute_push_turns_the_hand_edge_on_when_no_lean_is_clear():
    from phyagentos.primitives.contact import CLOSED_FINGERS_DEPTH_M, PUSH_LEANS_RAD

    def blocked(T_pre, T_start):  # only a hand whose fingers close along the push passes
        return None if abs(float(T_start[:3, 1] @ np.array([*d, 0.0]))) > 0.99 else "push start collides: hand-cabinet"

    _, first = _compute_push(_scene([0.05, -0.03]), blocked=lambda a, b: None, landmark="flat_stove_1", side="front", strategy="behind")
    d = np.asarray(first["direction"], dtype=float)
    d /= np.linalg.norm(d)
    board, record = _compute_push(_scene([0.05, -0.03]), blocked=blocked, landmark="flat_stove_1", side="front", strategy="behind")
    assert record["edge_on"] and record["lean_rad"] == 0.0
    assert [r["lean_rad"] for r in record["rejected"]] == list(PUSH_LEANS_RAD)
    start, pre, end = board["push_start_pose"], board["push_prestart_pose"], board["push_goal_pose"]
    assert start[:3, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-9)  # upright
    # the closed fingers' outer face stands the clearance behind the plate's face
    face = 0.069 * (abs(d[0]) + abs(d[1]))
    assert start[:2, 3] == pytest.approx(np.array([0.05, -0.03]) - (face + 0.02 + CLOSED_FINGERS_DEPTH_M) * d,
                                         abs=2e-4)
    assert pre[:3, 3] == pytest.approx(start[:3, 3] + [0.0, 0.0, 0.10], abs=1e-9)
    assert (end[:2, 3] - start[:2, 3]) @ d == pytest.approx(0.02 + record["distance_m"], abs=2e-4)  # rounded traces


def test_compute_push_comes_closer_to_the_object_when_no_start_at_the_skills_clearance_is_clear():
    from phyagentos.primitives.contact import FINGER_HALF_THICKNESS_M, PUSH_LEANS_RAD, TIGHT_CLEARANCE_M

    plate = np.array([0.05, -0.03])
    face = {}

    def blocked(T_pre, T_start):  # the cabinet stands 3 cm behind the plate's face: only a close start fits
        gap = float(np.linalg.norm(T_start[:2, 3] - plate)) - face["plate"]
        return None if gap < 0.02 else f"push start collides: finger-cabinet ({gap:.3f} m)"

    _, first = _compute_push(_scene(list(plate)), landmark="flat_stove_1", side="front", strategy="behind")
    d = np.asarray(first["direction"], dtype=float)
    face["plate"] = 0.069 * (abs(d[0]) + abs(d[1])) / np.linalg.norm(d)
    board, record = _compute_push(_scene(list(plate)), blocked=blocked, landmark="flat_stove_1", side="front", strategy="behind")
    assert record["clearance_m"] == TIGHT_CLEARANCE_M and not record["edge_on"] and record["lean_rad"] == 0.0
    assert len(record["rejected"]) == 2 * len(PUSH_LEANS_RAD)  # every start at the skill's 2 cm first
    start, end = board["push_start_pose"], board["push_goal_pose"]
    gap = float(np.linalg.norm(start[:2, 3] - plate)) - face["plate"]
    assert gap == pytest.approx(TIGHT_CLEARANCE_M + FINGER_HALF_THICKNESS_M, abs=3e-4)
    # the hand still ends where the plate's face must be: it travels the smaller gap
    assert float(np.linalg.norm(end[:2, 3] - start[:2, 3])) == pytest.approx(
        TIGHT_CLEARANCE_M + record["distance_m"], abs=2e-4)


@pytest.mark.parametrize("edge_on", [False, True])
def test_a_leaning_push_puts_the_hands_body_over_the_object_whichever_way_the_fingers_close(edge_on):
    from phyagentos.primitives.contact import _push_rotation

    d = np.array([-0.6, 0.8, 0.0])
    R = _push_rotation(float(np.arctan2(d[1], d[0])), d, edge_on=edge_on, lean_rad=0.6)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) == pytest.approx(1.0)
    assert R[:, 2] @ d == pytest.approx(-np.sin(0.6))  # the axis to the fingertips points back from the push
    assert R[2, 2] == pytest.approx(-np.cos(0.6))
    closing = R[:, 1]  # across the push; edge-on, along it (tilted with the lean)
    assert abs(closing @ d) == pytest.approx(np.cos(0.6) if edge_on else 0.0, abs=1e-9)


def test_free_shift_moves_the_aim_across_to_the_nearest_spot_clear_of_what_stands_there():
    from phyagentos.primitives.contact import free_shift

    across = np.array([0.0, 1.0])
    # nothing in the way: the aim stays where it is
    assert free_shift([0.0, 0.0], across, 0.05, [], max_shift_m=0.1) == 0.0
    # a 2 cm disc 6 cm off to the right: a 5 cm disc clears it (with the 1 cm margin) 2 cm to the left
    assert free_shift([0.0, 0.0], across, 0.05, [([0.0, 0.06], 0.02)], max_shift_m=0.1) == pytest.approx(-0.02)
    # dead ahead: the positive side is tried first at each size
    assert free_shift([0.0, 0.0], across, 0.05, [([0.0, 0.0], 0.02)], max_shift_m=0.1) == pytest.approx(0.08)
    # no shift within reach clears it: as far from it as the reach allows (the positive side of equals)
    assert free_shift([0.0, 0.0], across, 0.05, [([0.0, 0.0], 0.02)], max_shift_m=0.05) == pytest.approx(0.05)
    assert free_shift([0.0, 0.0], across, 0.05, [([0.0, 0.01], 0.02)], max_shift_m=0.05) == pytest.approx(-0.05)


def test_compute_push_aims_the_plate_clear_of_a_cream_cheese_beside_the_stove():
    from phyagentos.primitives.contact import FREE_MARGIN_M, PUSH_BESIDE_GAP_M

    scene = _scene([0.05, -0.03])
    scene["entities"][1]["attributes"]["shape"] = "cylinder"  # a plate is round: its radius, not a box's diagonal
    # libero_goal's cream cheese stands in front of the stove, to the viewer's left of its centre
    cheese = {"name": "cream_cheese_1", "kind": "object", "position": [-0.05, 0.10, 0.93],
              "quat_wxyz": [1, 0, 0, 0], "size": [0.02, 0.03, 0.02], "attributes": {"confidence": 0.9}}
    scene["entities"].append(cheese)
    board, record = _compute_push(scene, landmark="flat_stove_1", side="front")
    goal_x = -0.15 + 0.069 + PUSH_BESIDE_GAP_M
    shift = record["shift_m"]
    assert shift > 0.0  # towards the viewer's right (+y), away from the cheese
    aim = np.array([goal_x, 0.20 + shift])
    clear = 0.069 + np.hypot(0.02, 0.03) + FREE_MARGIN_M
    assert np.linalg.norm(aim - [-0.05, 0.10]) >= clear - 1e-9
    assert np.linalg.norm(aim - [0.0, 0.005] - [-0.05, 0.10]) < clear  # the nearest such step
    move = aim - [0.05, -0.03]
    assert record["direction"] == pytest.approx(move / np.linalg.norm(move), abs=1e-4)
    # still in front of the stove: within a quarter of its half width of its centre across, the middle
    # of what the verifier accepts there
    assert shift <= 0.25 * 0.095
    # a fixture is the landmark's world, not a thing on the table: no shift round it
    cheese["kind"] = "fixture"
    assert _compute_push(scene, landmark="flat_stove_1", side="front")[1]["shift_m"] == 0.0


def test_a_low_object_is_pressed_from_above_at_its_centre_and_dragged_to_the_aim():
    from phyagentos.motion.grasp import FINGERTIP_BELOW_TCP_M
    from phyagentos.primitives.contact import PRESS_CONTACT_N, PRESS_DEPTH_M, PRESS_START_ABOVE_M

    ways = []
    board, record = _compute_push(_scene([0.05, -0.03]), landmark="flat_stove_1", side="front",
                                  way_blocked=lambda *poses: ways.append(poses))
    # the landing is checked as low as the press may go (the fingertips on the plate's bottom, 0.90), so a
    # neighbour as high as the hand's body is met there; the drag at the start's height, over the plate
    [(land, start, end, above)] = ways
    assert land[2, 3] == pytest.approx(0.90 + FINGERTIP_BELOW_TCP_M + PRESS_DEPTH_M, abs=1e-9)
    assert land[:2, 3] == pytest.approx(start[:2, 3]) and start[2, 3] == end[2, 3] and above[2, 3] > end[2, 3] + 0.09
    assert record["press"] and record["rejected"] == []
    d = np.array([*record["direction"], 0.0])
    start, pre, end = board["push_start_pose"], board["push_prestart_pose"], board["push_goal_pose"]
    # over the plate's centre, the fingertips 1 cm above its top (0.92), the hand upright
    assert start[:3, 3] == pytest.approx([0.05, -0.03, 0.92 + PRESS_START_ABOVE_M + FINGERTIP_BELOW_TCP_M], abs=1e-9)
    assert start[:3, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-9)
    assert abs(float(start[:3, 1] @ d)) == pytest.approx(1.0, abs=1e-4)  # closing axis along the way: narrow across
    assert pre[:3, 3] == pytest.approx(start[:3, 3] + [0.0, 0.0, 0.10], abs=1e-9)
    # the plate moves with the hand: its centre ends where the hand does
    assert end[:2, 3] - start[:2, 3] == pytest.approx(record["distance_m"] * d[:2], abs=2e-4)
    press = board["push_press"]
    assert press["contact_n"] == PRESS_CONTACT_N and press["depth_m"] == PRESS_DEPTH_M and press["object"] == "plate_1"
    assert press["descent_m"] == pytest.approx(0.02 + PRESS_START_ABOVE_M, abs=1e-4)  # down to its bottom at most


def test_a_tall_object_or_fingertips_that_may_not_grip_push_from_behind_and_a_press_only_on_request():
    board, record = _compute_push(_scene([0.05, -0.03]), tips=None, landmark="flat_stove_1", side="front")
    assert not record["press"] and board["push_press"] is None  # a target that declares no fingertip friction
    board, record = _compute_push(_scene([0.05, -0.03]), tips=0.5, landmark="flat_stove_1", side="front")
    assert not record["press"]
    scene = _scene([0.05, -0.03])
    scene["entities"][1]["size"] = [0.03, 0.03, 0.05]  # 10 cm high: a press could tip it
    board, record = _compute_push(scene, landmark="flat_stove_1", side="front")
    assert not record["press"] and board["push_press"] is None
    board, record = _compute_push(scene, landmark="flat_stove_1", side="front", strategy="above")
    assert record["press"] and board["push_press"] is not None
    board, record = _compute_push(_scene([0.05, -0.03]), landmark="flat_stove_1", side="front", strategy="behind")
    assert not record["press"] and board["push_press"] is None


def test_a_press_whose_end_the_arm_cannot_reach_gives_way_to_a_start_behind():
    from phyagentos.primitives.contact import PUSH_LEANS_RAD

    ends = []

    def way_blocked(T_land, T_start, T_end, T_above):
        ends.append(T_end[:3, 3].copy())
        return "press end: IK did not converge"

    board, record = _compute_push(_scene([0.05, -0.03]), way_blocked=way_blocked, landmark="flat_stove_1",
                                  side="front")
    assert not record["press"] and record["lean_rad"] == 0.0 and board["push_press"] is None
    assert [r["press"] for r in record["rejected"]] == [True] * 8  # along, half way round, then across
    assert all(r["why"] == "press end: IK did not converge" for r in record["rejected"])
    assert len(ends) == 8 and np.allclose(ends[0], ends[7])
    # nothing clear at all: the first press, and the planner says why
    board, record = _compute_push(_scene([0.05, -0.03]), blocked=lambda a, b: "collides", landmark="flat_stove_1",
                                  side="front")
    assert record["press"] and len(record["rejected"]) == 8 + 2 * 2 * len(PUSH_LEANS_RAD)


def test_a_push_strategy_is_one_of_the_three():
    from phyagentos.primitives.contact import ComputePush

    with pytest.raises(ValueError, match="strategy must be one of auto, behind, above"):
        ComputePush("p", object="plate_1", landmark="flat_stove_1", side="front", strategy="sideways")


def test_a_press_whose_pre_start_meets_a_fixture_above_comes_down_from_lower():
    def blocked(T_pre, T_start):  # the hand turned along the way meets the cabinet's top 10 cm up, not 6
        return "push prestart collides: hand-cabinet_top" if T_pre[2, 3] - T_start[2, 3] > 0.07 else None

    board, record = _compute_push(_scene([0.05, -0.03]), blocked=blocked, landmark="flat_stove_1", side="front")
    assert record["press"] and record["approach_m"] == 0.06 and record["turn_rad"] == pytest.approx(np.pi / 2, abs=1e-4)
    assert [r["approach_m"] for r in record["rejected"]] == [0.10]
    start, pre = board["push_start_pose"], board["push_prestart_pose"]
    assert pre[:3, 3] == pytest.approx(start[:3, 3] + [0.0, 0.0, 0.06], abs=1e-9)

    # a start that is itself blocked is not tried again from lower: the next turn is
    def start_blocked(T_pre, T_start):
        return "push start collides: finger-bowl" if abs(float(T_start[:3, 1] @ [0.0, 1.0, 0.0])) > 0.9 else None

    _, record = _compute_push(_scene([0.05, -0.03]), blocked=start_blocked, landmark="flat_stove_1", side="front")
    assert all(r["approach_m"] == 0.10 for r in record["rejected"])


# libero_goal's looks as the bench measures them on generated scenes (libero/descriptors.yaml,
# generated_clutter_v3): the plate 13.9 cm across and flat, the bowl taken by its rim
GOAL_LOOKS = {"plate": {"size_m": [0.1386, 0.1384, 0.0186], "shape": "cylinder"},
              "akita_black_bowl": {"size_m": [0.113, 0.113, 0.0506], "shape": "cylinder"},
              "cream_cheese": {"size_m": [0.0846, 0.0452, 0.0198], "shape": "box"},
              "wine_bottle": {"size_m": [0.0164, 0.0164, 0.1568], "shape": "cylinder"}}


def test_only_a_thing_no_grasp_takes_is_untakeable_by_its_measured_look():
    from phyagentos.bench.libero import untakeable_objects

    assert untakeable_objects(GOAL_OBJECTS, GOAL_LOOKS) == {"plate_1"}
    # a category with no measured size is not guessed at
    assert untakeable_objects(GOAL_OBJECTS, {"plate": {"colour": [0.9, 0.9, 0.9]}}) == frozenset()


def test_a_move_beside_a_landmark_of_a_thing_the_hand_cannot_take_is_planned_as_the_push():
    push, _ = instruction_plan("push the plate to the front of the stove", GOAL_OBJECTS, GOAL_FIXTURES)
    # libero_goal_lan task 5's wording: a move, planned as the push once the plate's look is known
    moved, _ = instruction_plan("move the plate to the stove's front", GOAL_OBJECTS, GOAL_FIXTURES,
                                untakeable={"plate_1"})
    assert moved == push
    # without that knowledge (or for a thing the hand takes) it stays a pick and a place beside
    carried, _ = instruction_plan("move the plate to the stove's front", GOAL_OBJECTS, GOAL_FIXTURES)
    assert [n["skill"] for n in carried] == ["pick", "place"] and carried[1]["params"]["beside"] == "front"
    cheese, _ = instruction_plan("move the cream cheese to the stove's front", GOAL_OBJECTS, GOAL_FIXTURES,
                                 untakeable={"plate_1"})
    assert [n["skill"] for n in cheese] == ["pick", "place"]
    # a move onto the thing (not beside it) is never turned into a push: no push sets a thing on another
    onto, _ = instruction_plan("put the plate on the stove", GOAL_OBJECTS, GOAL_FIXTURES, untakeable={"plate_1"})
    assert [n["skill"] for n in onto] == ["pick", "place"]


def test_the_libero_bench_plans_libero_goal_lan_task_5_as_a_push_from_the_measured_looks(tmp_path):
    pytest.importorskip("libero")
    import yaml

    from phyagentos.bench import libero as bench
    from phyagentos.targets.libero import parse_bddl, resolve_task

    # the looks given, as a workspace that measured them before holds them: nothing is built
    root = tmp_path / "libero"
    root.mkdir()
    (root / "descriptors.yaml").write_text(yaml.safe_dump(
        {**GOAL_LOOKS, "_method": bench._LOOKS_METHOD, "_measured_tasks": ["libero_goal_lan/5"]}))
    world = bench._fixture_world(parse_bddl(resolve_task("libero_goal_lan", 5).bddl_path))
    (root / "fixture_looks.yaml").write_text(yaml.safe_dump(
        {"_method": bench._FIXTURE_LOOKS_METHOD, "worlds": {world: {"measured_as": "libero_goal/5", "looks": {}}}}))
    suite_path, ids, _ = bench.prepare_libero_suite("libero_goal_lan", tmp_path, tasks=("5",), seeds=(0,))
    graph = yaml.safe_load((suite_path.parent / "t5.yaml").read_text())
    [node] = graph["nodes"]
    assert ids == ("t5",) and node["skill"] == "push"
    assert node["params"] | {"object": "plate_1", "landmark": "flat_stove_1", "side": "front"} == node["params"]
