"""Rim grasps of a bowl wider than the gripper (issue 28, libero_spatial).

Geometry of :func:`phyagentos.motion.rim_grasp.rim_grasp_candidates` (the fingers straddle
the wall, the tcp's height against the rim, the order of the yaws), the rule that picks a
rim grasp (:func:`rim_graspable`), and :class:`~phyagentos.primitives.perception.ComputeGrasp`
on a Franka model: a bowl is taken by its rim, a wide box is still refused as before, and
the close expects the wall, not the diameter.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from phyagentos.errors import IKError
from phyagentos.motion.grasp import (
    FINGERTIP_BELOW_TCP_M,
    PAD_DEPTH_ABOVE_TCP_M,
    GraspPlan,
    hand_yaw,
    slide_offsets,
    top_down_rotation,
    turn_offsets,
)
from phyagentos.motion.rim_grasp import (
    DEFAULT_HANDLED_WALL_M,
    DEFAULT_RIM_WALL_M,
    PARTLY_SEEN_RIM_ANGLE_RAD,
    RIM_GRIP_DEPTH_M,
    near_long_axis,
    near_short_axis,
    open_container,
    partly_seen_rim_graspable,
    rim_grasp_candidates,
    rim_graspable,
)

# the perceived akita bowl of libero_spatial (bench descriptors, generated scenes): 11.24 cm
# across, 5.04 cm tall
HALF = (0.0562, 0.0562, 0.0252)


def bowl_at(x=0.5, y=0.0, z=0.0252):
    T = np.eye(4)
    T[:3, 3] = [x, y, z]
    return T


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def test_the_fingers_straddle_the_wall_at_every_rim_point():
    T = bowl_at()
    plans = rim_grasp_candidates(T, HALF)
    assert len(plans) == 16
    for p in plans:
        G = p.grasp
        assert np.allclose(G[:3, 2], [0, 0, -1])  # top-down
        radial = G[:2, 3] - T[:2, 3]
        r = float(np.linalg.norm(radial))
        assert r == pytest.approx(HALF[0] - DEFAULT_RIM_WALL_M / 2, abs=1e-9)  # over the middle of the wall
        u = radial / r
        assert abs(float(G[:2, 1] @ u)) == pytest.approx(1.0, abs=1e-9)  # the fingers close radially
        # opened just beyond the wall, one finger is inside the bowl, the other outside
        o = p.width_m / 2 + 0.0005
        fingers = [G[:2, 3] + s * o * G[:2, 1] for s in (1.0, -1.0)]
        radii = sorted(float(np.linalg.norm(f - T[:2, 3])) for f in fingers)
        assert radii[0] < HALF[0] - DEFAULT_RIM_WALL_M and radii[1] > HALF[0]
        assert p.width_m == DEFAULT_RIM_WALL_M  # the wall, not the 11 cm diameter
        assert np.allclose(p.pregrasp[:3, :3], G[:3, :3]) and p.pregrasp[2, 3] == pytest.approx(G[2, 3] + 0.10)


def test_the_tcp_closes_below_the_rim_with_the_pads_over_it_and_the_tips_off_the_table():
    T = bowl_at(z=0.0252)
    top = 0.0504
    for p in rim_grasp_candidates(T, HALF, support_z_m=0.0):
        z = p.grasp[2, 3]
        assert z == pytest.approx(top - RIM_GRIP_DEPTH_M)
        assert z + PAD_DEPTH_ABOVE_TCP_M > top  # the rim is between the pads, below the finger base
        assert z - FINGERTIP_BELOW_TCP_M > 0.0  # the outer fingertip stays above the table
    # a shallow dish: raised so the fingertips keep clear of the support
    shallow = rim_grasp_candidates(bowl_at(z=0.01), (0.06, 0.06, 0.01), support_z_m=0.0)
    assert shallow[0].grasp[2, 3] == pytest.approx(FINGERTIP_BELOW_TCP_M + 0.004)


def test_rim_points_come_nearest_the_current_hand_yaw_first():
    T = bowl_at()
    yaw0 = 0.3
    plans = rim_grasp_candidates(T, HALF, current_yaw_rad=yaw0)
    turns = [round(abs(_wrap(p.yaw_rad - yaw0)), 6) for p in plans]
    assert turns[0] == 0.0 and turns[1] == 0.0
    assert turns == sorted(turns)
    assert max(turns) <= math.pi / 2 + 1e-9  # the hand is symmetric: never more than a quarter turn
    # the two points reached without turning lie along the hand's finger axis, on either side
    d0 = plans[0].grasp[:2, 3] - T[:2, 3]
    d1 = plans[1].grasp[:2, 3] - T[:2, 3]
    assert np.allclose(d0, -d1)
    # of those two, the one nearer the preferred point first
    near = T[:2, 3] + 0.2 * np.array([math.sin(yaw0), -math.cos(yaw0)])
    far = T[:2, 3] - 0.2 * np.array([math.sin(yaw0), -math.cos(yaw0)])
    for pref in (near, far):
        first = rim_grasp_candidates(T, HALF, current_yaw_rad=yaw0, prefer_xy=pref)[0]
        others = rim_grasp_candidates(T, HALF, current_yaw_rad=yaw0, prefer_xy=pref)[1]
        assert np.linalg.norm(first.grasp[:2, 3] - pref) < np.linalg.norm(others.grasp[:2, 3] - pref)


def test_a_point_whose_open_outer_finger_lands_on_a_neighbour_is_tried_last():
    T = bowl_at()
    plain = rim_grasp_candidates(T, HALF)
    # a ramekin right beside the first point's outer finger
    u = (plain[0].grasp[:2, 3] - T[:2, 3]) / np.linalg.norm(plain[0].grasp[:2, 3] - T[:2, 3])
    ramekin = (T[:2, 3] + 0.11 * u, 0.045, 0.045)
    plans = rim_grasp_candidates(T, HALF, keep_clear=[ramekin])
    assert not np.allclose(plans[0].grasp, plain[0].grasp)
    assert any(np.allclose(p.grasp, plain[0].grasp) for p in plans[-4:])


def test_joint_7_at_its_limit_keeps_only_yaws_it_can_turn_to():
    lim = 2.8973
    plans = rim_grasp_candidates(bowl_at(), HALF, current_yaw_rad=0.0, current_q7_rad=lim - 0.06)
    for p in plans:
        q7 = (lim - 0.06) - _wrap(p.yaw_rad - 0.0)
        assert -lim + 0.05 <= q7 <= lim - 0.05


@pytest.mark.parametrize("half,wall,why", [
    ((0.0562, 0.0562, 0.0252), 0.06, "less than the radius"),
    ((0.0562, 0.0562, 0.0252), 0.0, "must be > 0"),
    ((0.0562, 0.0562, -0.01), 0.003, "must be positive"),
])
def test_an_impossible_rim_grasp_says_why(half, wall, why):
    with pytest.raises(IKError, match="no rim grasp") as exc:
        rim_grasp_candidates(bowl_at(), half, wall_m=wall)
    assert why in str(exc.value)


def test_a_tipped_bowl_is_refused():
    T = bowl_at()
    c, s = math.cos(0.6), math.sin(0.6)
    T[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    with pytest.raises(IKError, match="not upright"):
        rim_grasp_candidates(T, HALF)


def test_only_a_round_open_container_too_wide_to_take_across_is_taken_by_its_rim():
    assert rim_graspable("akita_black_bowl", "cylinder", HALF)
    assert rim_graspable("bowl", "box", (0.056, 0.052, 0.025))  # seen as a box, still round enough
    assert not rim_graspable("akita_black_bowl", "cylinder", (0.035, 0.035, 0.025))  # fits across: taken across
    assert not rim_graspable("cookies", "box", (0.057, 0.057, 0.01))  # not a container
    assert not rim_graspable(None, "cylinder", HALF)  # no category: nothing says it is open
    assert not rim_graspable("bowl", "box", (0.06, 0.03, 0.02))  # not round
    assert not rim_graspable("bowl", "cylinder", (0.06, 0.06, 0.08))  # taller than wide: no dish
    assert not rim_graspable("bowl", "sphere", HALF)
    assert not rim_graspable("bowling_pin", "cylinder", HALF)  # a word of the class, not a prefix
    assert open_container("akita_black_bowl", "cylinder", (0.035, 0.035, 0.025))


# --------------------------------------------------------------------- ComputeGrasp on a Franka


@pytest.fixture(scope="module")
def franka():
    from phyagentos.targets import MuJoCoTarget
    from phyagentos.targets.scene import SceneSpec

    t = MuJoCoTarget("rim", SceneSpec.default(), seed=0)
    yield t
    t.close()


def _run_compute_grasp(target, entity, board=None, **params):
    from phyagentos.primitives.base import PrimitiveFailure
    from phyagentos.primitives.perception import ComputeGrasp

    leaf = ComputeGrasp("ComputeGrasp", object=entity["name"], **params)
    board = {"snapshot": {"entities": [entity]}} if board is None else board
    records = []
    leaf.ctx = SimpleNamespace(target=target, perceiver=None,
                               trace=SimpleNamespace(record=lambda kind, **f: records.append({"kind": kind, **f})))

    def get(key):
        if key not in board:
            raise PrimitiveFailure("skill.blackboard", f"blackboard key {key!r} was never written")
        return board[key]

    leaf.get = get
    leaf.set = board.__setitem__
    leaf.step()
    return board, records


def _entity(name, cls, shape, half, xy=(0.45, -0.25)):  # the default scene: wall at y 0.03, cube at (0.5, -0.2)
    return {"name": name, "kind": "object", "position": [xy[0], xy[1], half[2]], "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "size": list(half), "attributes": {"shape": shape, "class": cls, "confidence": 0.9}}


def test_compute_grasp_takes_a_bowl_by_its_rim_and_the_close_expects_the_wall(franka):
    ent = _entity("bowl_1", "akita_black_bowl", "cylinder", HALF)
    board, records = _run_compute_grasp(franka, ent)
    G = board["grasp_pose"]
    r = float(np.hypot(G[0, 3] - 0.45, G[1, 3] + 0.25))
    assert r == pytest.approx(HALF[0] - DEFAULT_RIM_WALL_M / 2, abs=1e-6)
    [rec] = records
    assert rec["grasp_kind"] == "rim" and rec["wall_m"] == DEFAULT_RIM_WALL_M
    # the hand turns as little as it can
    assert abs(_wrap(hand_yaw(G) - hand_yaw(franka.tcp_pose()))) < 1e-6
    planned = franka.runtime_notes["planned_grasp"]
    assert planned == {"object": "bowl_1", "width_m": DEFAULT_RIM_WALL_M, "kind": "rim", "preshape_m": None}
    assert board["look_closer"] is False  # seen whole: no second look asked for
    # a skill parameter overrides the assumed wall
    _run_compute_grasp(franka, ent, rim_wall_m=0.005)
    assert franka.runtime_notes["planned_grasp"]["width_m"] == 0.005


def test_a_recomputed_rim_grasp_keeps_the_rim_point_already_chosen(franka):
    ent = _entity("bowl_1", "akita_black_bowl", "cylinder", HALF)
    board, _ = _run_compute_grasp(franka, ent, candidate=1)
    first = board["grasp_pose"].copy()
    # re-observed from the pre-grasp, 4 mm off: the same side, refined, not candidate 1 again
    ent["position"][0] += 0.004
    board, records = _run_compute_grasp(franka, ent, board=board, candidate=1)
    assert np.linalg.norm(board["grasp_pose"][:3, 3] - first[:3, 3]) < 0.01
    assert records[0]["rim_point"] == 0


def test_compute_grasp_still_refuses_a_box_too_wide_for_the_fingers(franka):
    ent = _entity("cookies_1", "cookies", "box", (0.057, 0.057, 0.01))
    with pytest.raises(IKError, match=r"box is 11\.4 cm wide across the fingers; the gripper takes 7\.6 cm at most"):
        _run_compute_grasp(franka, ent)


def test_a_bowl_out_of_reach_is_refused_listing_each_rim_point(franka):
    ent = _entity("bowl_1", "akita_black_bowl", "cylinder", HALF, xy=(2.5, 0.0))
    with pytest.raises(IKError, match="no rim grasp of 'bowl_1' is reachable") as exc:
        _run_compute_grasp(franka, ent)
    assert str(exc.value).count("rim point") == 16


def test_the_grasp_check_expects_the_wall_not_the_diameter():
    from phyagentos.primitives.grasp_sense import MIN_OPENING_M, holding_problem, min_opening_m

    assert min_opening_m(None) == MIN_OPENING_M and min_opening_m(0.04) == MIN_OPENING_M
    assert min_opening_m(DEFAULT_RIM_WALL_M) == pytest.approx(0.00075)
    notes = {"grasp": {"object": "bowl_1", "width_m": DEFAULT_RIM_WALL_M}}
    target = SimpleNamespace(runtime_notes=notes, sim_time=0.0, wrist_external_force_n=lambda: None,
                             unloaded_wrist_force_n=lambda: None)

    def p(opening, effort=4.0):
        return SimpleNamespace(gripper_opening_m=opening, gripper_effort_n=effort, stamp_s=0.0, wrist_force_n=None)

    assert holding_problem(target, p(0.0015), expected="bowl_1") is None  # 3 mm wall: 1.5 mm per finger
    assert holding_problem(target, p(0.0042), expected="bowl_1") is None  # the leaning wall: 4.2 mm (LIBERO)
    assert "nothing between them" in holding_problem(target, p(0.0003), expected="bowl_1")
    # the fingers stopped 3 cm apart: that is the bowl's side, or something else, not its wall
    assert "wider than the object" in holding_problem(target, p(0.03), expected="bowl_1")


def test_an_across_grasp_the_arm_cannot_reach_clear_gives_way_to_the_next_candidate(franka, monkeypatch):
    """A pre-grasp whose forearm would pass through a neighbouring bottle (LIBERO-10's ketchup
    beside the soup: ``goal_in_collision`` on the first pick of 4 of 6 episodes) is skipped for
    the next candidate the arm reaches clear; when none is clear, the asked candidate stays."""
    import phyagentos.primitives.perception as perception

    ent = _entity("can_1", "alphabet_soup", "box", (0.03, 0.02, 0.04))
    blocked = {"first": True}

    def unusable(target, plan, checks):  # the first candidate asked for collides, the rest are clear
        if blocked["first"]:
            blocked["first"] = False
            return "pre-grasp collides: ketchup_1_main-robot0_link5"
        return None

    monkeypatch.setattr(perception, "_unusable", unusable)
    board, records = _run_compute_grasp(franka, ent)
    assert records[0]["candidate_used"] == 1 and "ketchup" in records[0]["candidates_refused"][0]
    first = board["grasp_pose"].copy()
    monkeypatch.setattr(perception, "_unusable", lambda target, plan, checks: "pre-grasp collides: wall")
    board, records = _run_compute_grasp(franka, ent)
    refused = records[0]["candidates_refused"]
    # 2 candidates x 2 heights centred, then slid 1.5 cm either way along the 6 cm side (2.5 cm would take
    # a pad off the box), then turned 15 and 30 degrees either way (the 4 x 6 cm box still fits the stroke)
    assert "candidate_used" not in records[0] and len(refused) == 4 + 8 + 16
    assert sum(" slid +1.5 cm " in r for r in refused) == 4 and not any("2.5 cm" in r for r in refused)
    assert sum(" turned -30 deg " in r for r in refused) == 4
    assert not np.allclose(board["grasp_pose"], first)  # candidate 0 again, as asked
    monkeypatch.undo()
    _, records = _run_compute_grasp(franka, ent)  # nothing in the way in the default scene
    assert "candidates_refused" not in records[0]


def test_when_no_grasp_is_clear_the_first_refused_only_at_its_grasp_is_taken_not_a_blocked_pre_grasp(
        franka, monkeypatch):
    """A flat cream cheese box beside a milk carton (LIBERO-10 task 1 init 4): every pre-grasp
    from 10 cm meets the carton, every grasp from 15 cm puts the fingertips in the table. The
    planner cannot reach a blocked pre-grasp at all (``goal_in_collision``, a whole attempt
    spent); a pre-grasp it reaches, whose straight approach stops on the table, is taken
    instead: the first such candidate in the order they were tried, traced ``fallback``."""
    import phyagentos.primitives.perception as perception
    from phyagentos.primitives.perception import Blocked

    ent = _entity("cream_cheese_1", "cream_cheese", "box", (0.042, 0.022, 0.016))
    low = _run_compute_grasp(franka, ent)[0]["pregrasp_pose"].copy()

    def unusable(ctx, obj, plan):
        if plan.pregrasp[2, 3] < low[2, 3] + 0.01:  # from 10 cm: the carton at the pre-grasp
            return Blocked("pre-grasp collides: gripper0_rightfinger-milk_1_main", stage="pre-grasp", collides=True)
        return Blocked("grasp collides: gripper0_leftfinger-living_room_table_col", stage="grasp", collides=True)

    monkeypatch.setattr(perception, "_unusable", unusable)
    board, records = _run_compute_grasp(franka, ent)
    [rec] = records
    assert rec["candidate_used"] == 0 and rec["approach_height_m"] == pytest.approx(0.15)
    assert rec["fallback"].startswith("candidate 0 from 0.15 m: grasp collides")
    assert rec["candidates_refused"][0].startswith("candidate 0 from 0.10 m: pre-grasp collides")
    assert board["pregrasp_pose"][2, 3] == pytest.approx(low[2, 3] + 0.05)
    # every candidate blocked before its grasp: the candidate asked for, as before (the planner says why)
    monkeypatch.setattr(perception, "_unusable", lambda ctx, obj, plan: Blocked(
        "pre-grasp collides: gripper0_rightfinger-milk_1_main", stage="pre-grasp", collides=True))
    board, records = _run_compute_grasp(franka, ent)
    assert "candidate_used" not in records[0] and "fallback" not in records[0]
    np.testing.assert_allclose(board["pregrasp_pose"], low, atol=1e-9)


def test_when_no_centred_grasp_is_clear_the_grasp_slides_along_the_side_it_holds(franka, monkeypatch):
    """A carton beside a cream cheese box along the closing direction meets the hand: a grasp slid
    along the box's long side, both pads still on it, clears it; a re-computed grasp keeps the slide."""
    import phyagentos.primitives.perception as perception

    ent = _entity("cream_cheese_1", "cream_cheese", "box", (0.042, 0.022, 0.016))
    centred = _run_compute_grasp(franka, ent)[0]["grasp_pose"].copy()

    def unusable(ctx, obj, plan):  # only a grasp 2.5 cm to one side of the centre is clear
        x = plan.grasp[:3, 0]
        along = float(np.dot(plan.grasp[:3, 3] - centred[:3, 3], x))
        return None if along < -0.02 else "pre-grasp collides: gripper0_right_gripper-milk_1_main"

    monkeypatch.setattr(perception, "_unusable", unusable)
    board, records = _run_compute_grasp(franka, ent)
    [rec] = records
    assert rec["slid_m"] == pytest.approx(-0.025)
    G = board["grasp_pose"]
    assert float(np.dot(G[:3, 3] - centred[:3, 3], G[:3, 0])) == pytest.approx(-0.025, abs=1e-9)
    assert G[2, 3] == pytest.approx(centred[2, 3]) and hand_yaw(G) == pytest.approx(hand_yaw(centred))
    # re-observed from that pre-grasp: the refinement keeps the slide
    board, records = _run_compute_grasp(franka, ent, board=board)
    assert records[0]["slid_m"] == pytest.approx(-0.025)
    # a box too short for the pads to slide on is never slid
    assert slide_offsets(GraspPlan(G, G, 0.0, 0.04), np.eye(4), (0.012, 0.012, 0.02)) == ()


