"""The held-object model: ``holding`` and ``lifted`` decided from proprioception and the tcp's
forward kinematics when the hand hides the object from the cameras (issue 9, false failures)."""

from __future__ import annotations

import math

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from test_recovery_diagnosis import bundle, grasp, observe, session

import phyagentos.app.orchestrator as orchestrator
from phyagentos.agent.coordinator import AgentCoordinator
from phyagentos.agent.criteria import evaluate, parse_criteria
from phyagentos.agent.held_object import HOLD_STD_M, estimate_held, refine
from phyagentos.agent.verifier import SessionVerifier, load_evidence
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

AT = (0.5, -0.2, 0.02)  # where the cameras saw the cube (2 cm half extents) before the grasp
DOWN = [0.0, 1.0, 0.0, 0.0]  # tcp pointing down (180 deg about x)
BASE_N = 11.8  # the open, free hand's wrist force


def cube(pos=AT, *, conf=0.95, std=0.002, size=0.02):
    return {"name": "cube", "kind": "object", "position": list(pos), "quat_wxyz": [1, 0, 0, 0], "size": [size] * 3,
            "attributes": {"source": "perceived", "confidence": conf, "position_std_m": std}}


def hand(tcp, opening, effort, load, *, stamp=6.0):
    """Terminal proprioception: tcp and gripper entities (no camera sighting of the cube)."""
    return [{"name": "tcp", "kind": "robot", "position": list(tcp), "quat_wxyz": DOWN, "size": [0, 0, 0],
             "attributes": {"source": "proprioception"}},
            {"name": "gripper", "kind": "gripper", "position": list(tcp), "quat_wxyz": DOWN, "size": [opening, 0, 0],
             "attributes": {"source": "proprioception", "opening_m": opening, "effort_n": effort,
                            "wrist_force_n": [0.0, 0.0, -(BASE_N + load)]}}]


def sample(phase, opening, load, tcp, *, effort=None, stamp=0.0):
    return {"kind": "proprio", "leaf": phase, "phase": phase, "stamp_s": stamp, "opening_m": opening,
            "effort_n": 500.0 * opening if effort is None else effort,
            "wrist_force_n": [0.0, 0.0, -(BASE_N + load)], "wrist_load_n": load,
            "tcp_position_m": list(tcp), "tcp_quat_wxyz": DOWN}


def close_rec(opening):
    return {"kind": "gripper", "leaf": "CloseOnObject", "command": "close", "object": "cube", "opening_m": opening,
            "effort_n": 500.0 * opening, "stalled": opening > 0.002, "closed_on_something": opening > 0.002}


def pick_trace(*, opening=0.019, loads=(4.9, 4.9), rise=0.15, aim=AT, close_at=AT, end_opening=None):
    """A pick's trace: observe, grasp, close at ``close_at``, lift by ``rise`` with the wrist
    ``loads`` sampled on the way and at the check."""
    end_opening = opening if end_opening is None else end_opening
    top = (close_at[0], close_at[1], close_at[2] + rise)
    mid = (close_at[0], close_at[1], close_at[2] + rise / 2)
    return [sample("before_open", 0.04, 0.0, (0.3, 0.0, 0.4), effort=0.0, stamp=0.0),
            observe(aim, std=0.002), grasp(aim),
            sample("before_close", 0.04, 0.0, close_at, effort=0.0, stamp=4.0),
            close_rec(opening),
            sample("after_close", opening, 0.3, close_at, stamp=4.2),
            sample("Lift", opening, loads[0], mid, stamp=5.0),
            sample("check_holding", end_opening, loads[-1], top, stamp=6.0),
            {"kind": "load", "leaf": "CheckHolding", "object": "cube", "wrist_load_n": loads[-1], "baseline_n": BASE_N,
             "mass_estimate_kg": loads[-1] / 9.81}]


def occluded(tmp_path, trace, *, tcp_end, opening=0.019, load=4.9, stamp=6.0, initial=None, name="s"):
    """Evidence of a pick whose terminal view does not see the cube (the hand hides it)."""
    terminal = {"stamp_s": stamp, "entities": hand(tcp_end, opening, 500.0 * opening, load), "relations": []}
    init = {"stamp_s": 0.0, "entities": [cube()] if initial is None else initial, "relations": []}
    return bundle(tmp_path, init, terminal, trace, status="completed", name=name)


