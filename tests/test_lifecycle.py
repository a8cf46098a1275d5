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


def test_lifecycles_fired_from_many_threads_at_once_each_follow_their_own_session():
    # The statechart is shared by the process's lifecycles: events fired concurrently on
    # different sessions must never see or move one another's state.
    import sys
    import threading

    paths = {
        "happy": ["claim", "preflight", "start", "finish", "submit", "verify", "succeed"],
        "rejected": ["claim", "preflight", "reject"],
        "cancelled": ["claim", "preflight", "start", "cancel", "cancelled"],
        "released": ["claim", "preflight", "release", "claim", "preflight", "start", "outcome_unknown", "verify",
                     "fail"],
    }
    ends = {"happy": "succeeded", "rejected": "rejected", "cancelled": "cancelled", "released": "failed"}
    failures: list[str] = []

    def worker(kind: str) -> None:
        for _ in range(150):
            try:
                lifecycle = SessionLifecycle(make_record())
                for event in paths[kind]:
                    lifecycle.fire(event)
            except Exception as exc:  # noqa: BLE001 - any error in a thread is a failure here
                failures.append(f"{kind}: {type(exc).__name__}: {exc}")
                return
            events = [t.event.split(":")[0] for t in lifecycle.record.transitions]
            if lifecycle.state != ends[kind] or events != paths[kind]:
                failures.append(f"{kind}: ended {lifecycle.state} after {events}")
                return

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        threads = [threading.Thread(target=worker, args=(kind,)) for kind in paths]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    finally:
        sys.setswitchinterval(interval)
    assert failures == []
