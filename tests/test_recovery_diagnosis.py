"""Diagnosis from evidence into the taxonomy, and the recovery it leads to (no simulation).

Bundles here are written the way the SessionRunner writes them (perceived snapshots,
trace.jsonl with the CONTRACT_9 section 5 entries, events, bundle.yaml), so these tests
pin the rules on exact evidence. Nothing here carries simulator state: the rules work
from what a robot perceives and feels.
"""

from __future__ import annotations

import json

import pytest
import yaml

from phyagentos.agent.diagnosis import CAUSES, diagnose
from phyagentos.agent.recovery import LADDERS, RecoveryPlanner
from phyagentos.agent.verifier import SessionVerifier, load_evidence
from phyagentos.protocol import Attempt, SessionRecord, Verdict
from phyagentos.protocol.lifecycle import utc_now

PICK_ACCEPT = {"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}}
PLACE_ACCEPT = {"inside": {"object": "cube", "region": "goal"}, "released": "cube"}


def ent(name, pos, kind="object", size=(0.02, 0.02, 0.02), *, std=0.003, conf=0.95):
    attrs = {"source": "perceived", "confidence": conf, "position_std_m": std} if kind == "object" else {}
    return {"name": name, "kind": kind, "position": list(pos), "quat_wxyz": [1, 0, 0, 0], "size": list(size),
            "attributes": attrs}


def snap(cube, *, holding=False, tcp_z=0.37, std=0.003, conf=0.95):
    rel = [{"subject": "gripper", "relation": "holding", "object": "cube", "confidence": 0.9}] if holding else []
    return {"entities": [ent("cube", cube, std=std, conf=conf), ent("goal", (0.5, 0.25, 0.0), "region", (0.08, 0.08, 0.0)),
                         ent("tcp", (0.46, 0.0, tcp_z), "robot", (0, 0, 0))], "relations": rel}


def observe(perceived, std=0.003, conf=0.95, leaf="ObserveScene"):
    return {"kind": "observe", "leaf": leaf, "objects": {"cube": {"position": list(perceived), "confidence": conf,
                                                                  "position_std_m": std}}, "unknown": 0}


def grasp(at):
    return {"kind": "grasp_pose", "object": "cube", "observed_position": list(at), "grasp": list(at)}


def close(opening, effort=0.0):
    return {"kind": "gripper", "command": "close", "object": "cube", "opening_m": opening, "effort_n": effort,
            "stalled": opening > 0.002, "closed_on_something": opening > 0.002}


def proprio(phase, opening, load, effort=30.0):
    return {"kind": "proprio", "phase": phase, "opening_m": opening, "effort_n": effort,
            "wrist_force_n": [0.0, 0.0, -load], "wrist_load_n": load}


def bundle(tmp_path, initial, terminal, trace=(), *, events=(), status="failed", code=None, leaf=None, name="s"):
    d = tmp_path / "evidence" / name
    d.mkdir(parents=True)
    (d / "initial.yaml").write_text(yaml.safe_dump(initial))
    (d / "terminal.yaml").write_text(yaml.safe_dump(terminal))
    (d / "events.yaml").write_text(yaml.safe_dump(list(events)))
    (d / "trace.jsonl").write_text("".join(json.dumps(r) + "\n" for r in trace))
    files = {"initial": "initial.yaml", "terminal": "terminal.yaml", "events": "events.yaml", "trace": "trace.jsonl"}
    (d / "bundle.yaml").write_text(yaml.safe_dump({"session_id": name, "files": files, "outcome": {
        "status": status, "error_code": code, "failed_primitive": leaf, "message": f"{code or ''} at {leaf or ''}"}}))
    return load_evidence(d)


def session(skill="pick", accept=PICK_ACCEPT, params=None, sid="r-pick_cube-1", parent=None) -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id=sid, run_id="r", node="pick_cube", skill=skill, target="franka_tabletop",
                         parameters=params or {"object": "cube"}, accept=accept, created_at=now, updated_at=now,
                         parent_session_id=parent)


def test_a_missed_grasp_from_an_uncertain_observation_is_a_perception_error(tmp_path):
    seen = (0.5, -0.225, 0.02)
    ev = bundle(tmp_path, snap(seen, std=0.012), snap((0.5, -0.2, 0.02), tcp_z=0.05),
                [observe(seen, std=0.012), grasp(seen), close(0.0004)], code="grasp.missed", leaf="CloseOnObject")
    d = diagnose(session(), ev)
    assert d.cause == "perception_error" and d.category == "perception"
    assert d.facts["perceived_std_m"] == pytest.approx(0.012) and d.facts["missed_grasp"] is True
    assert "1.2 cm" in d.summary
    assert "evidence/s/trace.jsonl" in d.evidence and "evidence/s/initial.yaml" in d.evidence