def test_when_neither_a_centred_nor_a_slid_grasp_is_clear_the_hand_turns_while_the_box_still_fits(
        franka, monkeypatch):
    """A basket beside a butter box along the closing direction meets the 20 cm hand whether the
    grasp is centred or slid along the box (LIBERO-10 task 1, generated scene 506): turned about
    the vertical the hand's end swings away while the box still fits the fingers' stroke; a
    re-computed grasp keeps the turn; a box that would not fit turned is never turned."""
    import phyagentos.primitives.perception as perception

    ent = _entity("butter_1", "butter", "box", (0.0393, 0.0207, 0.0151))
    centred = _run_compute_grasp(franka, ent)[0]["grasp_pose"].copy()

    def unusable(ctx, obj, plan):  # clear only with the hand turned 25 degrees or more
        turn = abs((hand_yaw(plan.grasp) - hand_yaw(centred) + np.pi / 2) % np.pi - np.pi / 2)
        return None if turn > np.radians(25) else "pre-grasp collides: basket_1_main-gripper0_right_gripper"

    monkeypatch.setattr(perception, "_unusable", unusable)
    board, records = _run_compute_grasp(franka, ent)
    [rec] = records
    assert abs(rec["turned_rad"]) == pytest.approx(np.radians(30), abs=1e-3)
    G = board["grasp_pose"]
    np.testing.assert_allclose(G[:3, 3], centred[:3, 3], atol=1e-9)  # about the same tool point
    assert abs(abs(hand_yaw(G) - hand_yaw(centred)) % np.pi - np.radians(30)) < 1e-6
    across = 2 * (0.0207 * np.cos(np.radians(30)) + 0.0393 * np.sin(np.radians(30)))
    assert franka.runtime_notes["planned_grasp"]["width_m"] == pytest.approx(across, abs=1e-4)
    # re-observed from that pre-grasp: the refinement keeps the turn
    board, records = _run_compute_grasp(franka, ent, board=board)
    assert abs(records[0]["turned_rad"]) == pytest.approx(np.radians(30), abs=1e-3)
    # a box whose turned width passes the stroke (8 cm less 4 mm) is never turned
    across_y = np.eye(4)
    across_y[:3, :3] = top_down_rotation(0.0)  # the fingers close along the box's y axis
    wide = GraspPlan(across_y, across_y, 0.0, 0.07)
    assert turn_offsets(wide, np.eye(4), (0.05, 0.035, 0.02)) == ()  # 7 cm across, 9.4 cm turned 15 degrees
    assert len(turn_offsets(wide, np.eye(4), (0.0393, 0.0207, 0.02))) == 4  # 4.1 cm across, 7.5 cm turned 30


