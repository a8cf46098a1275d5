"""What a session's runtime phase is built from, as one comparable digest.

A runner prepares a session (acquires and checkpoints its target, observes the initial
world, builds the safety guard and the skill context) while the WatchdogSupervisor makes
the ``start`` transition durable, and starts ticking only on ``go`` (:mod:`.worker`).
The preparation is used only if the session the supervisor started is, in every field
the runtime phase reads, the one the runner prepared from: ``go`` carries the digest of
the started record and the runner compares it with its own (:func:`runtime_basis`). Any
difference (a hand-edited session file between preflight and start, a plan the
supervisor did not record as the runner produced it) discards the preparation and the
session is set up afresh from the file, as if nothing had been prepared.

The module imports nothing heavy: the supervisor's process computes the digest too.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

__all__ = ["RUNTIME_FIELDS", "runtime_basis"]

#: The session fields the runtime phase reads (the SessionRunner, the skill context,
#: the target pool, the evidence bundle's ``task.yaml``); the others (state, lease,
#: attempts, timestamps, verdicts) belong to the supervisor and the Agent.
RUNTIME_FIELDS = frozenset({"session_id", "run_id", "goal_graph", "node", "parent_session_id", "skill",
                            "skill_runtime", "target", "parameters", "accept", "limits", "scene", "seed",
                            "context", "recovery", "adapter_plan", "tool_manifest"})


def runtime_basis(record: Any) -> str:
    """SHA-256 (hex, 64 characters) of ``record``'s :data:`RUNTIME_FIELDS` as canonical
    JSON (``model_dump(mode="json")``, keys sorted, floats as Python's shortest repr).

    Two records with the same basis give the runtime phase the same inputs; a record
    round-tripped through its session file keeps its basis (YAML and JSON both render
    floats with the shortest repr that reads back to the same double).

    Args:
        record: a :class:`~phyagentos.protocol.SessionRecord`.
    """
    data = record.model_dump(mode="json", include=set(RUNTIME_FIELDS))
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