def test_a_missed_grasp_where_the_object_is_now_seen_elsewhere_is_a_stale_observation(tmp_path):
    seen = (0.5, -0.2, 0.02)
    ev = bundle(tmp_path, snap(seen), snap((0.5, -0.15, 0.02), tcp_z=0.04),
                [observe(seen), grasp(seen), close(0.0003)], code="grasp.missed", leaf="CloseOnObject")
    d = diagnose(session(), ev)
    assert d.cause == "object_moved"
    assert d.facts["moved_since_observation_m"] == pytest.approx(0.05, abs=1e-4)


def test_an_opening_near_zero_after_close_with_consistent_perception_is_a_missed_grasp(tmp_path):
    # no runtime error code at all: the gripper closed to 0.3 mm, the cube is still seen where the grasp aimed
    at = (0.54, -0.2, 0.02)
    ev = bundle(tmp_path, snap(at), snap((0.545, -0.2, 0.02)), [observe(at), grasp(at), close(0.0003)],
                status="completed")
    d = diagnose(session(), ev)
    assert d.cause == "grasp_missed" and d.facts["close_opening_m"] == 0.0003


def test_closed_on_the_object_then_lost_it_is_a_slip(tmp_path):
    at = (0.5, -0.2, 0.02)
    ev = bundle(tmp_path, snap(at), snap(at, tcp_z=0.17),
                [observe(at), grasp(at), close(0.019, 40.0)], code="grasp.slipped", leaf="CheckHolding")
    d = diagnose(session(), ev)
    assert d.cause == "object_slipped" and "CheckHolding" in d.summary


@pytest.mark.parametrize("samples,source", [
    # the fingers close a further 6 mm during the transfer: the object slid out between them
    ([proprio("lift", 0.019, 2.0), proprio("transfer", 0.019, 2.0), proprio("transfer", 0.013, 0.3)], "opening"),
    # the opening holds but the wrist load falls from 5 N to 1 N: the object dropped
    ([proprio("lift", 0.019, 5.0), proprio("transfer", 0.0185, 5.1), proprio("transfer", 0.0185, 1.0)], "wrist_load"),
])
def test_a_slip_is_seen_in_proprioception_alone(tmp_path, samples, source):
    at = (0.5, -0.2, 0.02)
    ev = bundle(tmp_path, snap(at), snap((0.5, -0.05, 0.02)), [observe(at), grasp(at), close(0.019, 40.0), *samples],
                status="completed")
    d = diagnose(session(skill="place", accept=PLACE_ACCEPT, params={"object": "cube", "region": "goal"}), ev)
    assert d.cause == "object_slipped" and d.facts["slip_source"] == source


def test_a_runtime_slip_record_is_a_slip(tmp_path):
    at = (0.5, -0.2, 0.02)
    slip = {"kind": "slip", "leaf": "Execute", "object": "cube", "stamp_s": 3.2, "opening_drop_m": 0.004,
            "load_drop_n": 1.1}
    ev = bundle(tmp_path, snap(at), snap(at), [observe(at), close(0.019, 40.0), slip], status="completed")
    d = diagnose(session(), ev)
    assert d.cause == "object_slipped" and d.facts["slip_source"] == "runtime"


def test_place_without_the_object_in_hand_is_an_unmet_precondition_that_reopens_the_pick(tmp_path):
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, -0.2, 0.02)),
                [observe((0.5, -0.2, 0.02))], code="grasp.slipped", leaf="CheckHolding")
    s = session(skill="place", accept=PLACE_ACCEPT, params={"object": "cube", "region": "goal"})
    d = diagnose(s, ev)
    assert d.cause == "precondition_unmet"
    assert RecoveryPlanner().plan(s, d) is None  # no upstream node acquires the object: retrying place is futile
    rev = RecoveryPlanner().plan(s, d, upstream="pick_cube")
    assert rev.strategy == "re_pick_upstream" and rev.reopen == "pick_cube" and rev.cause == "precondition_unmet"
    assert rev.parameters == {}  # the place itself is not retried with other parameters
    # a re-pick that did not help is not spent again
    assert RecoveryPlanner().plan(s, d, upstream="pick_cube", history=[_replanned(s, "precondition_unmet")]) is None


@pytest.mark.parametrize("code,leaf,cause,variant", [
    ("ik.unreachable", "SolveIK", "ik_unreachable", None),
    ("planning.failed", "PlanPath", "planning_failed", None),
    ("timing.failed", "Retime", "planning_failed", None),
    ("execution.tracking", "Execute", "collision", "planned"),
    ("execution.tracking", "Lift", "collision", "cartesian"),
    ("target.error", None, "runtime_error", None),
    ("contact.excessive_force", "PushObject", "collision", "contact"),
])
def test_runtime_error_codes_map_onto_the_taxonomy(tmp_path, code, leaf, cause, variant):
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, -0.2, 0.02)), code=code, leaf=leaf)
    d = diagnose(session(), ev)
    assert d.cause == cause and d.category == CAUSES[cause][0]
    assert d.facts.get("variant") == variant


