"""The error-code taxonomy: every attributed failure is ``<family>.<detail>``.

A code names *what* ended an attempt or a session, so a verdict, a benchmark report
or an operator can tell a safety stop from a policy stall from a crashed runner.
Codes are stored in ``Attempt.error.code`` and ``SessionResult.error.code``; the
human reference is ``docs/ERRORS.md`` (a test keeps the two in step).

Each family belongs to one category of the paper's error taxonomy (perception,
policy, adapter, execution, timeout, safety, verifier, plus the runtime's own
preflight, target, heartbeat, cancelled and runtime families). A real arm's bus faults
(``bus.*``) count as ``target``; a real arm's calibration problems (``calibration.*``)
are found before anything moves and count as ``preflight``.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

__all__ = [
    "FAMILIES",
    "CODES",
    "family_of",
    "category_of",
    "is_known",
    # runtime-plane codes written by the supervisor and runner
    "TIMEOUT_QUEUE",
    "TIMEOUT_PREFLIGHT",
    "TIMEOUT_EXECUTION",
    "HEARTBEAT_RUNNER",
    "HEARTBEAT_TARGET",
    "HEARTBEAT_POLICY",
    "CANCELLED_OPERATOR",
    "CANCELLED_ESTOP",
    "CANCELLED_SHUTDOWN",
    "RUNTIME_RUNNER_DIED",
    "RUNTIME_LEASE_EXPIRED",
    "RUNTIME_ERROR",
    "TARGET_ERROR",
]

#: family -> (category, meaning)
FAMILIES: Mapping[str, tuple[str, str]] = MappingProxyType({
    "preflight": ("preflight", "compatibility preflight rejected the session before any target access"),
    "adapter": ("adapter", "an adapter or action bridge refused a conversion (malformed input is never repaired)"),
    "bridge": ("adapter", "an action bridge's declared parameters are invalid"),
    "policy": ("policy", "the policy server was unreachable, stalled, disconnected or answered malformed data"),
    "target": ("target", "the target failed to build, observe or execute a command"),
    "safety": ("safety", "the SafetyGuard rejected, halted or clamped a command"),
    "timeout": ("timeout", "a session time limit was exceeded"),
    "heartbeat": ("heartbeat", "a component stopped sending heartbeats"),
    "cancelled": ("cancelled", "the session was cancelled"),
    "verifier": ("verifier", "the verifier could not judge the evidence"),
    "runtime": ("runtime", "the runtime itself failed (runner process, lease, internal error)"),
    "perception": ("perception", "an observation did not contain what the skill needs"),
    "ik": ("execution", "inverse kinematics did not reach the pose"),
    "planning": ("execution", "no collision-free path was found"),
    "timing": ("execution", "time parameterisation failed"),
    "motion": ("execution", "a motion computation failed"),
    "execution": ("execution", "the target did not follow the commanded motion"),
    "grasp": ("execution", "the grasp missed or the object slipped"),
    "skill": ("execution", "the skill's behaviour tree is inconsistent"),
    "bus": ("target", "a real arm's servo bus or its bus guard stopped the arm (silent servo, corrupt packets, "
                      "overload, stall, out-of-range reading, a goal outside the calibrated limits) or could not be "
                      "opened; the arm was stopped by its declared stop policy"),
    "calibration": ("preflight", "a real arm's calibration file is missing, malformed or does not match its bus"),
})

TIMEOUT_QUEUE = "timeout.queue"
TIMEOUT_PREFLIGHT = "timeout.preflight"
TIMEOUT_EXECUTION = "timeout.execution"
HEARTBEAT_RUNNER = "heartbeat.runner"
HEARTBEAT_TARGET = "heartbeat.target"
HEARTBEAT_POLICY = "heartbeat.policy"
CANCELLED_OPERATOR = "cancelled.operator"
CANCELLED_ESTOP = "cancelled.estop"
CANCELLED_SHUTDOWN = "cancelled.shutdown"
RUNTIME_RUNNER_DIED = "runtime.runner_died"
RUNTIME_LEASE_EXPIRED = "runtime.lease_expired"
RUNTIME_ERROR = "runtime.error"
TARGET_ERROR = "target.error"

#: Codes with a fixed meaning. Families may hold further codes (e.g. each
#: ``preflight.*`` rejection item); those are documented with their family.
CODES: Mapping[str, str] = MappingProxyType({
    TIMEOUT_QUEUE: "the session stayed pending longer than limits.queue_timeout_s after submit",
    TIMEOUT_PREFLIGHT: "compatibility preflight took longer than limits.preflight_timeout_s (the runner was stopped)",
    TIMEOUT_EXECUTION: "the skill ran longer than limits.execution_timeout_s",
    HEARTBEAT_RUNNER: "the SessionRunner's heartbeat was older than limits.heartbeat_timeout_s",
    HEARTBEAT_TARGET: "the target's heartbeat was older than limits.heartbeat_timeout_s",
    HEARTBEAT_POLICY: "the policy's heartbeat was older than limits.heartbeat_timeout_s",
    CANCELLED_OPERATOR: "a cancel signal in RUNTIME_SIGNAL.md",
    CANCELLED_ESTOP: "an e-stop signal in RUNTIME_SIGNAL.md halted the session",
    CANCELLED_SHUTDOWN: "the supervisor was asked to stop (SIGINT/SIGTERM) while the session was actuating",
    RUNTIME_RUNNER_DIED: "the runner process died during actuation; outcome unknown, judged from a fresh observation",
    RUNTIME_LEASE_EXPIRED: "the supervisor holding the lease stopped renewing it; outcome unknown, judged from a fresh observation",
    RUNTIME_ERROR: "an unexpected error inside the runtime (traceback in the message)",
    TARGET_ERROR: "the target raised an error",
})


def family_of(code: str) -> str:
    """The family of ``code`` (text before the first dot)."""
    return code.split(".", 1)[0]


def is_known(code: str) -> bool:
    """True when ``code`` is ``<known family>.<detail>``."""
    family, _, detail = code.partition(".")
    return family in FAMILIES and bool(detail)


def category_of(code: str) -> str:
    """The taxonomy category of ``code`` (``'unknown'`` for an unknown family)."""
    entry = FAMILIES.get(family_of(code))
    return entry[0] if entry else "unknown"
