"""What every primitive needs from its session, handed over through ``tree.setup(context=...)``.

py_trees passes ``setup(**kwargs)`` down the whole tree, so the runner builds one
:class:`SkillContext` per session and each primitive keeps a reference to it.
"""

from __future__ import annotations

import json
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

__all__ = ["SkillContext", "Profiler", "TraceRecorder", "CancelToken", "MotionSettings"]


class CancelToken:
    """Set by the supervisor; checked by the runner between ticks and by long primitives."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.reason = ""
        self.code = "cancelled.operator"

    def cancel(self, reason: str = "", code: str = "cancelled.operator") -> None:
        """Request a stop; ``code`` attributes it (``cancelled.operator``, ``cancelled.estop``,
        ``cancelled.shutdown`` or ``timeout.execution``; see docs/ERRORS.md)."""
        self.reason = reason
        self.code = code
        self._event.set()

    def is_set(self) -> bool:
        return self._event.is_set()


class Profiler:
    """Wall time per category in seconds (``ik``, ``planning``, ``timing``, ``simulation`` ...)."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = {}
        self.counts: dict[str, int] = {}

    @contextmanager
    def section(self, category: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.totals[category] = self.totals.get(category, 0.0) + time.perf_counter() - start
            self.counts[category] = self.counts.get(category, 0) + 1


class TraceRecorder:
    """Append-only action/observation trace, one JSON object per line.

    Kept in memory and flushed once at the end of the session: the trace is
    evidence, not a hot-loop side effect.
    """

    def __init__(self) -> None:
        self.records: list[dict[str, Any]] = []
        self._t0 = time.perf_counter()

    def record(self, kind: str, **data: Any) -> None:
        """Append ``{t_wall_s, kind, **data}``; values must be JSON-serialisable."""
        self.records.append({"t_wall_s": round(time.perf_counter() - self._t0, 6), "kind": kind, **data})

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        with path.open("w", encoding="utf-8") as fh:
            for rec in self.records:
                fh.write(json.dumps(rec, ensure_ascii=False) + "\n")
        return path


@dataclass(frozen=True)
class MotionSettings:
    """Planner and timing defaults; skills may override per leaf.

    Attributes:
        planner: OMPL planner name.
        planning_timeout_s: wall-clock budget per planning query, s.
        velocity_scale: fraction (0, 1] of the robot's joint velocity limits.
        acceleration_scale: fraction (0, 1] of the robot's joint acceleration limits.
        tracking_tol_rad: max joint tracking error during execution before aborting, rad.
        control_period_s: simulated time advanced per behaviour-tree tick while
            executing, s; cancellation is checked between ticks.
    """

    planner: str = "RRTConnect"
    planning_timeout_s: float = 2.0
    velocity_scale: float = 1.0
    acceleration_scale: float = 1.0
    tracking_tol_rad: float = 0.05
    control_period_s: float = 0.1


@dataclass
class SkillContext:
    """Session-scoped services for primitives.

    Attributes:
        target: the :class:`~phyagentos.targets.base.BaseRolloutTarget` to act on.
        params: the session's skill parameters.
        seed: session seed (planner RNG, perturbations).
        trace: action/observation trace (evidence).
        events: target and safety events, each ``{code, message, ...}`` (evidence).
        profiler: wall time per category.
        cancel: cancellation token.
        motion: planner/timing settings.
        on_observation: called with each snapshot an ``observe`` leaf takes
            (the runner writes it to ENVIRONMENT.md).
        failure: set by the first failing primitive: ``{code, primitive, message}``.
        guard: the session's :class:`~phyagentos.runtime.safety_guard.SafetyGuard`;
            every command to the target passes it (``None`` only in unit tests of
            primitives that do not move the arm).
        plan: the session's AdapterPlan from preflight, as a dict.
        perceiver: the session's :class:`~phyagentos.perception.Perceiver` (built on the
            first observation of a target with cameras when the runner gave none).
        evidence_dir, evidence_rel: the session's bundle directory (absolute, and
            relative to the workspace) where observations save their frames.
        on_actuation_start: called by the SkillRuntime once, right before its first
            tick (a tree), its first inference (a policy, after connecting) or its first
            model step (an agent); the SessionRunner records the attempt's
            ``actuation_started_at`` there.
        alive: stamps the runner's heartbeat and nothing else (no target call, no render,
            no checkpoint), so it is safe from a helper thread: a SkillRuntime waiting on
            something other than the target (a language model loading or thinking) calls it
            to show the runner is working, not stuck. ``None`` outside a SessionRunner.
    """

    target: Any
    params: Mapping[str, Any] = field(default_factory=dict)
    seed: int | None = None
    trace: TraceRecorder = field(default_factory=TraceRecorder)
    events: list[dict[str, Any]] = field(default_factory=list)
    profiler: Profiler = field(default_factory=Profiler)
    cancel: CancelToken = field(default_factory=CancelToken)
    motion: MotionSettings = field(default_factory=MotionSettings)
    on_observation: Callable[[dict], None] | None = None
    failure: dict[str, Any] | None = None
    guard: Any = None
    plan: Mapping[str, Any] | None = None
    perceiver: Any = None
    evidence_dir: Path | None = None
    evidence_rel: str | None = None
    observations: int = 0
    on_actuation_start: Callable[[], None] | None = None
    alive: Callable[[], None] | None = None

    def actuation_starts(self) -> None:
        """Tell the session that its skill's first tick (or first step) follows now
        (:attr:`on_actuation_start`); the SkillRuntimes call it once."""
        if self.on_actuation_start is not None:
            self.on_actuation_start()

    def fail(self, code: str, primitive: str, message: str) -> None:
        """Record a primitive failure; the last one wins (retries overwrite earlier ones)."""
        self.failure = {"code": code, "primitive": primitive, "message": message}
        self.trace.record("failure", code=code, primitive=primitive, message=message)