def test_safety_events_and_timeouts_come_first(tmp_path):
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, -0.2, 0.02)),
                events=[{"code": "safety.workspace"}], code="execution.tracking", leaf="Execute", name="a")
    assert diagnose(session(), ev).cause == "safety_intervention"
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, -0.2, 0.02)), status="timed_out",
                code="timeout.execution", name="b")
    assert diagnose(session(), ev).cause == "timeout"


def test_replan_verdict_carries_diagnosis_and_the_first_rung_of_its_ladder(tmp_path):
    seen = (0.5, -0.23, 0.02)
    ev = bundle(tmp_path, snap(seen, std=0.01), snap((0.5, -0.2, 0.02), tcp_z=0.05),
                [observe(seen, std=0.01), grasp(seen), close(0.0)], code="grasp.missed", leaf="CloseOnObject")
    v = SessionVerifier().verify(session(), ev)
    assert v.verdict == "replan"
    assert [c.status for c in v.criteria] == ["unsatisfied", "unsatisfied"]
    assert all(c.evidence == ["evidence/s/initial.yaml", "evidence/s/terminal.yaml"] for c in v.criteria)
    assert v.diagnosis.cause == "perception_error"
    assert v.revision.strategy == "average_frames" and v.revision.step == 1
    # the hand was left 5 cm above the table: the child backs off and lets the scene settle first
    assert v.revision.parameters == {"observe_samples": 16, "backoff_m": 0.10, "settle_s": 0.5}
    assert set(v.evidence) >= {"evidence/s/trace.jsonl", "evidence/s/initial.yaml", "evidence/s/terminal.yaml"}


def _replanned(rec: SessionRecord, cause: str) -> SessionRecord:
    """``rec`` with a replan verdict for ``cause`` on its last attempt (as the coordinator leaves it)."""
    from phyagentos.protocol import Diagnosis

    verdict = Verdict(verdict="replan", reason="x", at=utc_now(),
                      diagnosis=Diagnosis(cause=cause, category=CAUSES[cause][0], summary="x"))
    return rec.model_copy(update={"attempts": [Attempt(number=1, started_at=utc_now(), verdict=verdict)]})


def test_same_cause_again_climbs_the_ladder_and_an_exhausted_ladder_is_failure(tmp_path):
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, -0.2, 0.02), tcp_z=0.3),
                [observe((0.5, -0.2, 0.02)), grasp((0.5, -0.2, 0.02)), close(0.019, 40.0)],
                code="grasp.slipped", leaf="CheckHolding")
    root = _replanned(session(), "object_slipped")
    child = session(params={"object": "cube", "grip_force_n": 40.0}, sid="r-pick_cube-2", parent=root.session_id)
    v = SessionVerifier(max_replans=3).verify(child, ev, history=[root])
    assert v.verdict == "replan" and v.revision.strategy == "firmest_grip_slower_transfer" and v.revision.step == 2
    assert v.revision.parameters == {"grip_force_n": 70.0, "transfer_velocity_scale": 0.5, "lift_velocity_scale": 0.15}
    grandchild = _replanned(child, "object_slipped")
    v = SessionVerifier(max_replans=3).verify(session(sid="r-pick_cube-3"), ev, history=[root, grandchild])
    assert v.verdict == "failure" and "no recovery strategy left for object_slipped" in v.reason


def test_a_step_memory_already_applied_is_skipped(tmp_path):
    from phyagentos.protocol import Diagnosis

    d = Diagnosis(cause="perception_error", category="perception", summary="x")
    already = session(params={"object": "cube", "observe_samples": 16})
    rev = RecoveryPlanner().plan(already, d)
    assert rev.strategy == "average_and_re_observe" and rev.parameters == {"observe_samples": 32, "reobserve_samples": 16}


def test_revisions_only_set_parameters_the_skill_declares():
    from phyagentos.protocol import Diagnosis

    hold = session(skill="hold", accept={"still": {}}, params={"duration_s": 1.0})
    d = Diagnosis(cause="criteria_unmet", category="verifier", summary="x")
    assert RecoveryPlanner().plan(hold, d) is None  # hold declares none of careful_retry's parameters
    assert set(LADDERS) >= {"perception_error", "object_moved", "grasp_missed", "object_slipped", "planning_failed",
                            "ik_unreachable", "collision/planned", "collision/cartesian", "timeout",
                            "goal_in_collision", "perception_unknown"}


