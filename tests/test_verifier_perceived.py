"""The verifier on perceived state: confidence, uncertainty bands, another view, never a
guessed success; recovery that addresses the cause (issue 9 part 4, issue 11 item 6)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_recovery_diagnosis import PLACE_ACCEPT, bundle, close, observe, session, snap

from phyagentos.agent.verifier import SessionVerifier
from phyagentos.protocol import Attempt, Diagnosis, Verdict
from phyagentos.protocol.lifecycle import utc_now

PLACE = {"skill": "place", "accept": PLACE_ACCEPT, "params": {"object": "cube", "region": "goal"}}
IN_GOAL = (0.5, 0.25, 0.02)


def _with_verdict(rec, verdict: Verdict):
    return rec.model_copy(update={"attempts": [Attempt(number=1, started_at=utc_now(), verdict=verdict)]})


def test_a_confident_view_inside_the_shrunk_region_is_success(tmp_path):
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02), holding=True), snap(IN_GOAL, std=0.004), status="completed")
    v = SessionVerifier().verify(session(**PLACE), ev)
    assert v.verdict == "success", v.reason


def test_a_low_confidence_view_asks_for_another_view_once_then_fails_as_perception_unknown(tmp_path):
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02), holding=True), snap(IN_GOAL, conf=0.3), status="completed")
    place = session(**PLACE)
    first = SessionVerifier().verify(place, ev)
    assert first.verdict == "replan" and first.diagnosis.cause == "perception_unknown"
    assert first.revision.strategy == "another_view" and first.revision.skill == "observe"
    assert first.revision.cause == "perception_unknown" and first.revision.parameters == {"samples": 4}
    assert "confidence 0.30" in first.criteria[0].reason and first.criteria[0].status == "unknown"
    # the other view is no better: failure, never success
    second = SessionVerifier().verify(place, ev, history=[_with_verdict(place, first)])
    assert second.verdict == "failure" and second.diagnosis.cause == "perception_unknown"


def test_an_absent_object_is_unknown_never_success(tmp_path):
    terminal = snap(IN_GOAL)
    terminal["entities"] = [e for e in terminal["entities"] if e["name"] != "cube"]
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02), holding=True), terminal, status="completed")
    v = SessionVerifier().verify(session(**PLACE), ev)
    assert v.verdict == "replan" and v.diagnosis.cause == "perception_unknown"
    assert "not in the terminal snapshot" in v.criteria[0].reason


def test_a_centre_within_two_sigma_of_the_region_edge_is_unknown_not_success(tmp_path):
    # 7 cm from the centre of an 8 cm half-width region: inside, but sigma 1 cm puts the edge within 2 sigma
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02), holding=True), snap((0.5, 0.32, 0.02), std=0.01),
                status="completed")
    v = SessionVerifier().verify(session(**PLACE), ev)
    assert v.criteria[0].status == "unknown" and v.verdict != "success"
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02), holding=True), snap((0.5, 0.32, 0.02), std=0.002),
                status="completed", name="t")
    assert SessionVerifier().verify(session(**PLACE), ev).verdict == "success"


def test_a_low_confidence_holding_relation_is_not_a_successful_pick(tmp_path):
    terminal = snap((0.5, -0.2, 0.17), holding=True)
    terminal["relations"][0]["confidence"] = 0.2
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), terminal, [close(0.019, 40.0)], status="completed")
    v = SessionVerifier().verify(session(), ev)
    assert v.verdict != "success" and v.criteria[0].status == "unknown"


@settings(max_examples=150, deadline=None)
@given(conf=st.floats(0.0, 0.499), std=st.floats(0.0, 0.05), dx=st.floats(-0.2, 0.2), dy=st.floats(-0.2, 0.2),
       dz=st.floats(-0.05, 0.05), depth=st.integers(0, 3))
def test_a_low_confidence_observation_never_yields_success(tmp_path_factory, conf, std, dx, dy, dz, depth):
    d = tmp_path_factory.mktemp("ev")
    ev = bundle(d, snap((0.5, -0.2, 0.02), holding=True),
                snap((0.5 + dx, 0.25 + dy, 0.02 + dz), std=std, conf=conf), status="completed")
    place = session(**PLACE)
    v = SessionVerifier(max_replans=3).verify(place, ev, lineage_depth=depth)
    assert v.verdict != "success"
    assert v.verdict == "failure" or v.revision.strategy == "another_view"


def test_an_unreachable_target_is_failure_with_no_retry(tmp_path):
    far = (3.0, 0.0, 0.02)
    ev = bundle(tmp_path, snap(far), snap(far), [observe(far)], code="ik.unreachable", leaf="ComputeGrasp")
    v = SessionVerifier().verify(session(), ev)
    assert v.verdict == "failure" and v.diagnosis.cause == "ik_unreachable" and v.revision is None


def test_a_collision_at_the_goal_configuration_gets_planning_revisions_not_another_look(tmp_path):
    plan = {"kind": "plan", "planner": "RRTConnect", "collision_at_goal": True}
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.17), holding=True), snap((0.5, -0.2, 0.17), holding=True),
                [observe((0.5, -0.2, 0.17)), plan], code="planning.failed", leaf="PlanPath")
    place = session(**PLACE)
    v = SessionVerifier().verify(place, ev)
    assert v.diagnosis.cause == "goal_in_collision" and v.diagnosis.category == "policy"
    assert v.verdict == "replan" and v.revision.strategy == "another_approach"
    assert v.revision.parameters == {"approach_height_m": 0.15}  # place declares no grasp_candidate
    assert not {"observe_samples", "reobserve_samples"} & set(v.revision.parameters)
    # the planner's own message is a planner report too
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.17), holding=True), snap((0.5, -0.2, 0.17), holding=True),
                [], code="planning.failed", leaf="PlanPath", name="m")
    ev = ev.__class__(**{**ev.__dict__, "outcome": {**ev.outcome, "message":
                                                     "goal configuration is invalid: hand <-> wall"}})
    assert SessionVerifier().verify(place, ev).diagnosis.cause == "goal_in_collision"


@pytest.mark.parametrize("cause", ["safety_intervention", "runtime_error", "ik_unreachable"])
def test_causes_no_parameter_can_fix_get_no_revision(cause):
    from phyagentos.agent.recovery import RecoveryPlanner

    d = Diagnosis(cause=cause, category="x", summary="x")
    assert RecoveryPlanner().plan(session(), d) is None


def test_every_revision_names_the_cause_it_addresses(tmp_path):
    from phyagentos.agent.diagnosis import CAUSES
    from phyagentos.agent.recovery import RecoveryPlanner

    for cause in CAUSES:
        for variant in (None, "planned", "cartesian"):
            d = Diagnosis(cause=cause, category=CAUSES[cause][0], summary="x", facts={"variant": variant})
            for s in (session(), session(**PLACE)):
                rev = RecoveryPlanner().plan(s, d, upstream="pick_cube")
                if rev is not None:
                    assert rev.cause == cause and (f"addresses {cause}" in rev.rationale or rev.reopen)
                    assert rev.parameters or rev.limits or rev.reopen


def test_a_slip_during_a_place_re_opens_the_pick_with_a_firmer_grip(tmp_path):
    held, dropped = (0.5, -0.1, 0.25), (0.5, -0.05, 0.02)
    ev = bundle(tmp_path, snap(held, holding=True), snap(dropped), [observe(held)], code="grasp.slipped",
                leaf="CheckHoldingAfterTransfer")
    place = session(**PLACE)
    v = SessionVerifier().verify(place, ev)
    assert v.diagnosis.cause == "object_slipped"
    # with no upstream node to re-open, retrying the place cannot bring the object back: failure
    assert v.verdict == "failure" and v.revision is None
    verifier = SessionVerifier()
    verifier.set_upstream(lambda s: "pick_cube")
    v = verifier.verify(place, ev)
    assert v.verdict == "replan" and v.revision.reopen == "pick_cube"
    assert v.revision.strategy == "firmer_grip" and v.revision.parameters == {"grip_force_n": 40.0}
    assert v.revision.cause == "object_slipped"


def _ent(name, pos, size, conf, std=0.002):
    return {"name": name, "kind": "object", "position": list(pos), "quat_wxyz": [1, 0, 0, 0], "size": list(size),
            "attributes": {"source": "perceived", "confidence": conf, "position_std_m": std}}


@pytest.mark.parametrize("plate_end,status", [
    (((0.003, -0.002, 0.45), 0.12), "satisfied"),   # seen weakly where it was: it stands in
    (((0.08, 0.0, 0.45), 0.12), "unknown"),         # seen weakly 8 cm away: it may have been pushed
    (None, "unknown"),                               # not seen at all: nothing says it did not move
    (((0.003, -0.002, 0.45), 0.9), "satisfied"),   # seen confidently: judged on that sighting
])
def test_a_plate_hidden_by_the_mug_set_on_it_stands_where_it_was_seen_confidently(plate_end, status):
    from phyagentos.agent.criteria import evaluate, parse_criteria

    plate0 = _ent("plate_1", (0.0, 0.0, 0.45), (0.1, 0.1, 0.01), 0.95)
    mug = _ent("mug_1", (0.0, 0.0, 0.46 + 0.06), (0.045, 0.045, 0.06), 0.9)
    initial = {"entities": [plate0], "relations": []}
    ents = [mug] + ([] if plate_end is None else [_ent("plate_1", plate_end[0], (0.05, 0.03, 0.01), plate_end[1])])
    terminal = {"entities": ents, "relations": []}
    [c] = parse_criteria({"on": {"object": "mug_1", "support": "plate_1"}})
    out = evaluate(c, initial, terminal)
    assert out.status == status, out.reason
    if status == "satisfied" and plate_end[1] < 0.5:
        assert "where the initial snapshot saw it" in out.reason


VIEW = {"viewer": {"right_xy": [0.0, 1.0]}}  # LIBERO's agentview: the image's right is world +y


@pytest.mark.parametrize("pudding,status", [
    ((0.15, 0.11, 0.47), "satisfied"),    # 4 cm right of the plate's edge, on the table
    ((0.15, -0.11, 0.47), "unsatisfied"),  # on its left
    ((0.15, 0.0, 0.48), "unsatisfied"),   # on the plate
    ((0.15, 0.30, 0.47), "unsatisfied"),  # across the table
    ((0.28, 0.11, 0.47), "unsatisfied"),  # right of it but far behind
    ((0.15, 0.072, 0.47), "unknown"),     # its centre within 2 sigma of the plate's edge
])
def test_beside_is_the_viewers_side_of_the_landmark_next_to_it_on_the_same_surface(pudding, status):
    from phyagentos.agent.criteria import evaluate, parse_criteria

    plate = _ent("plate_1", (0.15, 0.0, 0.45), (0.069, 0.069, 0.01), 0.9)
    pud = _ent("chocolate_pudding_1", pudding, (0.03, 0.022, 0.03), 0.9, std=0.002)
    terminal = {"entities": [plate, pud], "relations": [], **VIEW}
    [c] = parse_criteria({"beside": {"object": "chocolate_pudding_1", "landmark": "plate_1", "side": "right"}})
    out = evaluate(c, {"entities": [plate]}, terminal)
    assert out.status == status, out.reason
    # the same pudding seen from behind the robot is on the plate's other side
    if status == "satisfied":
        flipped = {**terminal, "viewer": {"right_xy": [0.0, -1.0]}}
        assert evaluate(c, {"entities": [plate]}, flipped).status == "unsatisfied"
        without = {k: v for k, v in terminal.items() if k != "viewer"}
        assert "viewer's left and right" in evaluate(c, {"entities": [plate]}, without).reason


@pytest.mark.parametrize("bottom,status", [
    (0.0085, "satisfied"),    # on the plate's floor, 8.5 mm up, under its 3 cm rim
    (0.030, "satisfied"),     # on its rim top
    (0.0, "unknown"),         # down at the table inside the plate's footprint: not resting on it, not clearly off
    (0.055, "unsatisfied"),   # 2.5 cm above the rim: not resting
])
def test_on_a_dish_rests_anywhere_from_its_floor_to_its_rim(bottom, status):
    from phyagentos.agent.criteria import evaluate, parse_criteria

    table = 0.425
    plate = _ent("plate_1", (0.0, -0.3, table + 0.015), (0.069, 0.069, 0.015), 0.95, std=0.005)
    mug = _ent("mug_1", (0.005, -0.295, table + bottom + 0.06), (0.048, 0.048, 0.06), 0.9)
    snap = {"entities": [plate, mug], "relations": []}
    [c] = parse_criteria({"on": {"object": "mug_1", "support": "plate_1"}})
    out = evaluate(c, snap, snap)
    assert out.status == status, out.reason


def test_an_object_far_down_in_a_tall_supports_footprint_is_not_on_it():
    from phyagentos.agent.criteria import evaluate, parse_criteria

    # the cabinet's top at 0.655 m; a bowl in its open top drawer, 10 cm below that top
    cabinet = _ent("wooden_cabinet_1", (0.0, 0.0, 0.425 + 0.115), (0.12, 0.2, 0.115), 0.9)
    bowl = _ent("bowl_1", (0.0, 0.05, 0.555 + 0.025), (0.065, 0.065, 0.025), 0.9)
    snap = {"entities": [cabinet, bowl], "relations": []}
    [c] = parse_criteria({"on": {"object": "bowl_1", "support": "wooden_cabinet_1"}})
    assert evaluate(c, snap, snap).status == "unsatisfied"


@pytest.mark.parametrize("offset,status", [
    (0.008, "satisfied"),    # well inside: level on the plate's floor
    (0.028, "unknown"),      # its base reaches the rim within the uncertainty
    (0.045, "unsatisfied"),  # its base over the rim: it leans on it
])
def test_down_in_a_dish_the_objects_base_must_lie_inside_the_rim(offset, status):
    from phyagentos.agent.criteria import evaluate, parse_criteria

    table = 0.425
    plate = _ent("plate_1", (0.0, 0.3, table + 0.015), (0.069, 0.069, 0.015), 0.95, std=0.005)
    mug = _ent("mug_1", (0.0, 0.3 - offset, table + 0.012 + 0.058), (0.052, 0.037, 0.058), 0.9)
    snap = {"entities": [plate, mug], "relations": []}
    [c] = parse_criteria({"on": {"object": "mug_1", "support": "plate_1"}})
    out = evaluate(c, snap, snap)
    assert out.status == status, out.reason


@pytest.mark.parametrize("obj,offset,status", [
    ("bowl", 0.010, "satisfied"),    # a bowl as wide as the plate's middle, near its centre
    ("bowl", 0.061, "unsatisfied"),  # 6 cm off at the rim's height: on the rim and the table (LIBERO said no)
    ("bowl", 0.027, "unknown"),      # at the edge of the middle within the uncertainty
    ("box", 0.040, "satisfied"),     # a small box 4 cm off: its whole footprint still over the plate
    ("box", 0.076, "unsatisfied"),   # its footprint past the plate's edge
])
def test_on_a_flat_support_the_objects_footprint_lies_over_it_or_it_stands_near_its_middle(obj, offset, status):
    """Found on the development split (``bench --generated``, libero_spatial task 7, seed 501): a
    bowl let go 6 cm off the plate's centre was judged on it; LIBERO's checker counted it off."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    table = 0.425
    plate = _ent("plate_1", (0.0, 0.3, table + 0.009), (0.082, 0.082, 0.009), 0.95, std=0.0015)
    size = (0.056, 0.056, 0.025) if obj == "bowl" else (0.02, 0.015, 0.01)
    thing = _ent(obj, (0.0, 0.3 + offset, table + 0.018 + size[2]), size, 0.9, std=0.0015)
    snap = {"entities": [plate, thing], "relations": []}
    [c] = parse_criteria({"on": {"object": obj, "support": "plate_1"}})
    out = evaluate(c, snap, snap)
    assert out.status == status, out.reason


