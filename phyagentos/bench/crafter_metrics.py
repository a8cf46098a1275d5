"""Crafter's own metrics for a bench run on the game target (scoring only).

Per episode (one world): the achievements the game itself counted (its ground truth,
``targets/crafter/ground_truth.yaml``, written by the target and read here only for
scoring), the episode length in game steps, the death cause (diagnosed from the
session traces by :func:`phyagentos.agent.memory.deaths.diagnose_death`, the same
diagnosis the Agent learns from) or ``alive``, and for every achievement the session
whose trace recorded it, so each number is traceable to a session id.

Over the run: the success rate of each of the 22 achievements (share of episodes that
unlocked it at least once) and the **Crafter score**, their geometric mean
``exp(mean(ln(1 + s_i))) - 1`` with ``s_i`` in percent (Hafner, "Benchmarking the
Spectrum of Agent Capabilities", ICLR 2022, section 3), also in percent.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Sequence

from phyagentos.agent.memory.deaths import diagnose_death
from phyagentos.errors import BenchError
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.targets.crafter import CRAFTER_ACHIEVEMENTS
from phyagentos.yamlsource import read_yaml

__all__ = ["crafter_score", "crafter_score_interval", "episode_metrics", "crafter_report", "is_crafter_run"]


def crafter_score(rates_percent: Sequence[float]) -> float:
    """Crafter score in percent from per-achievement success rates in percent (Hafner 2022)."""
    if not rates_percent:
        return 0.0
    return math.exp(sum(math.log(1.0 + float(s)) for s in rates_percent) / len(rates_percent)) - 1.0


def crafter_score_interval(achievements: Sequence[Sequence[str]], *, names: Sequence[str] = CRAFTER_ACHIEVEMENTS,
                           resamples: int = 2000, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the Crafter score over episodes.

    The score is a geometric mean over achievements of rates taken over episodes, so an
    achievement that a few episodes unlock moves it a lot; resampling whole episodes
    (with replacement, ``resamples`` times, a fixed ``seed``) shows how much.

    Args:
        achievements: per episode, the names of the achievements it unlocked.
        names: every achievement the score averages over (Crafter's 22).
        resamples: bootstrap resamples.
        level: coverage of the interval (0.95: the 2.5th and 97.5th percentiles).
        seed: seed of the resampling generator (the interval is reproducible).

    Returns:
        ``(low, high)`` in percent; ``(0.0, 0.0)`` with no episode.
    """
    import numpy as np  # noqa: PLC0415

    n = len(achievements)
    if n == 0:
        return 0.0, 0.0
    index = {a: i for i, a in enumerate(names)}
    unlocked = np.zeros((n, len(names)), dtype=bool)
    for e, achieved in enumerate(achievements):
        for a in achieved:
            if a in index:
                unlocked[e, index[a]] = True
    draws = np.random.default_rng(seed).integers(0, n, size=(resamples, n))
    rates = 100.0 * unlocked[draws].mean(axis=1)  # (resamples, achievements), percent
    scores = np.expm1(np.log1p(rates).mean(axis=1))
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.percentile(scores, [tail, 100.0 - tail])
    return float(low), float(high)


def _traces(episode_dir: Path) -> list[tuple[str, list[dict]]]:
    out = []
    for trace in sorted((episode_dir / "evidence").glob("*/trace.jsonl"), key=lambda p: p.stat().st_mtime):
        records = [json.loads(line) for line in trace.read_text(encoding="utf-8").splitlines() if line.strip()]
        out.append((trace.parent.name, records))
    return out


def episode_metrics(episode_dir: str | Path, *, target: str = "crafter") -> dict[str, Any] | None:
    """Metrics of one episode workspace, ``None`` when it has no game ground truth."""
    episode_dir = Path(episode_dir)
    gt_path = episode_dir / "targets" / target / "ground_truth.yaml"
    if not gt_path.is_file():
        return None
    gt = read_yaml(gt_path, error=BenchError)
    traces = _traces(episode_dir)
    unlocked_in: dict[str, str] = {}
    cause = "alive"
    for sid, records in traces:
        for r in records:
            if r.get("kind") == "game_achievement":
                unlocked_in.setdefault(str(r["achievement"]), sid)
        found = diagnose_death(records)
        if found is not None:
            cause = found[0]
    achieved = sorted(k for k, v in (gt.get("achievements") or {}).items() if v > 0)
    if gt.get("dead") and cause == "alive":
        cause = "death.unknown"
    return {"episode": episode_dir.name, "seed": gt.get("seed"), "length": int(gt.get("step", 0)),
            "dead": bool(gt.get("dead")), "death_cause": cause, "achievements": achieved,
            "unlocked_in": {a: unlocked_in.get(a) for a in achieved}, "sessions": [sid for sid, _ in traces]}


def is_crafter_run(run_dir: str | Path) -> bool:
    return any(Path(run_dir).glob("episodes/*/targets/crafter/ground_truth.yaml"))


def crafter_report(run_dir: str | Path, *, meta: dict | None = None) -> dict[str, Any]:
    """Score every episode of ``run_dir``; writes ``crafter.json`` and ``crafter.md`` there."""
    run_dir = Path(run_dir)
    episodes = [m for m in (episode_metrics(d) for d in sorted((run_dir / "episodes").iterdir()) if d.is_dir())
                if m is not None]
    n = len(episodes)
    rates = {a: (100.0 * sum(a in e["achievements"] for e in episodes) / n if n else 0.0) for a in CRAFTER_ACHIEVEMENTS}
    causes: dict[str, int] = {}
    for e in episodes:
        causes[e["death_cause"]] = causes.get(e["death_cause"], 0) + 1
    lengths = sorted(e["length"] for e in episodes)
    report = {
        "episodes": n,
        "score_percent": round(crafter_score(list(rates.values())), 3),
        "score_ci95_percent": [round(v, 3) for v in crafter_score_interval([e["achievements"] for e in episodes])],
        "success_rates_percent": {a: round(r, 1) for a, r in rates.items()},
        "achievements_per_episode": round(sum(len(e["achievements"]) for e in episodes) / n, 3) if n else 0.0,
        "length_mean": round(sum(lengths) / n, 1) if n else 0.0,
        "length_median": lengths[n // 2] if n else 0,
        "death_causes": causes,
        "per_episode": episodes,
        **({"meta": meta} if meta else {}),
    }
    atomic_write_text(run_dir / "crafter.json", json.dumps(report, indent=2))
    lines = [f"# Crafter metrics ({n} episodes)", "",
             f"Crafter score: **{report['score_percent']:.1f} %** (geometric mean of the success rates, Hafner 2022; "
             f"95 % bootstrap interval over episodes {report['score_ci95_percent'][0]:.1f}-"
             f"{report['score_ci95_percent'][1]:.1f} %)",
             f"Episode length: mean {report['length_mean']} steps, median {report['length_median']}",
             f"Death causes: {', '.join(f'{k} {v}' for k, v in sorted(causes.items()))}", "",
             "| achievement | success rate |", "|---|---|"]
    lines += [f"| {a} | {r:.0f} % |" for a, r in rates.items()]
    lines += ["", "| episode | seed | length | death cause | achievements | sessions |", "|---|---|---|---|---|---|"]
    lines += [f"| {e['episode']} | {e['seed']} | {e['length']} | {e['death_cause']} | {len(e['achievements'])} | "
              f"{len(e['sessions'])} |" for e in episodes]
    atomic_write_text(run_dir / "crafter.md", "\n".join(lines) + "\n")
    return report
