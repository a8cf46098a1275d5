"""Benchmark report: aggregated from the episodes' session files and evidence bundles.

The session documents (``episodes/<episode>/sessions/<id>.md``) are the only source of
verdicts; the report never re-judges. Per episode:

- **First**: every goal-graph node succeeded with its *root* session (no
  verifier-triggered child session was needed);
- **Final**: every node's latest session succeeded (after recovery);
- **rescued**: Final but not First;
- **length**: simulated seconds at the end of the episode (the target clock carried
  through all its sessions), number of sessions and of behaviour-tree ticks;
- **wall time**: the worker's wall time for the whole episode.

An episode with a session that ended on a heartbeat timeout (``heartbeat.*``: a runner,
target or policy went silent longer than ``limits.heartbeat_timeout_s``, on a shared
machine the symptom of load, not of the world) or that timed out waiting in the queue
(``timeout.queue``: it never reached a robot) is neither a robot success nor a robot
failure: it is left out of First, Final, rescued and the error taxonomy and counted on
its own row (``heartbeat_timeouts`` in report.json, with the codes).

Every unsuccessful session is classified with :func:`phyagentos.bench.taxonomy.classify`.
Every verified session is scored against its ``ground_truth.yaml``
(:mod:`phyagentos.bench.verifier_scoring`): the report carries the verifier's confusion
matrix per session and per criterion, the false success ("self-deception") and false
failure rates, and the ids behind each false verdict (``verifier`` in report.json, the
*Verifier accuracy* section of report.md).
Where a target reports its own task-completion signal (``ground_truth`` in the terminal
snapshot, e.g. FrankaKitchen's), it is set next to the verdict and disagreements are
listed. Every aggregate carries the episode and session ids it was computed from.

Outputs in the bench run directory: ``report.json``, ``report.md``,
``first_vs_final.png`` (per-task bars) and ``errors.png`` (taxonomy).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phyagentos.errors import BenchError
from phyagentos.protocol import Workspace
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.yamlsource import read_yaml

from .episode import OUTCOME_FILE, load_episode
from .taxonomy import CATEGORIES, classify
from .verifier_scoring import acting_ancestor, confusion, judged_ground_truth, score_session

__all__ = ["EpisodeRecord", "collect_episode", "build_report", "write_report", "load_report", "verifier_markdown"]

logger = logging.getLogger(__name__)


def _generation(session_id: str) -> int:
    return int(session_id.rsplit("-", 1)[1])


@dataclass(frozen=True)
class EpisodeRecord:
    """Everything the report needs from one episode (plain data in :attr:`data`)."""

    data: dict[str, Any]


def _unreadable(path: Path, exc: Exception) -> None:
    """An evidence file that is missing counts as empty; one that is present but bad is said."""
    if not isinstance(exc, FileNotFoundError):
        logger.warning("evidence file set aside: %s", exc)


def _bundle(root: Path, evidence: str | None) -> dict:
    if not evidence:
        return {}
    path = root / evidence / "bundle.yaml"
    try:
        return read_yaml(path, error=BenchError) or {}
    except (OSError, BenchError) as exc:
        _unreadable(path, exc)
        return {}


def _terminal(root: Path, evidence: str | None) -> dict:
    """The bundle's ``ground_truth.yaml`` (scoring reads truth only from there)."""
    if not evidence:
        return {}
    path = root / evidence / "ground_truth.yaml"
    try:
        return read_yaml(path, error=BenchError) or {}
    except (OSError, BenchError) as exc:
        _unreadable(path, exc)
        return {}


def _events(root: Path, evidence: str | None) -> list:
    if not evidence:
        return []
    try:
        return read_yaml(root / evidence / "events.yaml", error=BenchError) or []
    except (OSError, BenchError) as exc:
        _unreadable(root / evidence / "events.yaml", exc)
        return []


def _session_file(ws: Workspace, session_id: str, run_dir: Path) -> str:
    """Where the session's document is (terminal sessions are archived), relative to ``run_dir``."""
    find = getattr(ws, "find_session_path", None)
    path = find(session_id) if find is not None else None
    return (path or ws.sessions_dir / f"{session_id}.md").relative_to(run_dir).as_posix()


