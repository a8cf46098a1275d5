"""SessionVerifier: predicates judged from evidence files, never from return codes."""

from __future__ import annotations

import pytest
import yaml

from phyagentos.agent.criteria import PREDICATES, evaluate, parse_criteria
from phyagentos.agent.verifier import SessionVerifier, load_evidence
from phyagentos.errors import VerifierError
from phyagentos.protocol import SessionRecord
from phyagentos.protocol.lifecycle import utc_now


def entity(name, position, size=(0.02, 0.02, 0.02), kind="object", **attributes):
    return {"name": name, "kind": kind, "position": list(position), "quat_wxyz": [1, 0, 0, 0], "size": list(size),
            "attributes": attributes}


REGION = entity("goal", (0.5, 0.25, 0.0005), size=(0.08, 0.08, 0.0005), kind="region")


def snapshot(cube_pos, *, holding=False, q=(0.0,) * 7):
    rel = [{"subject": "gripper", "relation": "holding", "object": "cube"}] if holding else []
    return {"entities": [entity("cube", cube_pos), REGION, entity("panda", (0, 0, 0), kind="robot", joint_positions=list(q))],
            "relations": rel}


def write_bundle(directory, initial, terminal, *, events=(), outcome=None):
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "initial.yaml").write_text(yaml.safe_dump(initial))
    (directory / "terminal.yaml").write_text(yaml.safe_dump(terminal))
    (directory / "events.yaml").write_text(yaml.safe_dump(list(events)))
    files = {"initial": "initial.yaml", "terminal": "terminal.yaml", "events": "events.yaml"}
    (directory / "bundle.yaml").write_text(yaml.safe_dump({"session_id": "s", "files": files,
                                                           "outcome": outcome or {"status": "completed"}}))
    return load_evidence(directory)


def session(accept) -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id="r-place-1", run_id="r", node="place", skill="place", target="franka_tabletop",
                         accept=accept, created_at=now, updated_at=now)


PLACE_ACCEPT = {"inside": {"object": "cube", "region": "goal"}, "released": "cube"}


def test_object_resting_in_region_is_success(tmp_path):
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), snapshot((0.53, 0.22, 0.0205)))
    verdict = SessionVerifier().verify(session(PLACE_ACCEPT), ev)
    assert verdict.verdict == "success"
    assert [c.status for c in verdict.criteria] == ["satisfied", "satisfied"]
    assert all(c.evidence for c in verdict.criteria)


def test_object_outside_region_is_replan_then_failure_when_budget_is_spent(tmp_path):
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), snapshot((0.5, 0.05, 0.02)))
    verifier = SessionVerifier(max_replans=2)
    first = verifier.verify(session(PLACE_ACCEPT), ev, lineage_depth=0)
    assert first.verdict == "replan" and "not inside" in first.criteria[0].reason
    last = verifier.verify(session(PLACE_ACCEPT), ev, lineage_depth=2)
    assert last.verdict == "failure" and "after 2 replans" in last.reason


def test_completed_runtime_with_unmet_criteria_is_not_success(tmp_path):
    # the controller says "completed" but the cube never moved: evidence wins
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), snapshot((0.5, -0.2, 0.02)),
                      outcome={"status": "completed"})
    assert SessionVerifier().verify(session(PLACE_ACCEPT), ev).verdict != "success"


def test_cube_hovering_above_region_is_not_inside(tmp_path):
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), snapshot((0.5, 0.25, 0.12)))
    assert SessionVerifier().verify(session({"inside": {"object": "cube", "region": "goal"}}), ev).verdict == "replan"


def test_held_cube_is_not_inside_even_over_the_region(tmp_path):
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), snapshot((0.5, 0.25, 0.0205), holding=True))
    out = SessionVerifier().verify(session(PLACE_ACCEPT), ev)
    assert out.verdict == "replan"
    assert "still held" in out.criteria[0].reason


def test_missing_entity_is_unknown_another_view_then_failure(tmp_path):
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), {"entities": [], "relations": []})
    out = SessionVerifier().verify(session(PLACE_ACCEPT), ev)
    assert out.verdict == "replan" and out.criteria[0].status == "unknown"
    assert out.revision.strategy == "another_view" and out.diagnosis.cause == "perception_unknown"
    out = SessionVerifier(max_replans=1).verify(session(PLACE_ACCEPT), ev, lineage_depth=1)
    assert out.verdict == "failure" and out.diagnosis.cause == "perception_unknown"


def test_safety_event_turns_unmet_criteria_into_failure_not_replan(tmp_path):
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), snapshot((0.5, 0.0, 0.02)),
                      events=[{"code": "safety.workspace", "message": "tcp left the box"}])
    out = SessionVerifier().verify(session(PLACE_ACCEPT), ev)
    assert out.verdict == "failure" and "safety.workspace" in out.reason


def test_no_acceptance_criteria_never_counts_as_success(tmp_path):
    ev = write_bundle(tmp_path / "ev", snapshot((0.5, -0.2, 0.02)), snapshot((0.5, -0.2, 0.02)))
    out = SessionVerifier().verify(session({}), ev)
    assert out.verdict == "failure" and "return code" in out.reason


def test_lifted_and_holding_after_pick():
    initial, terminal = snapshot((0.5, -0.2, 0.02)), snapshot((0.5, -0.2, 0.17), holding=True)
    crits = parse_criteria({"holding": "cube", "lifted": {"object": "cube", "min_height": 0.05}})
    assert [evaluate(c, initial, terminal).status for c in crits] == ["satisfied", "satisfied"]
    low = snapshot((0.5, -0.2, 0.04), holding=True)
    assert evaluate(crits[1], initial, low).status == "unsatisfied"


def test_still_measures_joint_motion():
    (c,) = parse_criteria({"still": {"max_joint_motion_rad": 0.01}})
    assert evaluate(c, snapshot((0, 0, 0)), snapshot((0, 0, 0), q=(0.005,) * 7)).status == "satisfied"
    assert evaluate(c, snapshot((0, 0, 0)), snapshot((0, 0, 0), q=(0.0, 0.2, 0, 0, 0, 0, 0))).status == "unsatisfied"


def test_list_form_allows_a_predicate_twice():
    crits = parse_criteria([{"inside": {"object": "a", "region": "r"}}, {"inside": {"object": "b", "region": "r"}}])
    assert [c.args["object"] for c in crits] == ["a", "b"]


@pytest.mark.parametrize(
    "accept,message",
    [
        ({"levitating": "cube"}, "valid predicates: " + ", ".join(repr(p) for p in PREDICATES)),
        ({"inside": {"object": "cube"}}, "missing \\['region'\\]"),
        ({"inside": {"object": "cube", "region": "g", "colour": "red"}}, "unknown \\['colour'\\]"),
        ({"lifted": {"object": "cube", "min_height": "high"}}, "must be a number"),
        ("cube is placed", "accept must be a mapping or list"),
        (["holding"], "one-key mappings"),
    ],
)
def test_malformed_criteria_are_rejected_with_valid_choices(accept, message):
    with pytest.raises(VerifierError, match=message):
        parse_criteria(accept, where="graph.yaml:12")


def test_unreadable_bundle_is_a_verifier_error(tmp_path):
    with pytest.raises(VerifierError, match="bundle.yaml"):
        load_evidence(tmp_path / "nothing")
