"""What an edge does about a session when it loses the agent, and which submits are current.

The edge keeps real-time authority: losing the link never touches a safety interlock (the
supervisor, its runner's limits and the local e-stop work on without the network).

- ``finish``: a running session runs on to its own end (its limits, its tree); the
  outcome waits in the edge's workspace and converges after the reconnect.
- ``halt_and_hold``: a running session is cancelled through the edge's own
  RUNTIME_SIGNAL.md ("link lost"): the runner stops actuating and the target holds where
  it is; the session ends ``cancelled``.

Either way **nothing starts** from a submit the edge cannot confirm is current: a
submit older than ``submit_ttl_s`` when it arrives is refused (``stale``) and nothing is
written, and a pending session is claimed only while the agent that submitted it is
present; one whose agent stays away longer than ``submit_ttl_s`` is cancelled unstarted.

E-stop is local first, always (``phyagentos signal WS estop`` at the edge, read by its
supervisor from its own files), and remote when connected (the agent's e-stop reaches
every edge present).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

__all__ = ["LINK_LOST_REASON", "STALE_REASON", "SubmitTicket", "submit_is_stale"]

LINK_LOST_REASON = "link lost: halt and hold (link_loss policy)"
STALE_REASON = "stale submit: its agent stayed away, never started"


@dataclass(frozen=True)
class SubmitTicket:
    """What an edge keeps of an accepted submit (ws/fleet/submits/<id>.json)."""

    session_id: str
    agent: str
    issued_at: float  # the agent's wall clock, s since the epoch
    accepted_at: float  # the edge's wall clock
    link_loss: str

    def to_json(self) -> dict:
        return dict(self.__dict__)


def submit_is_stale(issued_at: float, ttl_s: float, *, now: float | None = None) -> bool:
    """True if a submit issued at ``issued_at`` (epoch s) is older than ``ttl_s`` now
    (clocks of the fleet's machines are assumed NTP-synchronised to well under ``ttl_s``)."""
    now = time.time() if now is None else now
    return now - issued_at > ttl_s or issued_at - now > ttl_s