def judge(ev, accept=None):
    crits = parse_criteria(accept or {"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}})
    return {c.name: refine(evaluate(c, ev.initial, ev.terminal), ev) for c in crits}


def test_an_occluded_held_object_is_held_and_lifted_from_proprioception(tmp_path):
    ev = occluded(tmp_path, pick_trace(), tcp_end=(0.5, -0.2, 0.17))
    before = {c.name: evaluate(c, ev.initial, ev.terminal).status for c in parse_criteria({"holding": "cube",
                                                                                          "lifted": "cube"})}
    assert before == {"holding": "unknown", "lifted": "unknown"}  # the cameras alone cannot tell
    est = estimate_held(ev, "cube")
    assert est.status == "held" and est.position_m == pytest.approx((0.5, -0.2, 0.17), abs=1e-6)
    assert est.position_std_m == pytest.approx(math.hypot(0.002, HOLD_STD_M))
    assert est.facts["mass_kg"] == pytest.approx(0.5, abs=0.01)
    out = judge(ev)
    assert out["holding"].status == "satisfied" and "held-object model" in out["holding"].reason
    assert out["lifted"].status == "satisfied" and "rose 0.150 m" in out["lifted"].reason
    v = SessionVerifier().verify(session(), ev)
    assert v.verdict == "success", v.reason


def test_the_carried_object_follows_the_tcp_rotation(tmp_path):
    # grasped 1 cm off the tcp in x; the hand then turns 90 deg about the vertical
    trace = pick_trace(aim=(0.51, -0.2, 0.02), close_at=AT)
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    turned = [0.0, c, s, 0.0]  # DOWN followed by 90 deg about world z
    terminal = {"stamp_s": 6.0, "entities": hand((0.5, -0.2, 0.17), 0.019, 9.5, 4.9), "relations": []}
    for e in terminal["entities"]:
        e["quat_wxyz"] = turned
    ev = bundle(tmp_path, {"entities": [cube((0.51, -0.2, 0.02))]}, terminal, trace, status="completed")
    est = estimate_held(ev, "cube")
    assert est.status == "held" and est.position_m == pytest.approx((0.5, -0.19, 0.17), abs=1e-6)


def test_an_empty_closed_gripper_holds_nothing(tmp_path):
    trace = pick_trace(opening=0.0003, loads=(0.0, 0.0))
    ev = occluded(tmp_path, trace, tcp_end=(0.5, -0.2, 0.17), opening=0.0003, load=0.0)
    assert estimate_held(ev, "cube").status == "not_held"
    out = judge(ev)
    assert out["holding"].status == "unsatisfied" and out["lifted"].status != "satisfied"
    assert SessionVerifier().verify(session(), ev).verdict != "success"


def test_a_wrist_load_that_drops_after_the_lift_is_a_slip_not_a_hold(tmp_path):
    trace = pick_trace(loads=(4.9, 0.4))
    ev = occluded(tmp_path, trace, tcp_end=(0.5, -0.2, 0.17), load=0.4)
    est = estimate_held(ev, "cube")
    assert est.status == "not_held" and est.facts["slip_source"] == "wrist_load"
    out = judge(ev)
    assert out["holding"].status == "unsatisfied" and out["lifted"].status == "unknown"
    assert SessionVerifier().verify(session(), ev).verdict != "success"


def test_a_later_view_whose_wrist_no_longer_carries_the_load_is_not_a_hold(tmp_path):
    # the another-view child looked 3 s later: the wrist force is back to the free hand's
    ev = occluded(tmp_path, pick_trace(), tcp_end=(0.5, -0.2, 0.17), load=0.0, stamp=9.0)
    assert estimate_held(ev, "cube").status == "not_held"
    assert judge(ev)["holding"].status == "unsatisfied"


@pytest.mark.parametrize("change,why", [
    ({"opening": 0.0025}, "within 2 sigma"),  # opening inside the band around the empty-closed width
    ({"loads": (0.12, 0.12)}, "of an empty hand"),  # a load too small to tell from the empty hand
    ({"close_at": (0.5, -0.16, 0.02)}, "closed 4.0 cm from"),  # the fingers closed away from the seen cube
    ({"opening": 0.034}, "wider than cube"),  # something wider than the cube is between the fingers
    ({"loads": (40.0, 40.0)}, "payload"),  # pressing on something, not carrying
])
def test_evidence_the_model_cannot_decide_leaves_holding_unknown(tmp_path, change, why):
    trace = pick_trace(**change)
    ev = occluded(tmp_path, trace, tcp_end=(0.5, -0.2, 0.17), opening=change.get("opening", 0.019),
                  load=change.get("loads", (4.9,))[-1])
    est = estimate_held(ev, "cube")
    assert est.status == "unknown" and why in est.reason, est.reason
    out = judge(ev)
    assert out["holding"].status != "satisfied" and out["lifted"].status == "unknown"
    assert SessionVerifier().verify(session(), ev).verdict != "success"


def test_a_trace_without_forward_kinematics_is_unknown(tmp_path):
    trace = [{k: v for k, v in r.items() if not k.startswith("tcp_")} for r in pick_trace()]
    ev = occluded(tmp_path, trace, tcp_end=(0.5, -0.2, 0.17))
    assert estimate_held(ev, "cube").status == "unknown"
    assert judge(ev)["holding"].status == "unknown"


def test_what_the_cameras_decided_is_never_overturned(tmp_path):
    # proprioception says held, but the cube is seen confidently back on the table
    terminal = {"stamp_s": 6.0, "entities": [cube((0.6, -0.1, 0.02)), *hand((0.5, -0.2, 0.17), 0.019, 9.5, 4.9)],
                "relations": []}
    ev = bundle(tmp_path, {"entities": [cube()]}, terminal, pick_trace(), status="completed")
    out = judge(ev)
    assert out["holding"].status == "unsatisfied" and out["lifted"].status == "unsatisfied"


def test_the_grasp_observation_stands_in_for_a_missing_initial_sighting(tmp_path):
    ev = occluded(tmp_path, pick_trace(), tcp_end=(0.5, -0.2, 0.17), initial=[])
    out = judge(ev)
    assert out["lifted"].status == "satisfied" and out["holding"].status == "satisfied"


def test_a_hand_that_held_the_object_at_the_start_gives_no_initial_height(tmp_path):
    # recorded pattern (seed 20120, re-pick): the session began with the object still in the
    # hand, opened (it fell), grasped it from the table and lifted it. Its initial height was
    # the hand's, so the grasp's observation must not stand in for it.
    trace = pick_trace()
    trace[0] = sample("before_open", 0.017, 0.78, (0.5, -0.2, 0.19), effort=8.5, stamp=0.0)
    ev = occluded(tmp_path, trace, tcp_end=(0.5, -0.2, 0.17), initial=[])
    out = judge(ev)
    assert out["holding"].status == "satisfied"
    assert out["lifted"].status == "unknown" and "hand was not empty" in out["lifted"].reason
    assert SessionVerifier().verify(session(), ev).verdict != "success"


@settings(max_examples=120, deadline=None)
@given(rise=st.floats(0.0, 0.2), std=st.floats(0.0, 0.03), opening=st.floats(0.0, 0.03),
       load=st.floats(0.0, 12.0))
def test_the_model_is_never_satisfied_inside_the_two_sigma_band(tmp_path_factory, rise, std, opening, load):
    d = tmp_path_factory.mktemp("held")
    trace = pick_trace(opening=opening, loads=(load, load), rise=rise)
    trace[1] = observe(AT, std=std)
    init = [cube(std=std)]
    ev = occluded(d, trace, tcp_end=(AT[0], AT[1], AT[2] + rise), opening=opening, load=load, initial=init)
    out = judge(ev)
    s = math.hypot(std, math.hypot(std, HOLD_STD_M))
    if out["lifted"].status == "satisfied":
        assert rise >= 0.05 + 2 * s - 1e-9
        assert out["holding"].status == "satisfied"
    if out["holding"].status == "satisfied":
        assert opening > 0.002 + 2 * 0.0005 and load > 0.1 + 2 * (0.05 + 0.05 * load)
        assert opening <= 0.02 + 0.008 + 2 * 0.0005


class HiddenByTheHand(AgentCoordinator):
    """Before ``pick_cube`` is verified, its terminal snapshot loses every sighting of the
    cube and the perceiver's holding relation, as when the hand hides it from both cameras.
    The runtime, the trace and the verdicts are real."""

    hidden: list[str] = []

    def step(self) -> int:
        for s in self.sessions():
            if s.node == "pick_cube" and s.state == "awaiting_verification" and s.session_id not in self.hidden:
                path = self.workspace.root / s.attempts[-1].evidence / "terminal.yaml"
                snap = yaml.safe_load(path.read_text())
                snap["entities"] = [e for e in snap["entities"] if e["name"] != "cube"]
                snap["relations"] = [r for r in snap["relations"] if "cube" not in (r.get("object"), r.get("subject"))]
                path.write_text(yaml.safe_dump(snap))
                self.hidden.append(s.session_id)
        return super().step()


@pytest.mark.sim
def test_a_real_pick_hidden_by_the_hand_is_judged_from_proprioception(tmp_path, monkeypatch):
    HiddenByTheHand.hidden = []
    monkeypatch.setattr(orchestrator, "AgentCoordinator", HiddenByTheHand)
    report = orchestrator.run_goal_graph(goal_graphs_dir() / "pick_and_place.yaml", tmp_path / "ws")
    ws = Workspace.open(tmp_path / "ws")
    assert HiddenByTheHand.hidden, "no pick session was verified"
    pick = ws.load_session(HiddenByTheHand.hidden[0])
    verdict = pick.attempts[-1].verdict
    assert verdict.verdict == "success", verdict.reason
    assert all(c.status == "satisfied" and "held-object model" in c.reason for c in verdict.criteria), verdict.criteria
    assert report.succeeded
    # the model's carried position agrees with the simulator's (read here, by the test, only)
    ev = load_evidence(ws.root / pick.attempts[-1].evidence)
    est = estimate_held(ev, "cube")
    true = yaml.safe_load((ws.root / pick.attempts[-1].evidence / "ground_truth.yaml").read_text())
    true_pos = true["terminal"]["objects"]["cube"]["position"]
    assert est.status == "held"
    assert math.dist(est.position_m, true_pos) < 3 * est.position_std_m + 0.005, (est.position_m, true_pos)
    assert est.facts["mass_kg"] == pytest.approx(true["terminal"]["objects"]["cube"]["mass_kg"], rel=0.2)


def _without_wrist_sensor(trace):
    """The trace LIBERO's Panda records: robosuite's hand has no force/torque sensor wired to
    the runtime, so every sample's wrist force and load are missing (issue 28)."""
    return [{**r, "wrist_force_n": None, "wrist_load_n": None} if r.get("kind") == "proprio" else r
            for r in trace if r.get("kind") != "load"]


def test_a_pick_without_a_wrist_sensor_is_unknown_to_the_model_never_held(tmp_path):
    ev = occluded(tmp_path, _without_wrist_sensor(pick_trace()), tcp_end=(0.5, -0.2, 0.17))
    for e in ev.terminal["entities"]:
        e["attributes"].pop("wrist_force_n", None)
    est = estimate_held(ev, "cube")
    assert est.status == "unknown" and "no wrist load sampled after the lift" in est.reason
    out = judge(ev)
    assert out["holding"].status == "unknown" and out["lifted"].status == "unknown"
    assert SessionVerifier().verify(session(), ev).verdict != "success"
    # the same hand whose fingers closed on nothing is still not held without a sensor
    empty = occluded(tmp_path, _without_wrist_sensor(pick_trace(opening=0.0003)), tcp_end=(0.5, -0.2, 0.17),
                     opening=0.0003, name="empty")
    assert estimate_held(empty, "cube").status == "not_held"


@pytest.mark.parametrize("load", [0.214, 0.12])  # salad dressing 21.8 g, bbq sauce 12.2 g (measured, LIBERO)
def test_a_featherweight_bottle_is_within_two_sigma_of_an_empty_hand_so_the_load_cannot_confirm_it(tmp_path, load):
    """With robosuite's wrist sensor wired (a diagnosis, not the target's configuration), the
    lifted salad dressing read 0.214 N: inside the empty hand's 2-sigma band (0.1 N + 2 x
    (0.05 + 5 %) = 0.221 N). The model stays undecided; the cameras must decide."""
    ev = occluded(tmp_path, pick_trace(loads=(load, load)), tcp_end=(0.5, -0.2, 0.17), load=load)
    est = estimate_held(ev, "cube")
    assert est.status == "unknown" and "of an empty hand" in est.reason
    assert judge(ev)["holding"].status != "satisfied"


def _seen_lifted(tmp_path, *, initial_conf, aim_conf, end_conf, rise=0.15, empty_at_start=True, name="seen"):
    """A pick whose wrist has no sensor (LIBERO's hand) and whose cameras see the cube in the
    hand at the end; the initial snapshot saw it at ``initial_conf`` (None: not at all), the
    grasp's own observation at ``aim_conf``."""
    trace = _without_wrist_sensor(pick_trace(rise=rise))
    trace[1]["objects"]["cube"]["confidence"] = aim_conf
    if not empty_at_start:
        trace[0] = {**trace[0], "opening_m": 0.017, "effort_n": 8.5}
    top = (AT[0], AT[1], AT[2] + rise)
    terminal = {"stamp_s": 6.0, "entities": [cube(top, conf=end_conf, std=0.005),
                                              *hand(top, 0.019, 9.5, 0.0)], "relations": []}
    for e in terminal["entities"]:
        e["attributes"].pop("wrist_force_n", None)
    initial = [] if initial_conf is None else [cube(conf=initial_conf)]
    return bundle(tmp_path, {"stamp_s": 0.0, "entities": initial, "relations": []}, terminal, trace,
                  status="completed", name=name)


@pytest.mark.parametrize("initial_conf", [0.36, None])
def test_a_weak_initial_sighting_is_replaced_by_the_grasps_confident_view(tmp_path, initial_conf):
    """Recorded pattern (LIBERO, libero_object task 0): the initial snapshot saw the can at 0.36
    against its look-alike, the pick's own observation at 0.84, the view after the lift at
    0.84; the hand has no wrist sensor. The rise from the grasp's view decides."""
    ev = _seen_lifted(tmp_path, initial_conf=initial_conf, aim_conf=0.84, end_conf=0.84)
    assert evaluate(parse_criteria({"lifted": "cube"})[0], ev.initial, ev.terminal).status == "unknown"
    out = judge(ev)
    assert out["lifted"].status == "satisfied" and "grasp's observation" in out["lifted"].reason
    not_lifted = _seen_lifted(tmp_path, initial_conf=initial_conf, aim_conf=0.84, end_conf=0.84, rise=0.0, name="low")
    assert judge(not_lifted)["lifted"].status == "unsatisfied"


@pytest.mark.parametrize("kw, why", [
    (dict(aim_conf=0.45, end_conf=0.84), "the grasp aimed at a sighting no better than a coin flip"),
    (dict(aim_conf=0.84, end_conf=0.4), "the end view does not see it confidently"),
    (dict(aim_conf=0.84, end_conf=0.84, empty_at_start=False), "the hand may have held it at the start"),
])
def test_the_grasps_view_stands_in_only_when_it_and_the_end_view_are_confident(tmp_path, kw, why):
    ev = _seen_lifted(tmp_path, initial_conf=0.36, **kw)
    assert judge(ev)["lifted"].status == "unknown", why
    assert SessionVerifier().verify(session(), ev).verdict != "success", why


def test_a_grasp_by_the_rim_closes_on_the_wall_so_its_aim_is_the_rim_point_and_it_carries_the_centre(tmp_path):
    """A mug or bowl taken by its rim: the tcp closes on the wall, 4-5 cm from the perceived centre,
    which is more than the capture radius from it; the rim point the grasp aimed at is where the
    fingers must have closed, and the container's centre is what is carried."""
    rim = (AT[0], AT[1] - 0.045, AT[2])
    trace = pick_trace(close_at=rim)
    g = next(r for r in trace if r["kind"] == "grasp_pose")
    ev = occluded(tmp_path, trace, tcp_end=(rim[0], rim[1], rim[2] + 0.15), name="across")
    assert estimate_held(ev, "cube").status == "unknown"  # an across grasp 4.5 cm off the object: not captured
    g.update({"grasp_kind": "rim", "grasp": list(rim)})
    ev = occluded(tmp_path, trace, tcp_end=(rim[0], rim[1], rim[2] + 0.15), name="rim")
    est = estimate_held(ev, "cube")
    assert est.status == "held" and est.position_m == pytest.approx((AT[0], AT[1], AT[2] + 0.15), abs=1e-6)


def test_a_grasp_by_a_mugs_handle_closes_on_the_handle_so_its_capture_is_judged_there(tmp_path):
    """A mug taken by its handle (``pick_by_handle``): the fingers close on the handle's bar, 6.7 cm
    from the cup's perceived centre (LIBERO-10's porcelain mug, libero_10_object task 9), beyond
    the capture radius from it. The handle point the grasp planned is where they must have closed;
    the mug's centre is what is carried, so ``lifted`` is judged from its rise. An across grasp
    that closed there, and a handle grasp that closed 4 cm from its own handle point, are not
    captured."""
    bar = (AT[0] + 0.067, AT[1], AT[2])
    trace = pick_trace(close_at=bar)
    g = next(r for r in trace if r["kind"] == "grasp_pose")
    ev = occluded(tmp_path, trace, tcp_end=(bar[0], bar[1], bar[2] + 0.15), name="across")
    assert estimate_held(ev, "cube").status == "unknown"
    g.update({"grasp_kind": "handle", "affordance": "handle", "grasp": list(bar)})
    ev = occluded(tmp_path, trace, tcp_end=(bar[0], bar[1], bar[2] + 0.15), name="handle")
    est = estimate_held(ev, "cube")
    assert est.status == "held" and est.position_m == pytest.approx((AT[0], AT[1], AT[2] + 0.15), abs=1e-6)
    assert judge(ev)["lifted"].status == "satisfied"
    g.update({"grasp": [bar[0], bar[1] + 0.04, bar[2]]})
    ev = occluded(tmp_path, trace, tcp_end=(bar[0], bar[1], bar[2] + 0.15), name="missed")
    assert estimate_held(ev, "cube").status == "unknown"
