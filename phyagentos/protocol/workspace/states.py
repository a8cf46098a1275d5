"""Session-state sets and helpers the parts of :class:`~phyagentos.protocol.Workspace` share."""

from __future__ import annotations

import re
from datetime import datetime

from ..schemas import SESSION_ID_PATTERN, TERMINAL_STATES

__all__ = ["LEASED_STATES", "WAITING_STATES", "TERMINAL", "SESSION_ID", "ts_key"]

#: States in which a supervisor holds the session's lease.
LEASED_STATES: tuple[str, ...] = ("claimed", "preflight_checking", "running", "finalizing", "cancelling")
#: Active states in which a session waits for someone (a supervisor or the Agent).
WAITING_STATES: tuple[str, ...] = ("pending", "awaiting_verification", "verifying", "awaiting_replan")
#: Terminal session states.
TERMINAL = frozenset(TERMINAL_STATES)
#: A valid session id (also the form of target names).
SESSION_ID = re.compile(SESSION_ID_PATTERN)


def ts_key(timestamp: str) -> datetime:
    """A sortable datetime of a protocol timestamp (ISO 8601, ``Z`` or an offset)."""
    return datetime.fromisoformat(timestamp[:-1] + "+00:00" if timestamp.endswith("Z") else timestamp)
