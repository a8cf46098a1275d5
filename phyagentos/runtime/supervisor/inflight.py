"""The session a supervisor is handling, and its runtime phase as a ``transitions`` machine.

The session file's lifecycle (:mod:`phyagentos.protocol.lifecycle`) says where the session
is for everyone; the phase here says what *this supervisor* is waiting for while it holds
the lease. Four phases, three events::

    preflight --start--> running --runner_lost--> recover_wait --recover--> recovering
                                                        ^                        |
                                                        +-------runner_lost------+

``preflight``: the runner checks compatibility (nothing moves); ``running``: the runner
actuates (heartbeats and the execution deadline are watched); ``recover_wait``: the
runner was killed or died while the target may have moved, and a runner must safe-stop
the target before the session can end (retried until a runner holds the target);
``recovering``: that safe stop is under way. A session taken over from an expired lease
starts in ``recover_wait``. Ends (verdict pending, rejected, released, cancelled) leave
the phase where it was: the supervisor drops the object.

One machine serves every in-flight session of the process (as the session statechart
does): building a ``Machine`` per claim would cost more than the claim's own write.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any

from transitions import Machine, MachineError

from phyagentos.errors import SupervisorError

__all__ = ["InflightSession", "PHASES", "PHASE_EVENTS"]

#: The runtime phases of an in-flight session, in the order a session normally meets them.
PHASES: tuple[str, ...] = ("preflight", "running", "recover_wait", "recovering")
#: ``(event, sources, destination)`` of the phase machine.
PHASE_EVENTS: tuple[tuple[str, tuple[str, ...], str], ...] = (
    ("start", ("preflight",), "running"),
    ("runner_lost", ("running", "recovering"), "recover_wait"),
    ("recover", ("recover_wait",), "recovering"),
)


class _Stepper:
    """The shared machine's one model: set to a session's phase, fired, read back."""

    phase: str


_STEPPER = _Stepper()
_MACHINE = Machine(model=_STEPPER, states=list(PHASES), initial="preflight", auto_transitions=False,
                   model_attribute="phase",
                   transitions=[{"trigger": e, "source": list(s), "dest": d} for e, s, d in PHASE_EVENTS])
_LOCK = threading.Lock()


@dataclass
class InflightSession:
    """The session this supervisor holds the lease of, and where it is in its runtime phase.

    Attributes:
        session_id, target, token: the session, its target and the lease token every
            write presents.
        limits: the session's :class:`~phyagentos.protocol.Limits` (timeouts in s).
        phase: one of :data:`PHASES`; changed only by :meth:`fire`.
        started: ``time.monotonic()`` at the claim or take-over (s).
        deadline: preflight, execution or safe-stop deadline (monotonic s), by phase.
        go_at: when ``go`` was sent (monotonic s).
        renew_at: next lease renewal (monotonic s).
        cancel: ``(code, reason)`` asked by a signal or a shutdown.
        kill_at: the runner is killed at this time if it has not stopped (monotonic s).
        kill_end: ``(status, code, message)`` the session ends with after a forced stop.
        end: ``(status, code, message)`` the safe stop writes.
        finished: the runner reported its skill finished (it writes the evidence now).
        recover_attempts: safe-stop jobs tried.
    """

    session_id: str
    target: str
    token: str
    limits: Any
    phase: str = "preflight"
    started: float = field(default_factory=time.monotonic)
    deadline: float | None = None
    go_at: float | None = None
    renew_at: float = 0.0
    cancel: tuple[str, str] | None = None
    kill_at: float | None = None
    kill_end: tuple[str, str, str] | None = None
    end: tuple[str, str, str] | None = None
    finished: bool = False
    recover_attempts: int = 0

    def __post_init__(self) -> None:
        if self.phase not in PHASES:
            raise SupervisorError(f"session {self.session_id}: unknown phase {self.phase!r}; "
                                  f"valid phases: {', '.join(PHASES)}")

    def fire(self, event: str) -> str:
        """Apply ``event`` (one of :data:`PHASE_EVENTS`) and return the new phase.

        Raises:
            SupervisorError: ``event`` is unknown or not valid from the current phase;
                the message names the phase and the events valid from it.
        """
        with _LOCK:
            _STEPPER.phase = self.phase
            try:
                _MACHINE.events[event].trigger(_STEPPER)
            except (KeyError, MachineError):
                valid = [e for e, sources, _ in PHASE_EVENTS if self.phase in sources]
                raise SupervisorError(f"session {self.session_id}: event {event!r} is not valid in phase "
                                      f"{self.phase!r}; valid events: {', '.join(valid) or 'none'}") from None
            self.phase = _STEPPER.phase
        return self.phase