def collect_episode(directory: Path, run_dir: Path) -> EpisodeRecord:
    """Read one episode's sessions, evidence and outcome into an :class:`EpisodeRecord`."""
    episode = load_episode(directory)
    outcome_path = directory / OUTCOME_FILE
    outcome = read_yaml(outcome_path, error=BenchError) if outcome_path.is_file() else None
    ws = Workspace.open(directory)
    sessions = [s for s in ws.list_sessions() if s.run_id == episode.run_id]
    task_nodes = [n.id for n in ws.read("TASK").data.nodes] if ws.read("TASK").data.run_id == episode.run_id else []
    rel = directory.relative_to(run_dir).as_posix()
    by_node: dict[str, list] = {}
    for s in sessions:
        by_node.setdefault(s.node, []).append(s)
    nodes = task_nodes or sorted(by_node)
    rows = []
    failures = []
    sim_time = 0.0
    ticks = 0
    ground_truth = []
    heartbeat: list[str] = []
    by_id = {s.session_id: s for s in sessions}
    for s in sessions:
        attempt = s.attempts[-1] if s.attempts else None
        verdict = attempt.verdict.verdict if attempt and attempt.verdict else None
        bundle = _bundle(directory, attempt.evidence if attempt else None)
        out = bundle.get("outcome", {}) if bundle else {}
        if out.get("sim_time_s") is not None:
            sim_time = max(sim_time, float(out["sim_time_s"]))
        ticks += int(out.get("ticks") or 0)
        row = {
            "session_id": s.session_id, "node": s.node, "state": s.state, "verdict": verdict,
            "parent_session_id": s.parent_session_id, "generation": _generation(s.session_id),
            "file": _session_file(ws, s.session_id, run_dir),
            "evidence": f"{rel}/{attempt.evidence}" if attempt and attempt.evidence else None,
            # a session that never ran an attempt (e.g. timed out in the queue) carries its code in result
            "error_code": (attempt.error.code if attempt and attempt.error else
                           s.result.error.code if attempt is None and s.result is not None and s.result.error else None),
            "reason": (attempt.verdict.reason if attempt and attempt.verdict else
                       "; ".join(r.code for r in s.rejection) or (attempt.error.message if attempt and attempt.error else "")),
        }
        rows.append(row)
        terminal = _terminal(directory, attempt.evidence if attempt else None)
        if attempt is not None and attempt.verdict is not None:
            acting = acting_ancestor(s, by_id.get)  # an another-view child is scored from the acting session's start
            truth = (judged_ground_truth(terminal, _terminal(directory, acting.attempts[-1].evidence))
                     if acting is not None else terminal)
            scored = score_session(accept=s.accept, verdict=attempt.verdict.model_dump(), gt=truth or None)
            row["truth"] = {"session_id": s.session_id, **scored}
        gt = (terminal.get("terminal") or {}).get("benchmark") if isinstance(terminal, dict) else None
        if isinstance(gt, dict) and "success" in gt:
            ground_truth.append({"session_id": s.session_id, "verdict": verdict, "env_success": bool(gt["success"]),
                                 "control_steps": gt.get("control_steps"), "step_budget": gt.get("step_budget"),
                                 "within_budget": bool(gt.get("within_budget", True)),
                                 "first_success_step": gt.get("first_success_step"),
                                 "init_settle": gt.get("init_settle"),
                                 "source": gt.get("source", ""), "task": gt.get("task"),
                                 "recovery": s.parent_session_id is not None,
                                 "agree": (verdict == "success") == bool(gt["success"])})
        if s.state != "succeeded" and str(row["error_code"] or "").startswith(LOAD_TIMEOUT_CODES):
            heartbeat.append(s.session_id)
        elif s.state != "succeeded":
            diagnosis = getattr(attempt.verdict, "diagnosis", None) if attempt and attempt.verdict else None
            category, cause = classify(state=s.state, error_code=row["error_code"],
                                       rejection_codes=[r.code for r in s.rejection],
                                       events=_events(directory, attempt.evidence if attempt else None),
                                       diagnosis=diagnosis.model_dump() if diagnosis is not None else None)
            failures.append({"session_id": s.session_id, "node": s.node, "state": s.state, "category": category,
                             "cause": cause, "reason": row["reason"]})
    first = bool(nodes) and all(any(x.parent_session_id is None and x.state == "succeeded" for x in by_node.get(n, []))
                                for n in nodes)
    final = bool(nodes) and all(
        by_node.get(n) and max(by_node[n], key=lambda x: _generation(x.session_id)).state == "succeeded" for n in nodes)
    data = {
        "episode_id": episode.episode_id, "run_id": episode.run_id, "task": episode.task, "seed": episode.seed,
        "split": episode.split, "directory": rel, "perturbation": episode.evaluation.get("perturbation"),
        "harness_status": outcome["status"] if outcome else "not_run",
        "harness_error": (outcome or {}).get("error", "")[-2000:],
        "worker": (outcome or {}).get("worker"),
        "wall_time_s": round(float(outcome["wall_time_s"]), 4) if outcome else None,
        "first_success": first, "final_success": final, "rescued": final and not first,
        "sessions": rows, "n_sessions": len(rows), "sim_time_s": round(sim_time, 4), "ticks": ticks,
        "failures": failures, "ground_truth": ground_truth, "heartbeat_timeout_sessions": heartbeat,
        # how far the objects moved while the init state settled (the first signal that says)
        "init_settle": next((g["init_settle"] for g in ground_truth if g.get("init_settle") is not None), None),
        **env_outcome(ground_truth),
    }
    return EpisodeRecord(data)


