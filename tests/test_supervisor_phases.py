"""The in-flight session's runtime phases are an explicit machine: only its three events
move a session between its four phases, and anything else is refused with the valid events."""

from __future__ import annotations

import pytest

from phyagentos.errors import SupervisorError
from phyagentos.runtime.supervisor import PHASES, InflightSession


def _session(phase: str = "preflight") -> InflightSession:
    return InflightSession(session_id="s1", target="franka_tabletop", token="t", limits=None, phase=phase)


def test_a_session_goes_from_preflight_to_running_and_through_a_lost_runner_to_recovery():
    inf = _session()
    assert [inf.fire(e) for e in ("start", "runner_lost", "recover", "runner_lost", "recover")] == \
        ["running", "recover_wait", "recovering", "recover_wait", "recovering"]


@pytest.mark.parametrize(("phase", "event", "valid"), [
    ("preflight", "recover", "start"),
    ("running", "start", "runner_lost"),
    ("recover_wait", "runner_lost", "recover"),
    ("recovering", "start", "runner_lost"),
])
def test_an_event_not_valid_in_the_phase_is_refused_with_the_valid_events(phase, event, valid):
    inf = _session(phase)
    with pytest.raises(SupervisorError, match=rf"not valid in phase '{phase}'; valid events: {valid}$"):
        inf.fire(event)
    assert inf.phase == phase  # nothing moved


def test_an_unknown_phase_is_refused_when_the_session_is_made():
    with pytest.raises(SupervisorError, match="unknown phase 'finalizing'; valid phases: " + ", ".join(PHASES)):
        _session("finalizing")


def test_two_sessions_keep_their_own_phases():
    a, b = _session(), _session("recover_wait")
    a.fire("start")
    b.fire("recover")
    assert (a.phase, b.phase) == ("running", "recovering")
