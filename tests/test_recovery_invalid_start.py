"""An invalid start configuration is not an ordinary planning failure (tracker issue 35).

A step on the SO-101 failed ``planning_failed`` with "start configuration is invalid:
moving_jaw_so101_v1 <-> wrist"; the ladder spent both replans on ``another_planner``, which
cannot plan from an invalid start, and never re-targeted. The runtime now records the
refused start in a ``plan`` entry (``collision_at_start``, ``start_contact``), diagnosis
calls it ``start_in_collision``, and recovery backs off (the scene touches the arm) or
re-targets at once (the arm touches itself). No simulation here.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from test_recovery_diagnosis import PICK_ACCEPT, PLACE_ACCEPT, _replanned, bundle, observe, session, snap

from phyagentos.agent.diagnosis import CAUSES, diagnose
from phyagentos.agent.recovery import RETARGET_CAUSES, RecoveryPlanner
from phyagentos.agent.verifier import SessionVerifier
from phyagentos.protocol import Diagnosis

ISSUE_35 = ("PlanPath: start configuration is invalid: moving_jaw_so101_v1 <-> wrist "
            "(q_start=[0.1, -0.4, 0.4, 1.5, 1.0])")


def _start_plan(contact, pairs):
    return {"kind": "plan", "planner": "RRTConnect", "waypoints": 0, "collision_at_goal": False,
            "collision_at_start": True, "start_contact": contact, "colliding_pairs": pairs}


def _bundle(tmp_path, trace, *, message=None, name="s"):
    ev = bundle(tmp_path, snap((0.45, -0.1, 0.02)), snap((0.45, -0.1, 0.02)), trace,
                code="planning.failed", leaf="PlanPath", name=name)
    if message is not None:
        ev.outcome["message"] = message
    return ev


class _Chooser:
    """A target chooser that finds another arm (the selector's answer, without a workspace)."""

    def __init__(self, target="franka_tabletop"):
        self.target, self.asked = target, []

    def choose(self, session, *, cause):
        self.asked.append(cause)
        return SimpleNamespace(target=self.target, reasons={self.target: "chosen: fits: reach (IK on its model)"})


def test_a_start_touching_the_arm_itself_is_diagnosed_start_in_collision_not_planning_failed(tmp_path):
    ev = _bundle(tmp_path, [observe((0.45, -0.1, 0.02)), _start_plan("self", [["moving_jaw_so101_v1", "wrist"]])],
                 message=ISSUE_35)
    d = diagnose(session(), ev)
    assert d.cause == "start_in_collision" and d.category == CAUSES["start_in_collision"][0]
    assert d.facts["variant"] == "self" and d.facts["colliding_pairs"] == [["moving_jaw_so101_v1", "wrist"]]
    assert "arm touches itself" in d.summary


def test_the_message_alone_is_enough_for_an_invalid_start(tmp_path):
    """Evidence written before the runtime recorded ``collision_at_start``: the runtime's
    message still names the refused start."""
    d = diagnose(session(), _bundle(tmp_path, [], message=ISSUE_35))
    assert d.cause == "start_in_collision" and d.facts["variant"] == "unknown"


def test_an_ordinary_planning_failure_stays_planning_failed(tmp_path):
    d = diagnose(session(), _bundle(tmp_path, [], message="PlanPath: no exact solution within 5.0 s"))
    assert d.cause == "planning_failed"


def test_a_self_contact_start_goes_to_another_arm_on_the_first_replan_never_another_planner():
    d = Diagnosis(cause="start_in_collision", category="policy", summary="x", facts={"variant": "self"})
    chooser = _Chooser()
    rev = RecoveryPlanner(retarget=chooser).plan(session(), d)
    assert rev is not None and rev.target == "franka_tabletop"
    assert rev.strategy == "switch_target_to_franka_tabletop" and rev.step == 1
    assert chooser.asked == ["start_in_collision"] and "start_in_collision" in RETARGET_CAUSES
    assert "planner" not in rev.parameters


def test_a_self_contact_start_without_another_arm_gives_up_instead_of_replanning():
    d = Diagnosis(cause="start_in_collision", category="policy", summary="x", facts={"variant": "self"})
    assert RecoveryPlanner().plan(session(), d) is None
    assert RecoveryPlanner(retarget=_Chooser(target=None)).plan(session(), d) is None


def test_a_start_touching_the_scene_backs_off_first_then_switches_target(tmp_path):
    d = Diagnosis(cause="start_in_collision", category="policy", summary="x", facts={"variant": "environment"})
    chooser = _Chooser()
    ladder = RecoveryPlanner(retarget=chooser)
    first = ladder.plan(session(), d)
    assert first.strategy == "back_off_first" and first.parameters == {"backoff_m": 0.10, "settle_s": 0.5}
    root = _replanned(session(), "start_in_collision")
    child = session(params={"object": "cube", "backoff_m": 0.10, "settle_s": 0.5}, sid="r-pick_cube-2",
                    parent=root.session_id)
    second = ladder.plan(child, d, history=[root])
    assert second.strategy == "switch_target_to_franka_tabletop" and second.step == 2


def test_a_skill_without_a_back_off_switches_target_at_once():
    """``place`` declares no ``backoff_m``: the back-off rung would change nothing."""
    d = Diagnosis(cause="start_in_collision", category="policy", summary="x", facts={"variant": "held_object"})
    place = session(skill="place", accept=PLACE_ACCEPT, params={"object": "cube", "region": "goal"})
    rev = RecoveryPlanner(retarget=_Chooser()).plan(place, d)
    assert rev.strategy == "switch_target_to_franka_tabletop"


def test_the_issue_35_replay_re_targets_within_a_budget_of_two(tmp_path):
    """The verifier's own ladder, as the run wires it: the first replan of the refused start
    already moves the node to the other arm (before: another_planner twice, budget spent)."""
    ev = _bundle(tmp_path, [observe((0.45, -0.1, 0.02)), _start_plan("self", [["moving_jaw_so101_v1", "wrist"]])],
                 message=ISSUE_35)
    verifier = SessionVerifier(max_replans=2)
    verifier.recovery.retarget = _Chooser()
    v = verifier.verify(session(accept=PICK_ACCEPT), ev)
    assert v.verdict == "replan" and v.diagnosis.cause == "start_in_collision"
    assert v.revision.target == "franka_tabletop"


def test_the_runtime_names_what_an_invalid_start_touches():
    from phyagentos.primitives.motion import start_contact_kind

    class _Checker:
        model = SimpleNamespace(body=lambda b: SimpleNamespace(name=["wrist", "moving_jaw_so101_v1", "gripper"][b]))
        robot_bodies = frozenset({0, 1, 2})
        attached = None

    c = _Checker()
    assert start_contact_kind(c, (("moving_jaw_so101_v1", "wrist"),)) == "self"
    assert start_contact_kind(c, (("gripper", "table"),)) == "environment"
    assert start_contact_kind(c, (("joint_limit", "wrist_roll"),)) == "joint_limit"
    c.attached = "cube"
    assert start_contact_kind(c, (("cube", "wrist"),)) == "held_object"
    assert np.all([start_contact_kind(c, ()) == "environment"])


def test_a_door_close_that_starts_against_the_door_backs_off_and_looks_from_clear_of_it():
    """LIBERO-10 task 9, init 9: the look into the microwave left the hand against its door,
    and the close could not plan from there. ``close_door`` declares the back-off, so the
    first replan raises the hand, and it reads the door only after leaving the cameras' view
    (from beside the door the slab was read as shut)."""
    import yaml

    from phyagentos.resources import trees_dir

    d = Diagnosis(cause="start_in_collision", category="policy", summary="x", facts={"variant": "environment"})
    close = session(skill="close_door", accept=[{"articulated": {"object": "microwave_1", "min": -0.02,
                                                                  "max": 0.02}}], params={"object": "microwave_1"})
    rev = RecoveryPlanner().plan(close, d)
    assert rev is not None and rev.strategy == "back_off_first"
    assert rev.parameters == {"backoff_m": 0.10, "settle_s": 0.5}
    tree = yaml.safe_load((trees_dir() / "close_door.yaml").read_text())
    names = [c.get("name") for c in tree["root"]["sequence"]["children"]]
    assert names.index("BackOff") < names.index("ClearViewFirst") < names.index("ObserveScene") \
        < names.index("ComputeDoorPush")
