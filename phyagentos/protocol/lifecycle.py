"""Session lifecycle as a hierarchical ``transitions`` statechart.

The states follow the design notes' session lifecycle (docs/ARCHITECTURE.md). Everything between a claim and a verdict lives under
an ``active`` parent, so ``cancel``, ``time_out`` and ``abort`` are declared once
for all of its children::

    pending ─claim─▶ active[claimed ─preflight─▶ preflight_checking ─start─▶ running
                     ─finish─▶ finalizing ─submit─▶ awaiting_verification
                     ─verify─▶ verifying] ─succeed/fail/replan─▶ succeeded/failed/awaiting_replan
    awaiting_replan ─replanned─▶ replanned
    active ─cancel─▶ cancelling ─cancelled─▶ cancelled
    active ─time_out─▶ timed_out        active ─abort─▶ failed
    preflight_checking ─reject─▶ rejected
    claimed|preflight_checking ─release─▶ pending          (lease lost before actuation)
    running|finalizing ─outcome_unknown─▶ awaiting_verification (crash during actuation:
                                                           observe and judge, never re-run)

Every transition is appended to the record's ``transitions`` list and handed to a
``persist`` callback, so the file on disk never lags the machine.

The chart is built once per process, when this module is imported, and shared: a lifecycle holds
only its session's state, and firing an event sets the chart's one model to that state,
triggers the event and reads the new state back, under a lock. Building a
``HierarchicalMachine`` per session cost 1.5 ms on a 2-core CI machine, and every
session write that fires an event (claim, start, submit, verdict) did so; the shared
chart fires in 0.2 ms.
"""

from __future__ import annotations

import logging
import threading
from datetime import datetime
from typing import Callable, cast

from transitions import MachineError
from transitions.extensions import HierarchicalMachine

from phyagentos.errors import LifecycleError

from .schemas import (
    TERMINAL_STATES,
    ErrorInfo,
    SessionRecord,
    SessionResult,
    SessionState,
    TransitionRecord,
    utc_now_iso,
)

__all__ = ["SessionLifecycle", "LIFECYCLE_EVENTS", "ACTIVE_STATES", "utc_now"]

logger = logging.getLogger(__name__)

ACTIVE_STATES = (
    "claimed",
    "preflight_checking",
    "running",
    "finalizing",
    "awaiting_verification",
    "verifying",
)

_STATES = [
    "pending",
    {"name": "active", "children": list(ACTIVE_STATES)},
    "cancelling",
    "awaiting_replan",
    *TERMINAL_STATES,
]

# (event, source, dest); names without "active_" are top-level states.
_TRANSITIONS = [
    ("claim", "pending", "active_claimed"),
    ("release", ["active_claimed", "active_preflight_checking"], "pending"),
    ("preflight", "active_claimed", "active_preflight_checking"),
    ("reject", "active_preflight_checking", "rejected"),
    ("start", "active_preflight_checking", "active_running"),
    ("finish", "active_running", "active_finalizing"),
    ("submit", "active_finalizing", "active_awaiting_verification"),
    ("outcome_unknown", ["active_running", "active_finalizing"], "active_awaiting_verification"),
    ("verify", "active_awaiting_verification", "active_verifying"),
    ("succeed", "active_verifying", "succeeded"),
    ("fail", "active_verifying", "failed"),
    ("replan", "active_verifying", "awaiting_replan"),
    ("replanned", "awaiting_replan", "replanned"),
    ("cancel", ["pending", "active"], "cancelling"),
    ("cancelled", "cancelling", "cancelled"),
    ("time_out", ["pending", "active", "cancelling"], "timed_out"),
    ("abort", ["active", "cancelling"], "failed"),
]

LIFECYCLE_EVENTS = tuple(sorted({t[0] for t in _TRANSITIONS}))
#: Every state a record can be in (the chart's leaves).
_RECORD_STATES = ("pending", *ACTIVE_STATES, *(s for s in _STATES[2:] if isinstance(s, str)))


utc_now = utc_now_iso  # one clock format for every protocol timestamp


def _parse_ts(value: str) -> datetime:
    return datetime.fromisoformat(value[:-1] + "+00:00" if value.endswith("Z") else value)


def _machine_state(state: str) -> str:
    return f"active_{state}" if state in ACTIVE_STATES else state