def env_outcome(ground_truth: list[dict]) -> dict[str, Any]:
    """The environment's own verdict on an episode from its sessions' signals (in order):
    ``env_success`` (its signal after the last session); as an external benchmark scores an
    episode (success ends it, within its step budget) ``env_first_success`` (held at the end of
    a session before any recovery session) and ``env_final_success`` (at the end of any
    session), both only within the budget; ``env_success_after_budget`` (the signal held only
    after the budget: a failure by the benchmark's protocol); ``control_steps`` and
    ``step_budget`` of the last session. Every value ``None`` without a signal. A success the
    checker noted during a session (``first_success_step``) counts even if a later motion undid
    it: the benchmark would have ended the episode there."""
    if not ground_truth:
        return {"env_success": None, "env_first_success": None, "env_final_success": None,
                "env_success_after_budget": None, "control_steps": None, "step_budget": None}
    final = any(_in_budget(g) for g in ground_truth)
    return {"env_success": ground_truth[-1]["env_success"], "env_first_success": _env_first(ground_truth),
            "env_final_success": final,
            "env_success_after_budget": not final and any(g["env_success"] or g.get("first_success_step") is not None
                                                          for g in ground_truth),
            "control_steps": ground_truth[-1].get("control_steps"), "step_budget": ground_truth[-1].get("step_budget")}


def _in_budget(g: dict) -> bool:
    """Whether a session's environment signal says the task succeeded within the benchmark's
    step budget (e.g. LIBERO's 220 / 280 / 300 / 520 control steps since the reset). With
    ``first_success_step`` (the control step at which the benchmark's checker first held,
    since the episode's reset: success ends an episode there, as LIBERO scores it): that step
    within the budget; else the signal at the end of the session, which must end within the
    budget (``within_budget``; a signal without a budget counts)."""
    step, budget = g.get("first_success_step"), g.get("step_budget")
    if step is not None:
        return budget is None or int(step) <= int(budget)
    return bool(g["env_success"]) and bool(g.get("within_budget", True))


def _env_first(ground_truth: list[dict]) -> bool | None:
    """The environment's signal held at the end of a session before the first recovery
    session, within the step budget (``None`` without a signal)."""
    if not ground_truth:
        return None
    for g in ground_truth:
        if g.get("recovery"):
            return False
        if _in_budget(g):
            return True
    return False


#: Error-code prefixes of sessions ended by machine load or waiting, not by the world.
LOAD_TIMEOUT_CODES: tuple[str, ...] = ("heartbeat.", "timeout.queue")


def _codes(rows) -> dict[str, int]:
    out: dict[str, int] = {}
    for r in rows:
        out[r["error_code"]] = out.get(r["error_code"], 0) + 1
    return out


def _rate(k: int, n: int) -> float | None:
    return round(100.0 * k / n, 2) if n else None


def _median(values: list[float]) -> float | None:
    if not values:
        return None
    v = sorted(values)
    mid = len(v) // 2
    return round(v[mid] if len(v) % 2 else 0.5 * (v[mid - 1] + v[mid]), 4)


