"""RUNTIME_SIGNAL.md semantics: signals are appended, folded into a state, acknowledged.

Operators and the Agent plane send signals through one validated path
(:meth:`Workspace.send_signal`, ``phyagentos signal ...``); nobody edits the list by hand.
A signal is never rewritten or removed while it still matters. Supervisors *fold* the
list in order into a :class:`SignalState`:

- ``pause`` / ``resume``: the latest one decides whether supervisors claim new sessions;
- ``estop`` / ``clear_estop``: the latest one decides whether actuation is allowed;
  an e-stop halts every running session now and blocks new actuation until cleared;
- ``cancel`` with a ``session_id`` cancels that session whenever a supervisor meets it
  (pending, running, or after a lease recovery); without one it cancels every session
  submitted before the signal.

Because the state is a fold, handling is idempotent: a restarted supervisor replays the
list and ends in the same state without acting twice on a finished session. What each
supervisor did is appended to ``handled`` (:class:`~phyagentos.protocol.schemas.SignalAck`).
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass, field
from datetime import datetime, timezone

from .schemas import Signal

__all__ = ["SIGNAL_KINDS", "SignalState", "fold_signals", "new_signal_id"]

SIGNAL_KINDS: tuple[str, ...] = ("cancel", "pause", "resume", "estop", "clear_estop")


def new_signal_id() -> str:
    """A sortable unique id such as ``sig-20261121T152233.123456-9f3a``."""
    return "sig-" + datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S.%f") + "-" + secrets.token_hex(2)


@dataclass
class SignalState:
    """The runtime state implied by a list of signals (see the module docstring).

    Attributes:
        paused: supervisors claim no new sessions.
        estop: the e-stop signal in force, or None.
        cancels: session id -> the cancel signal addressing it.
        cancel_all: cancel signals without a session id (each covers sessions
            submitted at or before its ``issued_at``).
    """

    paused: bool = False
    pause_signal: Signal | None = None
    estop: Signal | None = None
    cancels: dict[str, Signal] = field(default_factory=dict)
    cancel_all: list[Signal] = field(default_factory=list)

    @property
    def estopped(self) -> bool:
        return self.estop is not None

    def apply(self, signal: Signal) -> None:
        """Fold one more signal in."""
        if signal.kind == "pause":
            self.paused, self.pause_signal = True, signal
        elif signal.kind == "resume":
            self.paused, self.pause_signal = False, signal
        elif signal.kind == "estop":
            self.estop = signal
        elif signal.kind == "clear_estop":
            self.estop = None
        elif signal.kind == "cancel":
            if signal.session_id is None:
                self.cancel_all.append(signal)
            else:
                self.cancels.setdefault(signal.session_id, signal)

    def cancel_for(self, session_id: str, created_at: str) -> Signal | None:
        """The cancel signal that applies to a session submitted at ``created_at``, if any."""
        hit = self.cancels.get(session_id)
        if hit is not None:
            return hit
        created = _ts(created_at)
        for signal in self.cancel_all:
            if created <= _ts(signal.issued_at):
                return signal
        return None


def _ts(value: str) -> datetime:
    return datetime.fromisoformat(value[:-1] + "+00:00" if value.endswith("Z") else value)


def fold_signals(signals: list[Signal]) -> SignalState:
    """Fold ``signals`` in list order into a :class:`SignalState`."""
    state = SignalState()
    for signal in signals:
        state.apply(signal)
    return state