def _record_state(machine_state: str) -> SessionState:
    """The SESSIONS.md state of a chart state (the chart's leaves are the session states)."""
    return cast(SessionState, machine_state.removeprefix("active_"))


class _Stepper:
    """The shared chart's one model: set to a session's state, fired, read back."""

    _hsm_state: str
    trigger: Callable[[str], bool]  # added by the HierarchicalMachine


#: The process's session statechart and its one model, shared by every lifecycle.
_STEPPER = _Stepper()
_CHART = HierarchicalMachine(
    model=_STEPPER,
    states=_STATES,
    transitions=[list(t) for t in _TRANSITIONS],
    initial="pending",
    auto_transitions=False,
    model_attribute="_hsm_state",
)
#: Guards the chart and its model (two threads of a process fire events).
_CHART_LOCK = threading.Lock()


class SessionLifecycle:
    """The statechart of one session, bound to its :class:`SessionRecord`.

    Args:
        record: the session; its ``state`` is the machine's initial state, so a
            lifecycle restored from disk continues where it stopped.
        persist: called with the record after every transition (typically
            ``Workspace.save_session``). Keyword-only because skipping it loses state.

    Raises:
        LifecycleError: on an unknown state in the record or an illegal event;
            the message names the current state and the events valid from it.
    """

    def __init__(self, record: SessionRecord, *, persist: Callable[[SessionRecord], None] | None = None):
        self.record = record
        self._persist = persist
        if record.state not in _RECORD_STATES:
            raise LifecycleError(f"session {record.session_id}: unknown state {record.state!r}; "
                                 f"valid states: {', '.join(_RECORD_STATES)}")
        self._hsm_state = _machine_state(record.state)

    def _result(self, reason: str, error: ErrorInfo | None = None) -> SessionResult:
        """Terminal summary: status, last verdict, reason and claim-to-end wall time."""
        rec = self.record
        attempt = rec.attempts[-1] if rec.attempts else None
        verdict = attempt.verdict if attempt else None
        first = rec.transitions[0].at if rec.transitions else rec.created_at
        duration = (_parse_ts(rec.updated_at) - _parse_ts(first)).total_seconds()
        return SessionResult(
            status=self.state,
            verdict=verdict.verdict if verdict else None,
            reason=reason or (verdict.reason if verdict else ""),
            duration_s=max(0.0, duration),
            evidence=attempt.evidence if attempt else None,
            error=error,
        )

    @property
    def state(self) -> SessionState:
        """Current lifecycle state name as stored in SESSIONS.md (e.g. ``running``)."""
        return _record_state(self._hsm_state)

    @property
    def is_terminal(self) -> bool:
        return self.state in TERMINAL_STATES

    def allowed_events(self) -> list[str]:
        """Events that are legal from the current state, sorted."""
        with _CHART_LOCK:
            return sorted(_CHART.get_triggers(self._hsm_state))

    def fire(self, event: str, *, reason: str = "", error: ErrorInfo | None = None) -> str:
        """Apply ``event``, append it to ``record.transitions`` and persist.

        ``error`` (a code from docs/ERRORS.md) is kept in ``record.result`` when the
        event ends the session, so every terminal state carries its attribution.

        Returns:
            The new state name.

        Raises:
            LifecycleError: if ``event`` is unknown or illegal in the current state.
        """
        if event not in LIFECYCLE_EVENTS:
            raise LifecycleError(f"unknown lifecycle event {event!r}; valid events: {', '.join(LIFECYCLE_EVENTS)}")
        source = self.state
        try:
            with _CHART_LOCK:
                _CHART.set_state(self._hsm_state, model=_STEPPER)
                _STEPPER.trigger(event)
                self._hsm_state = _STEPPER._hsm_state
        except MachineError:
            raise LifecycleError(
                f"session {self.record.session_id}: illegal transition {event!r} from state {source!r}; "
                f"allowed from {source!r}: {', '.join(self.allowed_events()) or 'none (terminal)'}"
            ) from None
        now = utc_now()
        self.record.state = self.state
        self.record.updated_at = now
        self.record.transitions.append(
            TransitionRecord(at=now, source=source, dest=self.state, event=event if not reason else f"{event}: {reason}")
        )
        if self.is_terminal:
            self.record.result = self._result(reason, error)
        logger.debug("session %s: %s -(%s)-> %s", self.record.session_id, source, event, self.state)
        if self._persist is not None:
            self._persist(self.record)
        return self.state