def _summary(eps: list[dict]) -> dict[str, Any]:
    n = len(eps)
    first = [e["episode_id"] for e in eps if e["first_success"]]
    final = [e["episode_id"] for e in eps if e["final_success"]]
    rescued = [e["episode_id"] for e in eps if e["rescued"]]
    fr, fn = _rate(len(first), n), _rate(len(final), n)
    return {
        "episodes": n, "first_successes": len(first), "final_successes": len(final),
        "first_rate_pct": fr, "final_rate_pct": fn,
        "gain_points": round(fn - fr, 2) if fr is not None and fn is not None else None,
        "rescued": len(rescued), "rescued_episodes": rescued,
        "first_success_episodes": first, "final_success_episodes": final,
        "failed_episodes": [e["episode_id"] for e in eps if not e["final_success"]],
        "median_sim_time_s": _median([e["sim_time_s"] for e in eps]),
        "median_sessions": _median([float(e["n_sessions"]) for e in eps]),
        "median_wall_time_s": _median([e["wall_time_s"] for e in eps if e["wall_time_s"] is not None]),
    }


def build_report(run_dir: Path, meta: dict[str, Any]) -> dict[str, Any]:
    """Aggregate every episode under ``run_dir/episodes`` into the report dictionary."""
    directories = sorted((run_dir / "episodes").iterdir()) if (run_dir / "episodes").is_dir() else []
    every = [collect_episode(d, run_dir).data for d in directories if (d / "episode.yaml").is_file()]
    # heartbeat timeouts (machine load) are neither robot successes nor robot failures
    eps = [e for e in every if not e["heartbeat_timeout_sessions"]]
    lost = [e for e in every if e["heartbeat_timeout_sessions"]]
    tasks = list(dict.fromkeys(e["task"] for e in every))
    taxonomy: dict[str, dict[str, Any]] = {c: {"count": 0, "sessions": [], "causes": {}} for c in CATEGORIES}
    for e in eps:
        for f in e["failures"]:
            t = taxonomy[f["category"]]
            t["count"] += 1
            t["sessions"].append(f["session_id"])
            t["causes"][f["cause"]] = t["causes"].get(f["cause"], 0) + 1
    gt = [g for e in eps for g in e["ground_truth"]]
    perturbed = [e for e in eps if e["perturbation"]]
    by_kind: dict[str, list[dict]] = {}
    for e in perturbed:
        by_kind.setdefault(e["perturbation"]["kind"], []).append(e)
    report = {
        **meta,
        "overall": _summary(eps),
        "per_task": {t: _summary([e for e in eps if e["task"] == t]) for t in tasks},
        "unperturbed": _summary([e for e in eps if not e["perturbation"]]),
        "perturbed": {k: _summary(v) for k, v in sorted(by_kind.items())},
        "error_taxonomy": taxonomy,
        "ground_truth": {
            "sessions": len(gt),
            "agreements": sum(1 for g in gt if g["agree"]),
            "disagreements": [g for g in gt if not g["agree"]],
            "env_success_rate_pct": _rate(sum(1 for g in gt if g["env_success"]), len(gt)),
            "per_task": {t: {"episodes": sum(1 for e in eps if e["task"] == t and e["env_success"] is not None),
                             "env_successes": sum(1 for e in eps if e["task"] == t and e["env_success"]),
                             "env_success_episodes": [e["episode_id"] for e in eps if e["task"] == t and e["env_success"]],
                             "first_successes": sum(1 for e in eps if e["task"] == t and e.get("env_first_success")),
                             "final_successes": sum(1 for e in eps if e["task"] == t and e.get("env_final_success")),
                             "first_rate_pct": _rate(sum(1 for e in eps if e["task"] == t and e.get("env_first_success")),
                                                     sum(1 for e in eps if e["task"] == t and e["env_success"] is not None)),
                             "final_rate_pct": _rate(sum(1 for e in eps if e["task"] == t and e.get("env_final_success")),
                                                     sum(1 for e in eps if e["task"] == t and e["env_success"] is not None)),
                             "successes_after_budget": sum(1 for e in eps if e["task"] == t
                                                           and e.get("env_success_after_budget")),
                             "step_budget": next((e["step_budget"] for e in eps if e["task"] == t
                                                  and e.get("step_budget") is not None), None),
                             "median_control_steps": _median([float(e["control_steps"]) for e in eps if e["task"] == t
                                                              and e.get("control_steps") is not None]),
                             "sessions": [g["session_id"] for e in eps if e["task"] == t for g in e["ground_truth"]]}
                         for t in tasks},
        },
        # verifier accuracy against ground_truth.yaml (phyagentos.bench.verifier_scoring)
        "verifier": confusion(r["truth"] for e in every for r in e["sessions"] if "truth" in r),
        "harness_errors": [{"episode_id": e["episode_id"], "error": e["harness_error"]} for e in every
                           if e["harness_status"] != "completed"],
        "heartbeat_timeouts": {"episodes": [e["episode_id"] for e in lost],
                               "sessions": [sid for e in lost for sid in e["heartbeat_timeout_sessions"]],
                               "codes": _codes(e for x in lost for e in x["sessions"]
                                               if e["session_id"] in x["heartbeat_timeout_sessions"]),
                               "per_task": {t: sum(1 for e in lost if e["task"] == t) for t in tasks}},
        "episodes": every,
    }
    return report


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}%"