def test_ik_whose_solution_collides_tries_the_ready_configuration_and_a_swung_elbow(franka, monkeypatch):
    """SolveIK's seeds (clear_ik): the solution from the current joints, else from the ready
    configuration, else from the ready configuration with the elbow swung; the first clear
    one wins; none clear: the first solution with its pairs; nothing converges: IKError."""
    import phyagentos.primitives.motion as motion
    from phyagentos.errors import IKError
    from phyagentos.motion.grasp import top_down_rotation

    ctx = SimpleNamespace(target=franka)
    pose = np.eye(4)
    pose[:3, :3] = top_down_rotation(0.0)
    pose[:3, 3] = (0.45, -0.25, 0.2)
    first = motion.solve_ik(franka.model, q_seed=franka.arm_qpos(), target=pose,
                            **motion.ik_options(franka)).q

    class Checker:  # collides wherever joint 3 is within 0.2 rad of the first solution's
        def colliding_pairs(self, q):
            return (("ketchup_1_main", "robot0_link5"),) if abs(q[2] - first[2]) < 0.2 else ()

    monkeypatch.setattr(motion, "session_checker", lambda ctx, margin_m=0.0, opening_m=None: Checker())
    sol, pairs, seed = motion.clear_ik(ctx, pose)
    assert pairs == () and seed.startswith("swivel") and abs(sol.q[2] - first[2]) >= 0.2

    class Everywhere:
        def colliding_pairs(self, q):
            return (("wall", "robot0_link4"),)

    monkeypatch.setattr(motion, "session_checker", lambda ctx, margin_m=0.0, opening_m=None: Everywhere())
    sol, pairs, seed = motion.clear_ik(ctx, pose)
    assert seed == "current" and pairs == (("wall", "robot0_link4"),)
    np.testing.assert_allclose(sol.q, first, atol=1e-6)
    far = pose.copy()
    far[:3, 3] = (3.0, 0.0, 0.2)
    with pytest.raises(IKError):
        motion.clear_ik(ctx, far)


