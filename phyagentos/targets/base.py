"""The rollout-target contract every simulator, game or real robot implements.

A *rollout target* is where a session's actions happen. The runtime only talks to it
through :class:`BaseRolloutTarget`: observe, reset, low-level ``step``, execute a timed
joint trajectory, query a JSON-ready state summary and invoke one of a finite list of
named tools. Targets are context managers; ``close()`` releases their resources and is
idempotent.
"""

from __future__ import annotations

import abc
import inspect
from dataclasses import dataclass
from typing import Any, Literal

from phyagentos.errors import TargetError, format_choices

__all__ = ["BaseRolloutTarget", "ExecutionResult", "TargetKind", "TARGET_KINDS"]

TargetKind = Literal["simulation", "real_robot", "game"]
TARGET_KINDS: tuple[str, ...] = ("simulation", "real_robot", "game")


@dataclass(frozen=True)
class ExecutionResult:
    """Outcome of :meth:`BaseRolloutTarget.execute_trajectory`.

    Attributes:
        completed: the whole trajectory was streamed and the arm settled at its end.
        max_tracking_error_rad: largest ``|q - q_ref|`` over joints and time steps, rad.
        sim_time_s: target time spent executing (simulated seconds for simulations).
        steps: control steps taken.
        contacts: unexpected contact pairs seen during execution (sorted name pairs,
            e.g. ``('obstacle:wall', 'panda0_link7')``); empty when none.
        reason: empty when completed, otherwise why execution stopped.
    """

    completed: bool
    max_tracking_error_rad: float
    sim_time_s: float
    steps: int
    contacts: tuple[tuple[str, str], ...] = ()
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "completed": self.completed,
            "max_tracking_error_rad": self.max_tracking_error_rad,
            "sim_time_s": self.sim_time_s,
            "steps": self.steps,
            "contacts": [list(c) for c in self.contacts],
            "reason": self.reason,
        }


class BaseRolloutTarget(abc.ABC):
    """Abstract rollout target.

    Subclasses set :attr:`name` and :attr:`kind` and implement the abstract methods.
    :meth:`invoke_tool` dispatches to ``_tool_<name>`` methods for the names in
    :meth:`tools`; anything else raises :class:`TargetError` listing the valid tools.
    """

    def __init__(self, name: str, kind: TargetKind):
        if not isinstance(name, str) or not name:
            raise TargetError(f"target name must be a non-empty string, got {name!r}")
        if kind not in TARGET_KINDS:
            raise TargetError(f"unknown target kind {kind!r}; valid kinds: {format_choices(TARGET_KINDS)}")
        self._name = name
        self._kind = kind
        self._closed = False

    @property
    def name(self) -> str:
        """Target name as written in TARGETS.md."""
        return self._name

    @property
    def kind(self) -> str:
        """``'simulation'``, ``'real_robot'`` or ``'game'``."""
        return self._kind

    @property
    def closed(self) -> bool:
        return self._closed

    # -- contract -------------------------------------------------------------------
    @abc.abstractmethod
    def observe(self) -> dict:
        """Current observation (arrays allowed; see the subclass for keys)."""

    @abc.abstractmethod
    def reset(self, *, seed: int | None = None) -> dict:
        """Put the target in its initial state and return :meth:`observe`."""

    @abc.abstractmethod
    def step(self, ctrl) -> None:
        """Apply one low-level control command for one control period."""

    @abc.abstractmethod
    def execute_trajectory(self, traj, *, tracking_tol_rad: float) -> ExecutionResult:
        """Stream a timed joint trajectory (``t``, ``q``, ``qd`` arrays) to the arm."""

    @abc.abstractmethod
    def query_state(self) -> dict:
        """JSON-ready summary of the target state (plain lists, floats, strings)."""

    @abc.abstractmethod
    def tools(self) -> tuple[str, ...]:
        """Names accepted by :meth:`invoke_tool`."""

    def invoke_tool(self, name: str, **kwargs) -> Any:
        """Run tool ``name`` with keyword arguments.

        Raises :class:`TargetError` for an unknown tool (listing :meth:`tools`), for
        bad arguments, or when the target is closed.
        """
        valid = self.tools()
        if name not in valid:
            raise TargetError(f"target {self.name!r} has no tool {name!r}; valid tools: {format_choices(valid)}")
        if self._closed:
            raise TargetError(f"target {self.name!r} is closed")
        fn = getattr(self, f"_tool_{name}", None)
        if fn is None:  # pragma: no cover - subclass bug
            raise TargetError(f"target {self.name!r} lists tool {name!r} but does not implement it")
        sig = inspect.signature(fn)
        try:
            sig.bind(**kwargs)
        except TypeError as exc:
            params = ", ".join(str(p) for p in sig.parameters.values())
            raise TargetError(
                f"bad arguments for tool {name!r} of target {self.name!r}: {exc}; expected ({params})"
            ) from exc
        return fn(**kwargs)

    def halt(self) -> None:
        """Stop any motion and hold still (called on cancellation or errors).
        The default does nothing; targets that move on their own override it."""

    def close(self) -> None:
        """Release resources; further calls are no-ops."""
        self._closed = True

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, kind={self.kind!r})"