def _points(v: float | None) -> str:
    return "-" if v is None else f"{v:+.1f}"


def _plots(report: dict, run_dir: Path) -> list[str]:
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    files = []
    tasks = list(report["per_task"])
    if tasks:
        first = [report["per_task"][t]["first_rate_pct"] or 0.0 for t in tasks]
        final = [report["per_task"][t]["final_rate_pct"] or 0.0 for t in tasks]
        fig, ax = plt.subplots(figsize=(max(5.0, 1.6 * len(tasks) + 2), 3.8))
        xs = range(len(tasks))
        ax.bar([x - 0.2 for x in xs], first, width=0.4, label="First (first attempt)", color="#90a4ae")
        ax.bar([x + 0.2 for x in xs], final, width=0.4, label="Final (after recovery)", color="#43a047")
        for x, a, b in zip(xs, first, final):
            ax.text(x - 0.2, a + 1, f"{a:.0f}", ha="center", fontsize=8)
            ax.text(x + 0.2, b + 1, f"{b:.0f}", ha="center", fontsize=8)
        ax.set_xticks(list(xs), [f"{t}\n(n={report['per_task'][t]['episodes']})" for t in tasks], fontsize=8)
        ax.set_ylim(0, 125)
        ax.set_yticks(range(0, 101, 20))
        ax.set_ylabel("success rate (%)")
        ax.set_title(f"{report['suite']}: First vs Final ({report['protocol']}, {report['split']} seeds)")
        ax.legend(loc="upper center", ncol=2, fontsize=8, frameon=False)
        fig.tight_layout()
        fig.savefig(run_dir / "first_vs_final.png", dpi=110)
        plt.close(fig)
        files.append("first_vs_final.png")
    cats = [c for c in CATEGORIES if report["error_taxonomy"][c]["count"]]
    fig, ax = plt.subplots(figsize=(6, 3.2))
    counts = [report["error_taxonomy"][c]["count"] for c in cats]
    ax.bar(cats or ["none"], counts or [0], color="#e57373")
    ax.set_ylabel("unsuccessful sessions")
    ax.set_title("error taxonomy (from session evidence)")
    fig.tight_layout()
    fig.savefig(run_dir / "errors.png", dpi=110)
    plt.close(fig)
    files.append("errors.png")
    return files