def test_a_timeout_revision_lengthens_the_deadline():
    from phyagentos.protocol import Diagnosis, Limits

    s = session().model_copy(update={"limits": Limits(execution_timeout_s=60)})
    rev = RecoveryPlanner().plan(s, Diagnosis(cause="timeout", category="timeout", summary="x"))
    assert rev.strategy == "longer_deadline" and rev.limits == {"execution_timeout_s": 120.0}


class UprightJudge:
    """A judge of our own behind the Verifier interface: the object must end upright."""

    name = "upright"

    def judge(self, session, evidence):
        from phyagentos.agent.criteria import Criterion, CriterionOutcome

        c = Criterion(name="upright", args={"object": "cube"}, text="upright(object=cube)")
        cube = next(e for e in evidence.terminal["entities"] if e["name"] == "cube")
        ok = abs(cube["quat_wxyz"][0]) > 0.99
        return [CriterionOutcome(c, "satisfied" if ok else "unsatisfied", "upright" if ok else "tipped over",
                                 evidence.refs("terminal"))]


def test_judges_compose_behind_one_interface(tmp_path):
    from phyagentos.agent.verifier import PredicateVerifier

    true = (0.5, -0.2, 0.17)
    terminal = snap(true, holding=True)
    terminal["entities"][0]["quat_wxyz"] = [0.7, 0.7, 0, 0]
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), terminal, [close(0.019, 40.0)], status="completed")
    alone = SessionVerifier().verify(session(), ev)
    both = SessionVerifier([PredicateVerifier(), UprightJudge()]).verify(session(), ev)
    assert alone.verdict == "success"
    assert both.verdict == "replan" and both.verifier == "predicates+upright"
    assert [(c.name, c.status) for c in both.criteria][-1] == ("upright", "unsatisfied")


def test_a_push_that_closed_the_empty_hand_is_no_missed_grasp_and_pushes_again_slower(tmp_path):
    from phyagentos.protocol import Diagnosis

    # a push closes its empty hand to push with: the close names no object and grasps nothing by design
    push_close = {"kind": "gripper", "command": "close", "opening_m": 0.0002, "effort_n": 0.0, "stalled": False,
                  "closed_on_something": False}
    accept = {"inside": {"object": "cube", "region": "goal"}}
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, 0.1, 0.02)), [observe((0.5, -0.2, 0.02)), push_close],
                status="completed")
    push = session(skill="push", accept=accept, params={"object": "cube", "direction": [0, 1], "distance_m": 0.45})
    d = diagnose(push, ev)
    assert d.cause == "criteria_unmet" and d.cause != "grasp_missed"
    rev = RecoveryPlanner().plan(push, d)
    # the push again from where the cube stands now, at half the skill's default speed (0.05)
    assert rev.strategy == "push_again_slower" and rev.parameters == {"velocity_scale": 0.025}
    # the same close naming the object it takes is a missed grasp
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, -0.2, 0.02)),
                [observe((0.5, -0.2, 0.02)), {**push_close, "object": "cube"}], status="completed", name="t")
    assert diagnose(session(), ev).cause == "grasp_missed"
    # a pick whose criteria are unmet keeps the careful retry
    assert RecoveryPlanner().plan(session(), Diagnosis(cause="criteria_unmet", category="verifier",
                                                       summary="x")).strategy == "careful_retry"


def test_a_push_stopped_at_its_effort_limit_is_an_obstruction_not_a_software_error(tmp_path):
    """libero_goal_swap task 5: the plate dragged into the cream cheese met 40.1 N against the
    push's 40 N limit: a collision (execution), not a runtime error; no rung retries it yet (a
    push again from where the hand stopped starts its plan in contact)."""
    from phyagentos.protocol import Diagnosis

    push_close = {"kind": "gripper", "command": "close", "opening_m": 0.0002, "effort_n": 0.0, "stalled": False,
                  "closed_on_something": False}
    accept = {"inside": {"object": "cube", "region": "goal"}}
    ev = bundle(tmp_path, snap((0.5, -0.2, 0.02)), snap((0.5, -0.1, 0.02)), [observe((0.5, -0.2, 0.02)), push_close],
                code="contact.excessive_force", leaf="PushObject")
    push = session(skill="push", accept=accept, params={"object": "cube", "direction": [0, 1], "distance_m": 0.45})
    d = diagnose(push, ev)
    assert (d.cause, d.category, d.facts["variant"]) == ("collision", "execution", "contact")
    assert RecoveryPlanner().plan(push, d) is None
    # the push left short by a completed push keeps its rung
    assert RecoveryPlanner().plan(push, Diagnosis(cause="criteria_unmet", category="verifier",
                                                  summary="x")).strategy == "push_again_slower"
