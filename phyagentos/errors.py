"""Exception hierarchy: one root, one subclass per subsystem.

Every message says what was wrong, where (file and line for YAML inputs) and,
where there is a finite set, the valid choices.
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "PhyAgentOSError",
    "MissingExtraError",
    "RecordingError",
    "ViewError",
    "ProtocolError",
    "DocumentError",
    "LeaseError",
    "LockTimeout",
    "SessionExistsError",
    "GoalGraphError",
    "LifecycleError",
    "SkillError",
    "PreflightError",
    "TargetError",
    "MotionError",
    "IKError",
    "PlanningError",
    "TimingError",
    "VerifierError",
    "SafetyError",
    "ActionBridgeError",
    "PolicyError",
    "SupervisorError",
    "RenderError",
    "BenchError",
    "FleetError",
    "format_location",
    "format_choices",
]


def format_location(path: str | Path | None, line: int | None = None) -> str:
    """Return ``"path:line"`` (1-based line), ``"path"`` or ``""``."""
    if path is None:
        return ""
    return f"{path}:{line}" if line is not None else str(path)


def format_choices(choices) -> str:
    """Return the sorted valid choices as ``"'a', 'b'"`` for error messages."""
    return ", ".join(repr(c) for c in sorted(choices))


class PhyAgentOSError(Exception):
    """Root of every error PhyAgentOS raises on purpose.

    Its message never carries a credential: every string argument passes through
    :func:`phyagentos.untrusted.redact_secrets` (URL userinfo, ``key=``/``token=`` values,
    registered API keys), so no subsystem can leak one into a message, a log line or an
    MCP answer by quoting a URL or a setting.
    """

    def __init__(self, *args):
        from phyagentos.untrusted import redact_secrets  # noqa: PLC0415 - no import cycle at module load

        super().__init__(*(redact_secrets(a) if isinstance(a, str) else a for a in args))


class ProtocolError(PhyAgentOSError):
    """A protocol document or workspace could not be read, validated or written."""


class _Located(PhyAgentOSError):
    """Base of the located errors: a message prefixed with ``path:line``; keeps ``path`` and ``line``."""

    def __init__(self, message: str, *, path: str | Path | None = None, line: int | None = None):
        self.path = Path(path) if path is not None else None
        self.line = line
        from phyagentos.untrusted import redact_secrets  # noqa: PLC0415

        self.detail = redact_secrets(message)
        loc = format_location(path, line)
        super().__init__(f"{loc}: {message}" if loc else message)


class DocumentError(_Located, ProtocolError):
    """A protocol document is malformed; carries ``path`` and 1-based ``line``.

    The document on disk is never modified when this is raised.
    """


class LeaseError(ProtocolError):
    """A session write presented a lease token that is no longer current: another
    supervisor took the session over after this one's lease expired (fencing)."""


class SessionExistsError(ProtocolError):
    """A submit named a session id that is already in the workspace (active or archived);
    carries ``session_id`` and the ``path`` of the existing file."""

    def __init__(self, message: str, *, session_id: str, path: object) -> None:
        super().__init__(message)
        self.session_id = session_id
        self.path = path


class LockTimeout(ProtocolError, TimeoutError):
    """A workspace lock stayed held by another process or thread for longer than the
    caller's timeout (:meth:`~phyagentos.protocol.file_lock.WorkspaceLock.acquire`)."""


class GoalGraphError(_Located, PhyAgentOSError):
    """A goal graph is invalid; carries ``path`` and 1-based ``line`` when known."""


class LifecycleError(PhyAgentOSError):
    """An illegal session lifecycle transition was requested."""


class SkillError(_Located, PhyAgentOSError):
    """A skill manifest or behaviour tree is invalid (``path``/``line`` when known)."""


class PreflightError(PhyAgentOSError):
    """Compatibility preflight rejected a session (``items`` lists what is missing)."""

    def __init__(self, message: str, items: list | None = None):
        self.items = list(items or [])
        super().__init__(message)


class TargetError(PhyAgentOSError):
    """A target failed to build, observe, or execute a command.

    ``code`` is ``None`` for an ordinary failure (a session records ``target.error``) or an
    error code (``<family>.<detail>``, ``protocol/errorcodes``) when the target stopped
    itself for a reason it can name, e.g. ``bus.overload`` from a real arm's bus guard.
    """

    def __init__(self, message: str, *, code: str | None = None):
        self.code = code
        super().__init__(message)


class MotionError(PhyAgentOSError):
    """Root for IK, planning and time-parameterisation failures."""


class IKError(MotionError):
    """Inverse kinematics did not converge to the requested pose."""


class PlanningError(MotionError):
    """No collision-free joint-space path was found (or start/goal invalid)."""


class TimingError(MotionError):
    """Time parameterisation failed or produced a trajectory that is not collision free."""


class VerifierError(_Located, PhyAgentOSError):
    """Acceptance criteria are malformed or evidence is missing (``path``/``line`` when known)."""


class SafetyError(PhyAgentOSError):
    """A SafetyGuard check rejected a command (``code`` is the violation code)."""

    def __init__(self, message: str, *, code: str):
        self.code = code
        super().__init__(f"[{code}] {message}")


class ActionBridgeError(SafetyError):
    """An action bridge refused malformed input (``code`` is the violation code,
    ``bridge`` the bridge's name); bridges reject, they never repair silently."""

    def __init__(self, message: str, *, code: str, bridge: str):
        self.bridge = bridge
        super().__init__(f"action bridge {bridge!r}: {message}", code=code)


class PolicyError(PhyAgentOSError):
    """A policy server could not be reached, stalled, disconnected or answered
    malformed data (``code``: ``policy.unreachable``, ``policy.stalled``,
    ``policy.disconnected``, ``policy.error`` or ``policy.malformed``)."""

    def __init__(self, message: str, *, code: str):
        self.code = code
        super().__init__(f"[{code}] {message}")


class SupervisorError(PhyAgentOSError):
    """The WatchdogSupervisor could not claim, run, or write back a session."""


class RenderError(PhyAgentOSError):
    """A graph or image could not be rendered (no such run, Graphviz missing or failing)."""


class BenchError(PhyAgentOSError):
    """A benchmark could not run: bad suite definition, failed availability gate, or a
    worker that died; ``problems`` lists every diagnostic (empty for a single message)."""

    def __init__(self, message: str, *, problems: tuple[str, ...] = ()):
        self.problems = tuple(problems)
        detail = "".join(f"\n  - {p}" for p in self.problems)
        super().__init__(f"{message}{detail}")


class RecordingError(PhyAgentOSError):
    """A session recording is misconfigured (mode, camera, rate or size) or cannot be made."""


class ViewError(PhyAgentOSError):
    """``phyagentos view`` cannot start (bad host, port or workspace) or refused a request."""


class FleetError(_Located, PhyAgentOSError):
    """The fleet (phyagentos/fleet): a malformed fleet.yaml (with ``path``/``line``), a router
    or edge that cannot be reached, a target no edge owns, or a refused submit."""


class MissingExtraError(PhyAgentOSError):
    """An optional feature's package is not installed; the message names the extra that
    installs it (``pip install 'phyagentos[fleet]'``; pyproject's optional dependencies).
    ``extra`` is that extra's name, ``module`` the module that was missing."""

    def __init__(self, message: str, *, extra: str, module: str):
        self.extra, self.module = extra, module
        super().__init__(message)