def _markdown(report: dict) -> str:
    o = report["overall"]
    lines = [
        f"# Benchmark {report['suite']} — {report['bench_id']}",
        "",
        f"Suite `{report['suite_file']}`; protocol **{report['protocol']}** (memory `{report['memory']}`), "
        f"**{report['split']}** seeds {report['seeds_text']}; perturbations: {report['perturbations_text']}.",
        f"Executor `{report['executor']}` with {report['workers']} worker(s); wall time {report['wall_time_s']:.1f} s, "
        f"**{report['episodes_per_minute']:.2f} episodes/min** (execution phase). Availability gate: passed "
        f"({report['gate_checks']} checks, "
        "`gate.yaml`).",
        "",
        "Every number below is computed from the session files under `episodes/`; the *Episodes* table links each "
        "episode to its sessions, and `report.json` lists the episode and session ids behind every aggregate.",
        "",
        "## First vs Final",
        "",
        "| task | episodes | First | Final | gain (points) | rescued | median sim time (s) | median sessions | median wall (s) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for t, s in [*report["per_task"].items(), ("**overall**", o)]:
        lines.append(f"| {t} | {s['episodes']} | {_pct(s['first_rate_pct'])} ({s['first_successes']}) | "
                     f"{_pct(s['final_rate_pct'])} ({s['final_successes']}) | "
                     f"{_points(s['gain_points'])} | "
                     f"{s['rescued']} | {s['median_sim_time_s']} | {s['median_sessions']} | {s['median_wall_time_s']} |")
    hb = report.get("heartbeat_timeouts") or {}
    if hb.get("episodes"):
        lines.append(f"| heartbeat or queue timeout (machine load; not scored above) | {len(hb['episodes'])} | | | | | | | |")
    lines += ["", "![First vs Final](first_vs_final.png)", ""]
    if hb.get("episodes"):
        lines += [f"Episodes with a session that ended on a heartbeat or queue timeout ({hb.get('codes')}; neither "
                  "robot success nor failure): "
                  + ", ".join(f"`{e}`" for e in hb["episodes"]), ""]
    if o["rescued_episodes"]:
        lines += ["Rescued episodes (failed first, succeeded after a verifier-triggered child session): "
                  + ", ".join(f"`{e}`" for e in o["rescued_episodes"]), ""]
    if report["perturbed"]:
        lines += ["## Perturbations", "", "| perturbation | episodes | First | Final | rescued |", "|---|---:|---:|---:|---:|"]
        u = report["unperturbed"]
        lines.append(f"| none | {u['episodes']} | {_pct(u['first_rate_pct'])} | {_pct(u['final_rate_pct'])} | {u['rescued']} |")
        for k, s in report["perturbed"].items():
            lines.append(f"| {k} | {s['episodes']} | {_pct(s['first_rate_pct'])} | {_pct(s['final_rate_pct'])} | "
                         f"{s['rescued']} |")
        lines.append("")
    lines += ["## Error taxonomy", "",
              "Unsuccessful sessions (replanned, failed, rejected, timed out) by category, from their evidence.", "",
              "| category | sessions | causes | session ids |", "|---|---:|---|---|"]
    for c, t in report["error_taxonomy"].items():
        if not t["count"]:
            continue
        causes = ", ".join(f"{k} ×{v}" for k, v in sorted(t["causes"].items()))
        ids = ", ".join(f"`{s}`" for s in t["sessions"][:8]) + (" …" if len(t["sessions"]) > 8 else "")
        lines.append(f"| {c} | {t['count']} | {causes} | {ids} |")
    if not any(t["count"] for t in report["error_taxonomy"].values()):
        lines.append("| (none) | 0 | | |")
    lines += ["", "![error taxonomy](errors.png)", ""]
    g = report["ground_truth"]
    if g["sessions"]:
        lines += ["## Environment's own success signal", "",
                  f"{g['sessions']} session(s) carried the target's own task-completion signal; the verifier agreed on "
                  f"{g['agreements']}. Per task, the environment's verdict on each episode (its signal after the "
                  "episode's last session) next to ours:", "",
                  "| task | episodes | environment success | our Final | environment source |", "|---|---:|---:|---:|---|"]
        sources = {e["task"]: gg["source"] for e in report["episodes"] for gg in e["ground_truth"]}
        for t, pt in g["per_task"].items():
            if not pt["episodes"]:
                continue
            ours = report["per_task"][t]
            source = sources.get(t, "")
            lines.append(f"| {t} | {pt['episodes']} | {_pct(_rate(pt['env_successes'], pt['episodes']))} "
                         f"({pt['env_successes']}) | {_pct(ours['final_rate_pct'])} ({ours['final_successes']}) | "
                         f"{source} |")
        lines.append("")
        lines += ["As the benchmark itself scores an episode (success ends it, within its step budget): First = its "
                  "signal at the end of a session before any recovery session, Final = at the end of any session, "
                  "both only while the episode's control steps since the reset are within the budget (LIBERO's 220 / "
                  "280 / 300 / 520 for spatial / object / goal / 10); a success reached only after it is a failure, "
                  "counted in its own column.", "",
                  "| task | episodes | environment First | environment Final | success after the budget | "
                  "step budget | median control steps |", "|---|---:|---:|---:|---:|---:|---:|"]
        for t, pt in g["per_task"].items():
            if pt["episodes"]:
                budget = pt.get("step_budget")
                lines.append(f"| {t} | {pt['episodes']} | {_pct(pt['first_rate_pct'])} ({pt['first_successes']}) | "
                             f"{_pct(pt['final_rate_pct'])} ({pt['final_successes']}) | "
                             f"{pt.get('successes_after_budget', 0)} | {budget if budget is not None else 'none'} | "
                             f"{pt.get('median_control_steps')} |")
        lines.append("")
        if g["disagreements"]:
            lines += ["| session | task | verdict | environment success |", "|---|---|---|---|"]
            for d in g["disagreements"]:
                lines.append(f"| `{d['session_id']}` | {d['task']} | {d['verdict']} | {d['env_success']} |")
            lines.append("")
    lines += verifier_markdown(report.get("verifier"))
    if report["harness_errors"]:
        lines += ["## Harness errors", "", "These episodes did not complete; they count as failures above.", ""]
        for h in report["harness_errors"]:
            lines.append(f"- `{h['episode_id']}`: {h['error'].strip().splitlines()[-1] if h['error'] else 'not run'}")
        lines.append("")
    lines += ["## Episodes", "", "| episode | perturbation | First | Final | sim time (s) | sessions |", "|---|---|---|---|---:|---|"]
    for e in report["episodes"]:
        pert = e["perturbation"]["kind"] if e["perturbation"] else ""
        sess = ", ".join(f"[{s['session_id'].rsplit('-', 2)[-2]}#{s['generation']}]({s['file']}) {s['state']}"
                         for s in e["sessions"])
        lines.append(f"| `{e['episode_id']}` | {pert} | {'yes' if e['first_success'] else 'no'} | "
                     f"{'yes' if e['final_success'] else 'no'} | {e['sim_time_s']} | {sess} |")
    lines.append("")
    return "\n".join(lines)


def verifier_markdown(v: dict | None) -> list[str]:
    """The *Verifier accuracy* section of report.md (lines) from :func:`confusion`'s result."""
    if not v or not v["sessions_scored"]:
        return []
    m, c = v["session_matrix"], v["criterion_matrix"]
    lines = ["## Verifier accuracy against ground truth", "",
             f"{v['sessions_scored']} verified session(s) scored against their `ground_truth.yaml` "
             f"({v['sessions_unscored']} without one). Rows: what the verifier said on perceived evidence; "
             "columns: the criteria judged exactly on ground truth.", "",
             "| sessions | truth met | truth unmet |", "|---|---:|---:|",
             f"| verdict success | {m['true_success']} | **{m['false_success']}** (false success) |",
             f"| verdict replan/failure | {m['false_failure']} (false failure) | {m['true_failure']} |", "",
             f"False success (self-deception): **{_pct(v['false_success_rate_pct'])}** of scored sessions "
             f"({_pct(v['false_success_given_unmet_pct'])} of those truth says failed); false failure: "
             f"**{_pct(v['false_failure_rate_pct'])}** ({_pct(v['false_failure_given_met_pct'])} of those truth "
             "says succeeded).", "",
             "| criterion | true success | false success | true failure | false failure | unknown (met) | unscorable |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, row in sorted(v["per_predicate"].items()) + [("**all**", c)]:
        lines.append(f"| {name} | {row['true_success']} | {row['false_success']} | {row['true_failure']} | "
                     f"{row['false_failure']} | {row['unknown_met']} | {row['unscorable']} |")
    for key, title in (("false_success_sessions", "False successes"), ("false_failure_sessions", "False failures")):
        if v[key]:
            lines += ["", f"{title}: " + ", ".join(f"`{sid}`" for sid in v[key][:20])
                      + (" …" if len(v[key]) > 20 else "")]
    lines.append("")
    return lines


def write_report(run_dir: Path, meta: dict[str, Any]) -> dict[str, Any]:
    """Build the report and write ``report.json``, ``report.md`` and the plots; returns it."""
    report = build_report(run_dir, meta)
    report["plots"] = _plots(report, run_dir)
    atomic_write_text(run_dir / "report.json", json.dumps(report, indent=1, ensure_ascii=False) + "\n")
    atomic_write_text(run_dir / "report.md", _markdown(report))
    logger.info("report written to %s", run_dir / "report.md")
    return report


def load_report(run_dir: Path) -> dict[str, Any]:
    """Read ``report.json`` of a bench run directory."""
    return json.loads((Path(run_dir) / "report.json").read_text(encoding="utf-8"))
