"""``phyagentos bench``: availability gate -> session compiler -> executor -> report.

A bench run lives in ``<workspace>/bench/<bench_id>/``::

    suite.yaml            the suite as loaded (task sources resolved)
    gate.yaml             every availability check and its result
    plan.yaml             the episodes: task, seed, split, initial scene, perturbation
    template/             protocol templates the episode workspaces were created from
    episodes/<task>-s<seed>/   one workspace per episode (sessions/, evidence/, targets/)
    report.md report.json first_vs_final.png errors.png

``<workspace>`` itself is an ordinary workspace: its TARGETS.md, SKILLRUNTIME.md and
safety.yaml configure every episode, and its LESSONS.md / KNOWLEDGE.md are the bench
memory (see :mod:`phyagentos.bench.memory`).

Why one workspace per episode: an episode's sessions (root and verifier-triggered
children) and its simulated world state must stay together, and a worker must never
wait on, or scan, the sessions of other episodes; episodes are independent by design,
so isolating them makes parallel execution trivially safe and keeps per-session cost
constant however large the run. The report merges them.
"""

from __future__ import annotations

import json
import logging
import re
import secrets
import shutil
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from phyagentos.errors import BenchError
from phyagentos.protocol import Workspace, dump_yaml
from phyagentos.protocol.atomic import atomic_write_text

from .compiler import compile_episodes, episode_template_dir, plan_episodes
from .crafter_metrics import crafter_report, is_crafter_run
from .episode import EpisodeOutcome
from .executor import execute_episodes
from .gate import run_gate
from .memory import MEMORY_DOCS, MemoryPolicy
from .report import write_report
from .suite import Suite, load_suite

__all__ = ["BenchResult", "run_bench", "parse_seeds", "new_bench_id"]

logger = logging.getLogger(__name__)


def new_bench_id() -> str:
    """A sortable, unique bench id such as ``b20261121T152233-9f3a``."""
    return "b" + datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S") + "-" + secrets.token_hex(2)


def parse_seeds(text: str) -> tuple[int, ...]:
    """Seeds from ``"0,1,5"``, ``"0-49"`` or a mix (``"0-9,100"``); raises BenchError."""
    seeds: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m:
            raise BenchError(f"bad seed list {text!r}: expected comma-separated integers or ranges like 0-49")
        lo = int(m.group(1))
        hi = int(m.group(2)) if m.group(2) else lo
        if hi < lo:
            raise BenchError(f"bad seed range {part!r}: the end is smaller than the start")
        seeds.extend(range(lo, hi + 1))
    if len(set(seeds)) != len(seeds):
        raise BenchError(f"seed list {text!r} repeats a seed")
    return tuple(seeds)


@dataclass(frozen=True)
class BenchResult:
    """Where the run is and what its report says."""

    bench_id: str
    run_dir: Path
    report: dict

    @property
    def harness_errors(self) -> int:
        return len(self.report["harness_errors"])