@pytest.mark.parametrize("origin,std,status", [
    (None, 0.002, "satisfied"),             # no origin perceived: judged on its centre, 1.2 cm off
    ((0.0, 0.2695), 0.002, "unknown"),      # its model origin 3.05 cm off, towards the handle: not a success
    ((0.0, 0.262), 0.002, "unsatisfied"),   # ... 3.8 cm off
    ((0.0, 0.290), 0.002, "satisfied"),     # its origin 1 cm off
    ((0.0, 0.290), 0.012, "unknown"),       # ... the handle unseen: the origin as uncertain as its offset
])
def test_on_a_dish_a_handled_objects_model_origin_is_judged_not_its_centre(origin, std, status):
    """LIBERO-10 task 4 (an evaluation episode, read after the run): a mug's centre 1.75 cm off
    the plate's was judged on it; its model origin -- 1.65 cm from its cup's axis towards the
    handle, the point LIBERO's checker measures -- was 3.05 cm off, and the checker said no."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    table = 0.425
    plate = _ent("plate_1", (0.0, 0.3, table + 0.015), (0.069, 0.069, 0.015), 0.95, std=0.002)
    mug = _ent("mug_1", (0.0, 0.288, table + 0.012 + 0.058), (0.052, 0.037, 0.058), 0.9)
    if origin is not None:
        mug["attributes"].update(origin_xy=list(origin), origin_std_m=std)
    snap = {"entities": [plate, mug], "relations": []}
    [c] = parse_criteria({"on": {"object": "mug_1", "support": "plate_1"}})
    out = evaluate(c, snap, snap)
    assert out.status == status, out.reason


@pytest.mark.parametrize("open_depth,inside_relation,status", [
    (None, False, "satisfied"),   # a solid top at that height (a box, a cabinet's top): resting on it
    (0.012, False, "satisfied"),  # an open top no deeper than a dish (a plate): resting on its rim is on it
    (0.075, False, "unknown"),    # a basket 7.5 cm deep: on its rim, or seen only above its walls
    (0.075, True, "satisfied"),   # ... seen inside it by perception: in it
])
def test_at_the_rim_of_a_deep_open_container_an_object_is_not_in_it_unless_seen_inside(open_depth, inside_relation,
                                                                                       status):
    """LIBERO-10 task 1, init 1 (7e40e83's free spot, since reverted): the butter came to rest
    on the basket's rim; `on` said set, LIBERO's `In` did not. Perception's open depth now tells
    a basket's rim from a solid top."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    table = 0.425
    basket = _ent("basket_1", (0.0, 0.2, table + 0.04), (0.1, 0.08, 0.04), 0.95, std=0.003)
    if open_depth is not None:
        basket["attributes"]["open_depth_m"] = open_depth
    butter = _ent("butter_1", (0.06, 0.2, table + 0.08 + 0.012), (0.05, 0.025, 0.012), 0.9)  # bottom on the rim
    rel = [{"subject": "butter_1", "relation": "inside", "object": "basket_1", "confidence": 0.8}]
    snap = {"entities": [basket, butter], "relations": rel if inside_relation else []}
    [c] = parse_criteria({"on": {"object": "butter_1", "support": "basket_1"}})
    out = evaluate(c, snap, snap)
    assert out.status == status, out.reason
    if status == "unknown":
        assert "rim of an open container" in out.reason


@pytest.mark.parametrize("open_depth,dy,held,status", [
    (0.073, 0.0, False, "satisfied"),     # down in the basket, inside its walls
    (0.073, 0.055, False, "unknown"),     # its centre nearer a wall than its own half width: leaning on it?
    (0.073, 0.12, False, "unsatisfied"),  # its centre beyond the basket's footprint: beside it
    (0.073, 0.0, True, "unsatisfied"),    # still in the hand
    (None, 0.0, False, "unsatisfied"),    # a solid block that tall: far below its top is not on it
])
def test_down_in_a_deep_open_container_an_object_within_its_walls_is_in_it(open_depth, dy, held, status):
    """libero_object's development split (seed 501): a can set in the basket, seen there as its own
    segment down to the floor, was judged "not on basket_1" (its bottom far below the rim, where a
    dish's floor would be) and picked out again. Perception's open depth says the basket's inside
    goes down that far."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    basket = _ent("basket_1", (0.0, 0.25, 0.07), (0.087, 0.08, 0.07), 0.8, std=0.003)
    if open_depth is not None:
        basket["attributes"]["open_depth_m"] = open_depth
    soup = _ent("alphabet_soup_1", (-0.02, 0.25 + dy, 0.049), (0.023, 0.023, 0.049), 0.8, std=0.0027)
    rel = [{"subject": "gripper", "relation": "holding", "object": "alphabet_soup_1", "confidence": 0.9}] if held else []
    snap = {"entities": [basket, soup], "relations": rel}
    [c] = parse_criteria({"on": {"object": "alphabet_soup_1", "support": "basket_1"}})
    out = evaluate(c, snap, snap)
    assert out.status == status, out.reason


@pytest.mark.parametrize("walls_m,dy,status", [
    (0.06, 0.008, "satisfied"),    # upright in the slot, 8 mm off its middle: the walls hold it
    (0.06, 0.000, "satisfied"),
    (0.06, 0.060, "unsatisfied"),  # its centre past the floor's edge
    (None, 0.008, "unknown"),      # the same floor without walls: a wide thing near the middle of a flat support
])
def test_on_a_floor_between_walls_the_object_stands_anywhere_between_them(walls_m, dy, status):
    """LIBERO-90 task 74's book in the caddy's left compartment (5.8 cm wide): as a flat support's
    rule, a book 11 cm long is as wide as the floor, so it had to stand within 2.5 cm of the middle
    less 2 sigma of both (0.5 cm at the trace's 2 cm), and a book 5 mm off was undecided; the walls
    hold it upright."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    floor_z = 0.9
    slot = _ent("desk_caddy_1_left_compartment", (-0.39, -0.28, floor_z - 0.002), (0.029, 0.06, 0.002), 0.9, std=0.0099)
    slot["kind"] = "fixture"
    slot["attributes"].update({"class": "compartment", "support": True,
                               **({"walls_m": walls_m} if walls_m is not None else {})})
    slot["quat_wxyz"] = [0.7071068, 0.0, 0.0, 0.7071068]  # turned a quarter: its narrow side along world y
    book = _ent("black_book_1", (-0.39, -0.28 + dy, floor_z + 0.069), (0.055, 0.0085, 0.069), 0.95, std=0.001)
    snap = {"entities": [slot, book], "relations": []}
    [c] = parse_criteria({"on": {"object": "black_book_1", "support": "desk_caddy_1_left_compartment"}})
    out = evaluate(c, snap, snap)
    assert out.status == status, out.reason


@pytest.mark.parametrize("leant,held,status", [
    ((0.013, 0.016, 0.99), False, "satisfied"),    # seen lying on the ramp where the hand let it go
    ((0.013, 0.016, 0.30), False, "unknown"),      # seen so only weakly
    ((0.013, 0.016, 0.99), True, "unsatisfied"),   # still in the hand
    ((0.013, 0.12, 0.99), False, "unsatisfied"),   # its centre beyond the rack's footprint
    (None, False, "unsatisfied"),                  # no such relation: judged upright, its bottom far below the top
])
def test_a_bottle_lying_on_the_racks_ramp_is_on_the_rack_only_where_perception_saw_it_so(leant, held, status):
    """``on`` a fixture with a ramp (LIBERO's wine rack) is judged on perception's ``leant_on``
    relation (``perception.lean``): the bottle lies back on the ramp, its box's bottom far below
    the rack's top, where the upright test would fail it."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    rack = _ent("wine_rack_1", (-0.268, -0.242, 1.06), (0.138, 0.0705, 0.16), 0.99, std=0.01)
    dx, dy, conf = leant or (0.013, 0.016, 0.0)
    bottle = _ent("wine_bottle_1", (-0.268 + dx, -0.242 + dy, 1.212), (0.008, 0.008, 0.078), 0.99, std=0.01)
    rels = [] if leant is None else [{"subject": "wine_bottle_1", "relation": "leant_on", "object": "wine_rack_1",
                                      "confidence": conf}]
    if held:
        rels.append({"subject": "gripper", "relation": "holding", "object": "wine_bottle_1", "confidence": 0.95})
    terminal = {"entities": [rack, bottle], "relations": rels}
    [c] = parse_criteria({"on": {"object": "wine_bottle_1", "support": "wine_rack_1"}})
    out = evaluate(c, {"entities": [rack]}, terminal)
    assert out.status == status, out.reason
    if leant is not None and conf >= 0.5 and not held:
        assert "leant on wine_rack_1" in out.reason


@pytest.mark.parametrize("origin,status", [
    ((-0.008, -0.193), "satisfied"),   # its body 4.9 cm off the burner plate's centre, its handle over the edge
    ((0.045, -0.200), "unsatisfied"),  # its body beyond the plate's edge (7.5 cm from the centre) by 2 sigma
    ((0.012, -0.200), "unknown"),      # its body within 2 sigma of that edge
    (None, "unknown"),                 # no origin: its box's centre, handle and all, within 2 sigma of the edge
])
def test_on_a_burner_plate_a_handled_objects_body_stands_over_it_not_its_box(origin, status):
    """A moka pot's box includes its handle: set 4.9 cm off the centre of the stove's burner plate
    (15 cm square), the box's centre stood 6.0 cm off, within 2 sigma of the edge, and the
    verdict was undecided (LIBERO-10 task 8, the second pot: LIBERO's ``On`` asks the model
    origin to lie within the site, ``SiteObject.under``). The footprint is judged at the
    origin perception reports."""
    from phyagentos.agent.criteria import evaluate, parse_criteria

    stove = _ent("flat_stove_1", (-0.057, -0.198, 0.9155), (0.075, 0.075, 0.0155), 0.98, std=0.01)
    pot = _ent("moka_pot_2", (0.003, -0.206, 0.999), (0.066, 0.036, 0.068), 0.95, std=0.001)
    if origin is not None:
        pot["attributes"].update(origin_xy=list(origin), origin_std_m=0.001)
    terminal = {"entities": [stove, pot], "relations": []}
    [c] = parse_criteria({"on": {"object": "moka_pot_2", "support": "flat_stove_1"}})
    out = evaluate(c, {"entities": [stove]}, terminal)
    assert out.status == status, out.reason
