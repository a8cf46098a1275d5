"""The session statechart: legal paths, illegal transitions, persistence, restore."""

from __future__ import annotations

import pytest

from phyagentos.errors import LifecycleError
from phyagentos.protocol import SessionRecord
from phyagentos.protocol.lifecycle import ACTIVE_STATES, LIFECYCLE_EVENTS, SessionLifecycle, utc_now


def make_record(state: str = "pending") -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id="r1-pick-1", run_id="r1", node="pick", skill="pick", target="franka_tabletop",
                         state=state, created_at=now, updated_at=now)


def test_happy_path_reaches_succeeded_and_records_every_transition():
    saved = []
    lc = SessionLifecycle(make_record(), persist=lambda r: saved.append(r.state))
    for event in ("claim", "preflight", "start", "finish", "submit", "verify", "succeed"):
        lc.fire(event)
    assert lc.state == "succeeded" and lc.is_terminal
    assert saved == ["claimed", "preflight_checking", "running", "finalizing", "awaiting_verification", "verifying", "succeeded"]
    assert [t.dest for t in lc.record.transitions] == saved
    assert lc.record.transitions[0].source == "pending"


@pytest.mark.parametrize("state", ACTIVE_STATES)
def test_cancel_and_timeout_are_declared_once_on_active_and_apply_to_every_child(state):
    lc = SessionLifecycle(make_record(state))
    assert lc.fire("cancel") == "cancelling"
    assert lc.fire("cancelled") == "cancelled"
    lc = SessionLifecycle(make_record(state))
    assert lc.fire("time_out") == "timed_out"


@pytest.mark.parametrize(
    "state,event",
    [("pending", "start"), ("pending", "succeed"), ("claimed", "verify"), ("running", "claim"),
     ("succeeded", "cancel"), ("failed", "claim"), ("rejected", "start"), ("awaiting_verification", "finish")],
)
def test_illegal_transition_raises_and_names_allowed_events(state, event):
    lc = SessionLifecycle(make_record(state))
    with pytest.raises(LifecycleError) as info:
        lc.fire(event)
    assert state in str(info.value) and event in str(info.value)
    assert lc.state == state and lc.record.transitions == []


def test_unknown_event_lists_valid_events():
    lc = SessionLifecycle(make_record())
    with pytest.raises(LifecycleError, match="valid events: .*claim"):
        lc.fire("teleport")
    assert set(LIFECYCLE_EVENTS) >= {"claim", "cancel", "time_out", "outcome_unknown", "release"}


def test_crash_during_actuation_goes_to_verification_not_back_to_pending():
    lc = SessionLifecycle(make_record("running"))
    with pytest.raises(LifecycleError):
        lc.fire("release")
    assert lc.fire("outcome_unknown") == "awaiting_verification"


def test_lease_lost_before_actuation_returns_to_pending():
    for state in ("claimed", "preflight_checking"):
        assert SessionLifecycle(make_record(state)).fire("release") == "pending"


def test_restored_lifecycle_continues_from_the_persisted_state():
    rec = make_record()
    lc = SessionLifecycle(rec)
    lc.fire("claim")
    lc.fire("preflight")
    restored = SessionLifecycle(SessionRecord.model_validate(rec.model_dump()))
    assert restored.state == "preflight_checking"
    assert restored.fire("start") == "running"


def test_replan_verdict_waits_for_the_child_then_is_terminal():
    lc = SessionLifecycle(make_record("verifying"))
    assert lc.fire("replan") == "awaiting_replan"
    assert not lc.is_terminal
    assert lc.fire("replanned") == "replanned" and lc.is_terminal