def run_bench(
    suite: str | Path | Suite,
    workspace_dir: str | Path,
    *,
    episodes: int | None = None,
    seeds: tuple[int, ...] | None = None,
    split: str = "measurement",
    tasks: tuple[str, ...] | None = None,
    workers: int = 1,
    memory: str = "frozen",
    executor: str = "local",
    bench_id: str | None = None,
    on_compiled: Callable[[int], None] | None = None,
    on_episode: Callable[[EpisodeOutcome], None] | None = None,
    heartbeat_timeout_s: float | None = None,
    queue_timeout_s: float | None = None,
) -> BenchResult:
    """Run a benchmark suite end to end and write its report.

    Args:
        suite: shipped suite name, path of a suite YAML, or a loaded :class:`Suite`.
        workspace_dir: the bench workspace (created if needed).
        episodes: episodes per task (seeds of ``split``); default the suite's.
        seeds: explicit seeds per task (overrides ``episodes``).
        split: ``measurement`` or ``heldout`` (the suite's held-out seed range).
        tasks: run only these task ids (default all).
        workers: worker processes (>= 1).
        memory: ``off``, ``frozen`` (measurement) or ``learn`` (adaptation).
        executor: ``local`` process pool or ``ray``.
        bench_id: id of the run (default: new, time-sortable).
        on_compiled: called with the number of episodes once they are compiled.
        on_episode: called with each :class:`EpisodeOutcome` as it completes.
        heartbeat_timeout_s: the runner heartbeat timeout of every session, s (default
            ``None``: the graphs' own limits, i.e. the shipped 10 s). A benchmark on a
            loaded, shared machine raises it so that load does not end sessions the
            world did not fail; the report counts the heartbeat timeouts left apart.
        queue_timeout_s: how long every session may wait pending, s (default ``None``: the
            graphs' own, 600 s). Every episode is compiled before the first runs, so a run
            longer than this on a loaded machine would time out the last episodes' sessions
            in the queue; the report counts queue timeouts apart as well.

    Raises:
        BenchError: bad suite or arguments, or a failed availability gate (its
            diagnostics in ``problems``; ``gate.yaml`` written, no episode compiled).
    """
    started = time.perf_counter()
    suite = suite if isinstance(suite, Suite) else load_suite(suite)
    ws = Workspace.create(workspace_dir)
    bench_id = bench_id or new_bench_id()
    run_dir = ws.root / "bench" / bench_id
    if run_dir.exists():
        raise BenchError(f"bench run directory {run_dir} already exists")
    run_dir.mkdir(parents=True)
    policy = MemoryPolicy(mode=memory, bench_root=ws.root, snapshot_dir=run_dir / "memory")
    seed_list = tuple(seeds) if seeds is not None else suite.seeds(episodes=episodes, split=split)
    if not seed_list:
        raise BenchError("no seeds to run")
    limits = {}
    for key, value in (("heartbeat_timeout_s", heartbeat_timeout_s), ("queue_timeout_s", queue_timeout_s)):
        if value is not None and not value > 0:
            raise BenchError(f"{key} must be > 0 s, got {value}")
        if value is not None:
            limits[key] = float(value)
    plan = plan_episodes(suite, bench_id=bench_id, seeds=seed_list, split=split, memory=memory,
                         protocol=policy.protocol, tasks=tasks, limits=limits)
    atomic_write_text(run_dir / "suite.yaml", dump_yaml(suite.to_dict()))

    first_scenes = {}
    for ep in plan:
        first_scenes.setdefault(ep.task, ep.scene)
    gate = run_gate(ws, _restrict(suite, tasks), first_scenes)
    atomic_write_text(run_dir / "gate.yaml", dump_yaml(gate.to_dict()))
    if not gate.ok:
        raise BenchError(f"availability gate failed for suite {suite.name!r}: no episode was compiled "
                         f"(details in {run_dir / 'gate.yaml'})", problems=gate.problems)

    if memory == "frozen":
        policy.snapshot_dir.mkdir()
        for key in MEMORY_DOCS:
            shutil.copy2(ws.path(key), policy.snapshot_dir / f"{key}.md")
    template = episode_template_dir(ws.root, run_dir, policy.template_files(), safety=dict(suite.safety))
    # one template per distinct cell: tasks whose safety overrides agree share one
    task_templates: dict[str, Path] = {}
    by_cell: dict[str, Path] = {}
    for t in _restrict(suite, tasks).tasks:
        if t.safety:
            merged = {**suite.safety, **t.safety}
            key = json.dumps(merged, sort_keys=True)
            if key not in by_cell:
                by_cell[key] = episode_template_dir(ws.root, run_dir, policy.template_files(), safety=merged,
                                                    name=f"template_{t.id}")
            task_templates[t.id] = by_cell[key]
    atomic_write_text(run_dir / "plan.yaml", dump_yaml([ep.to_dict() for ep in plan]))
    directories = compile_episodes(plan, run_dir=run_dir, template=template, task_templates=task_templates)
    if on_compiled is not None:
        on_compiled(len(directories))
    compiled_s = time.perf_counter() - started

    exec_started = time.perf_counter()
    outcomes = execute_episodes(directories, workers=workers, memory=policy, executor=executor, on_done=on_episode)
    exec_s = time.perf_counter() - exec_started
    wall = time.perf_counter() - started
    meta = {
        "bench_id": bench_id, "suite": suite.name, "suite_file": str(suite.path), "description": suite.description,
        "protocol": policy.protocol, "memory": memory, "split": split, "seeds": list(seed_list),
        "seeds_text": _seeds_text(seed_list), "tasks": [t.id for t in _restrict(suite, tasks).tasks],
        "perturbations": {"rate": suite.perturbations.rate, "kinds": list(suite.perturbations.kinds)},
        "perturbations_text": (f"rate {suite.perturbations.rate:g} of {', '.join(suite.perturbations.kinds)}"
                               if suite.perturbations.rate else "none"),
        "executor": executor, "workers": workers, "session_limits": limits, "gate_checks": len(gate.checks),
        "compile_s": round(compiled_s, 3), "execute_s": round(exec_s, 3), "wall_time_s": round(wall, 3),
        "episodes_per_minute": round(60.0 * len(outcomes) / exec_s, 3) if exec_s > 0 else 0.0,
        "workspace": str(ws.root), "run_dir": str(run_dir),
    }
    report = write_report(run_dir, meta)
    if is_crafter_run(run_dir):  # the game tier: Crafter's own metrics (crafter.json, crafter.md)
        report = {**report, "crafter": crafter_report(run_dir, meta={"memory": memory, "split": split})}
    return BenchResult(bench_id=bench_id, run_dir=run_dir, report=report)


def _restrict(suite: Suite, tasks: tuple[str, ...] | None) -> Suite:
    if not tasks:
        return suite
    from dataclasses import replace  # noqa: PLC0415

    return replace(suite, tasks=tuple(suite.task(t) for t in tasks))


def _seeds_text(seeds: tuple[int, ...]) -> str:
    if len(seeds) > 1 and list(seeds) == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(str(s) for s in seeds)
