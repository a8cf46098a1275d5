"""Benchmarking as the same path (paper, Section 4.4).

Availability gate (:mod:`.gate`) -> session compiler over (task, seed) pairs
(:mod:`.compiler`, suites in :mod:`.suite`, perturbations in :mod:`.perturb`) -> the
ordinary AgentCoordinator / WatchdogSupervisor / SessionRunner / SessionVerifier loop in
worker processes (:mod:`.executor`, :mod:`.episode`) -> report from the session files
(:mod:`.report`, error taxonomy in :mod:`.taxonomy`). Entry point: :func:`run_bench`.

Like :mod:`phyagentos.app.orchestrator`, this package is a composition root: it may import
both planes, which still only meet through workspace files.
"""

from .gate import GateCheck, GateReport, run_gate
from .harness import BenchResult, new_bench_id, parse_seeds, run_bench
from .memory import MEMORY_MODES, MemoryPolicy
from .suite import Suite, available_suites, load_suite

__all__ = [
    "run_bench",
    "BenchResult",
    "parse_seeds",
    "new_bench_id",
    "run_gate",
    "GateReport",
    "GateCheck",
    "MEMORY_MODES",
    "MemoryPolicy",
    "Suite",
    "load_suite",
    "available_suites",
]