def test_a_partly_seen_bowl_is_rim_graspable_but_a_cut_box_or_a_narrow_one_is_not():
    # LIBERO's bowl in the open drawer, its far side behind the drawer's front: 11.3 x 8.1 cm
    assert partly_seen_rim_graspable("akita_black_bowl", "box", (0.0567, 0.0405, 0.025))
    assert not rim_graspable("akita_black_bowl", "box", (0.0567, 0.0405, 0.025))  # not round: the plain rule refuses
    assert not partly_seen_rim_graspable("akita_black_bowl", "cylinder", HALF)  # round: the plain rule takes it
    assert not partly_seen_rim_graspable("cookies", "box", (0.0567, 0.0405, 0.025))  # no container
    assert not partly_seen_rim_graspable("bowl", "box", (0.035, 0.02, 0.02))  # narrow enough to take across
    assert not partly_seen_rim_graspable("bowl", "box", (0.06, 0.03, 0.07))  # taller than wide: no dish


def test_only_rim_points_near_the_ends_of_the_long_side_are_kept():
    T = bowl_at(0.5, 0.1)
    T[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # the long side along world y
    plans = rim_grasp_candidates(T, HALF)
    kept = near_long_axis(plans, T)
    assert 0 < len(kept) < len(plans)
    for plan in kept:
        d = plan.grasp[:2, 3] - T[:2, 3]
        assert abs(d[1]) / np.linalg.norm(d) >= math.cos(PARTLY_SEEN_RIM_ANGLE_RAD) - 1e-9


def test_compute_grasp_takes_a_partly_seen_bowl_by_its_rim_near_its_long_side(franka):
    ent = _entity("bowl_1", "akita_black_bowl", "box", (0.0567, 0.0405, 0.025))
    board, records = _run_compute_grasp(franka, ent)
    [rec] = records
    assert rec["grasp_kind"] == "rim" and rec["partly_seen"] is True
    assert board["look_closer"] is True  # the pick looks again from its pre-grasp (Observe or_if)
    d = board["grasp_pose"][:2, 3] - np.array([0.45, -0.25])
    assert abs(d[0]) / np.linalg.norm(d) >= math.cos(PARTLY_SEEN_RIM_ANGLE_RAD) - 1e-9  # the box's long side is x
    assert float(np.linalg.norm(d)) == pytest.approx(0.0567 - DEFAULT_RIM_WALL_M / 2, abs=1e-6)


def test_a_pre_grasp_out_of_reach_is_tried_lower_when_the_grasp_is_in_reach(franka):
    """A bowl raised 0.45 m (a high shelf, a top drawer) at 0.72 m: from 10 cm above its rim
    no pre-grasp is reachable, from 4 cm one is."""
    ent = _entity("bowl_1", "akita_black_bowl", "cylinder", HALF, xy=(0.72, 0.0))
    ent["position"][2] = 0.45
    board, records = _run_compute_grasp(franka, ent)
    [rec] = records
    # every one of the 16 rim points was refused from 10 cm before a lower pre-grasp was tried
    assert rec["approach_height_m"] in (0.06, 0.04) and rec["rim_points_refused"] >= 16
    G, P = board["grasp_pose"], board["pregrasp_pose"]
    assert P[2, 3] - G[2, 3] == pytest.approx(rec["approach_height_m"], abs=1e-6)


# --------------------------------------------------------------------- mugs: a handled open container

# LIBERO-90's red coffee mug as perceived on its generated scenes (bench descriptors): 11.0 x 9.4 cm
# with the handle, 14.8 cm tall
MUG = (0.055, 0.047, 0.074)


def test_a_mug_is_taken_by_its_rim_whatever_its_height_and_its_handle():
    assert rim_graspable("red_coffee_mug", "box", MUG)
    assert rim_graspable("porcelain_mug", "cylinder", (0.048, 0.048, 0.062))
    assert not rim_graspable("red_coffee_mug", "box", (0.07, 0.035, 0.074))  # not a mug's footprint
    assert not rim_graspable("red_coffee_mug", "box", (0.035, 0.03, 0.05))  # fits across: taken across
    assert not rim_graspable("bowl", "box", MUG)  # a bowl that tall is no dish


def test_only_rim_points_near_the_ends_of_a_mugs_short_side_are_kept():
    for T in (bowl_at(0.5, 0.1), np.array([[0.0, -1.0, 0.0, 0.5], [1.0, 0.0, 0.0, 0.1], [0.0, 0.0, 1.0, 0.07],
                                           [0.0, 0.0, 0.0, 1.0]])):
        plans = rim_grasp_candidates(T, (MUG[1], MUG[1], MUG[2]))
        kept = near_short_axis(plans, T, MUG)
        assert 0 < len(kept) < len(plans)
        short = T[:2, 1]  # the box's y side is the short one (hx > hy)
        for plan in kept:
            d = plan.grasp[:2, 3] - T[:2, 3]
            assert abs(float(d @ short)) / np.linalg.norm(d) >= math.cos(PARTLY_SEEN_RIM_ANGLE_RAD) - 1e-9


def test_compute_grasp_takes_a_mug_by_its_rim_away_from_the_handle_and_expects_its_thicker_wall(franka):
    ent = _entity("red_coffee_mug_1", "red_coffee_mug", "box", MUG)
    board, records = _run_compute_grasp(franka, ent)
    [rec] = records
    assert rec["grasp_kind"] == "rim" and rec["wall_m"] == DEFAULT_HANDLED_WALL_M
    d = board["grasp_pose"][:2, 3] - np.array([0.45, -0.25])
    assert abs(d[1]) / np.linalg.norm(d) >= math.cos(PARTLY_SEEN_RIM_ANGLE_RAD) - 1e-9  # the short side is y
    assert float(np.linalg.norm(d)) == pytest.approx(MUG[1] - DEFAULT_HANDLED_WALL_M / 2, abs=1e-6)
    assert franka.runtime_notes["planned_grasp"] == {"object": "red_coffee_mug_1", "width_m": DEFAULT_HANDLED_WALL_M,
                                                     "kind": "rim", "preshape_m": None}


def test_a_round_mug_whose_handle_was_seen_is_taken_across_the_handle_about_its_cups_axis(franka):
    """Seen round (a cylinder, yaw 0), the footprint says nothing of where the handle is: the
    rim point may land on it. With the cup's axis and the handle's direction perceived
    (``perception.handle``), the rim points lie across the handle, the cup's radius from its axis."""
    half = (0.048, 0.048, 0.062)
    ent = _entity("porcelain_mug_1", "porcelain_mug", "cylinder", half)
    ent["attributes"].update(axis_xy=[0.457, -0.25], handle_xy=[1.0, 0.0])  # the centre 7 mm towards the handle (+x)
    board, records = _run_compute_grasp(franka, ent)
    [rec] = records
    assert rec["grasp_kind"] == "rim" and rec.get("about_axis") is True
    d = board["grasp_pose"][:2, 3] - np.array([0.457, -0.25])
    assert abs(d[1]) / np.linalg.norm(d) >= math.cos(PARTLY_SEEN_RIM_ANGLE_RAD) - 1e-9  # across the handle's +x
    assert float(np.linalg.norm(d)) == pytest.approx(half[1] - DEFAULT_HANDLED_WALL_M / 2, abs=1e-6)
