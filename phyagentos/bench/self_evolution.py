"""Measuring self-evolution: the same episodes, before and after memory.

The paper's claim is that verified outcomes make later sessions better. This module
measures it on the MuJoCo tabletop with the ordinary path (``run_goal_graph``: Session
Compiler, WatchdogSupervisor, SessionRunner, SessionVerifier, recovery, memory):

1. a seeded set of :class:`Episode` goal graphs (e.g. the randomised worlds of
   :mod:`phyagentos.bench.random_world`, whose failures come from the drawn world);
2. pass 1 runs every episode with empty memory (nothing retrieved) while verdicts are
   consolidated into LESSONS.md, KNOWLEDGE.md and SKILL.md;
3. pass 2 runs the same episodes in a fresh workspace holding a copy of that memory,
   frozen (retrieved, never written), so the measurement does not depend on order.

For each pass: first-attempt success (every node's first session succeeded) and final
success after verifier-driven recovery (every node succeeded), each traceable to the
session ids in the episode results.

This module composes both planes, like :mod:`phyagentos.app.orchestrator`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import yaml

from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.protocol import Workspace, atomic_write_bytes

__all__ = ["MEMORY_DOCUMENTS", "Episode", "EpisodeResult", "PassResult",
           "run_pass", "copy_memory", "measure"]

logger = logging.getLogger(__name__)

MEMORY_DOCUMENTS: tuple[str, ...] = ("LESSONS", "KNOWLEDGE", "SKILL")


@dataclass(frozen=True)
class Episode:
    """One seeded episode: a goal graph (mapping); ``kind`` labels the episode family."""

    episode_id: str
    kind: str | None
    seed: int
    graph: dict[str, Any]


@dataclass(frozen=True)
class EpisodeResult:
    """How an episode went in one pass (session ids make it traceable)."""

    episode_id: str
    kind: str | None
    run_id: str
    first_attempt_success: bool
    final_success: bool
    session_ids: tuple[str, ...]
    causes: tuple[str, ...]
    memory_items: tuple[str, ...]
    wall_time_s: float


@dataclass(frozen=True)
class PassResult:
    """One pass over the episodes."""

    name: str
    workspace: Path
    episodes: tuple[EpisodeResult, ...]
    wall_time_s: float
    lessons: int = 0
    candidates: int = 0
    knowledge: int = 0
    procedures: int = 0
    by_kind: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def first_attempt_rate(self) -> float:
        return sum(e.first_attempt_success for e in self.episodes) / max(len(self.episodes), 1)

    @property
    def final_rate(self) -> float:
        return sum(e.final_success for e in self.episodes) / max(len(self.episodes), 1)

    @property
    def sessions(self) -> int:
        return sum(len(e.session_ids) for e in self.episodes)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "workspace": str(self.workspace), "episodes": len(self.episodes),
                "first_attempt_rate": round(self.first_attempt_rate, 4), "final_rate": round(self.final_rate, 4),
                "sessions": self.sessions, "wall_time_s": round(self.wall_time_s, 2), "lessons": self.lessons,
                "candidates": self.candidates, "knowledge": self.knowledge, "procedures": self.procedures,
                "by_kind": self.by_kind, "results": [asdict(e) for e in self.episodes]}


def copy_memory(source: Workspace, destination: Workspace) -> None:
    """Copy LESSONS.md, KNOWLEDGE.md and SKILL.md from ``source`` to ``destination``."""
    for key in MEMORY_DOCUMENTS:
        atomic_write_bytes(destination.path(key), source.path(key).read_bytes())


def run_pass(name: str, episodes: Sequence[Episode], workspace_dir: str | Path, *, use_memory: bool,
             consolidate: bool, memory_from: Workspace | None = None,
             progress: Callable[[str], None] | None = None) -> PassResult:
    """Run every episode once in ``workspace_dir`` and collect the results.

    Args:
        use_memory: let the ContextBuilder retrieve memory for first attempts.
        consolidate: write verdicts into the workspace's memory.
        memory_from: start from a copy of this workspace's memory documents.
    """
    root = Path(workspace_dir)
    workspace = Workspace.create(root)
    if memory_from is not None:
        copy_memory(memory_from, workspace)
    graphs = root / "graphs"
    graphs.mkdir(exist_ok=True)
    started = time.perf_counter()
    results = []
    for ep in episodes:
        path = graphs / f"{ep.episode_id}.yaml"
        path.write_text(yaml.safe_dump(ep.graph, sort_keys=False), encoding="utf-8")
        t0 = time.perf_counter()
        report = run_goal_graph(path, root, seed=ep.seed, use_memory=use_memory, consolidate=consolidate)
        first = {}
        for s in report.sessions:
            first.setdefault(s.node, s)
        results.append(EpisodeResult(
            episode_id=ep.episode_id, kind=ep.kind, run_id=report.run_id,
            first_attempt_success=len(first) == len(ep.graph["nodes"]) and all(s.status == "succeeded"
                                                                                for s in first.values()),
            final_success=report.succeeded, session_ids=tuple(s.session_id for s in report.sessions),
            causes=tuple(s.cause for s in report.sessions if s.cause),
            memory_items=tuple(dict.fromkeys(i for s in report.sessions for i in s.memory)),
            wall_time_s=round(time.perf_counter() - t0, 3)))
        if progress:
            r = results[-1]
            progress(f"{name}: {r.episode_id} first={'ok' if r.first_attempt_success else 'fail'} "
                     f"final={'ok' if r.final_success else 'fail'} ({len(r.session_ids)} sessions)")
    by_kind: dict[str, dict[str, float]] = {}
    for kind in dict.fromkeys(e.kind or "none" for e in results):
        mine = [e for e in results if (e.kind or "none") == kind]
        by_kind[kind] = {"episodes": len(mine),
                         "first_attempt_rate": round(sum(e.first_attempt_success for e in mine) / len(mine), 4),
                         "final_rate": round(sum(e.final_success for e in mine) / len(mine), 4)}
    lessons = workspace.read("LESSONS").data
    return PassResult(name=name, workspace=root, episodes=tuple(results), wall_time_s=time.perf_counter() - started,
                      lessons=len(lessons.lessons), candidates=len(lessons.candidates),
                      knowledge=len(workspace.read("KNOWLEDGE").data.entries),
                      procedures=len(workspace.read("SKILL").data.procedures), by_kind=by_kind)


def measure(episodes: Sequence[Episode], root: str | Path, *,
            progress: Callable[[str], None] | None = None) -> tuple[PassResult, PassResult]:
    """Pass 1 with empty memory (consolidating), pass 2 with pass 1's memory, frozen.

    Workspaces: ``root/pass1_empty_memory`` and ``root/pass2_with_memory``.
    """
    root = Path(root)
    first = run_pass("pass 1 (empty memory)", episodes, root / "pass1_empty_memory", use_memory=False,
                     consolidate=True, progress=progress)
    second = run_pass("pass 2 (consolidated memory)", episodes, root / "pass2_with_memory", use_memory=True,
                      consolidate=False, memory_from=Workspace.open(first.workspace), progress=progress)
    return first, second
