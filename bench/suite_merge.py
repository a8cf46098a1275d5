"""Merge bench runs of one suite (e.g. two held-out seed ranges) into one table set.

    .venv/bin/python bench/suite_merge.py RUN_DIR [RUN_DIR ...] [--out bench/results/suite_merge.json]

RUN_DIR is a ``phyagentos bench`` run directory (``<workspace>/bench/<bench_id>/``),
finished or stopped: the episodes are re-read from their session files with
:func:`phyagentos.bench.report.collect_episode` (the report's own code), and an episode
whose worker never wrote ``outcome.yaml`` (not run, or stopped mid-way) is left out and
listed; so is an episode that never started (every session timed out waiting in the queue,
``timeout.queue``: no robot moved, e.g. the tail of a run longer than ``queue_timeout_s``).
Episodes with a session ended by a heartbeat timeout (machine load) are counted on their
own row, never as robot successes or failures, as in the bench report.

Prints Markdown: First / Final / rescued per task with Wilson 95 % intervals, the error
taxonomy, the verifier's session and per-criterion confusion matrices; writes the JSON.
"""

from __future__ import annotations

import sys
from pathlib import Path

from _harness import markdown_table, parser, write_json

from phyagentos.bench.report import _summary, collect_episode
from phyagentos.bench.taxonomy import CATEGORIES
from phyagentos.bench.verifier_scoring import confusion, wilson_interval

HERE = Path(__file__).resolve().parent


def _ci(k: int, n: int) -> str:
    ci = wilson_interval(k, n)
    return "-" if ci is None else f"[{ci[0]:.0f}, {ci[1]:.0f}] %"


def merge(run_dirs: list[Path]) -> dict:
    """Episodes of every run (ran to the end), the scored ones' summaries and matrices."""
    every, not_run, never_started = [], [], []
    for run in run_dirs:
        for d in sorted((run / "episodes").iterdir()):
            if not (d / "episode.yaml").is_file():
                continue
            e = collect_episode(d, run).data
            e = {**e, "run": run.name}
            if e["harness_status"] == "not_run":
                not_run.append(e)
            elif e["sessions"] and all(s["error_code"] == "timeout.queue" for s in e["sessions"]):
                never_started.append(e)
            else:
                every.append(e)
    scored = [e for e in every if not e["heartbeat_timeout_sessions"]]
    lost = [e for e in every if e["heartbeat_timeout_sessions"]]
    tasks = list(dict.fromkeys(e["task"] for e in every))
    taxonomy = {c: {"count": 0, "causes": {}} for c in CATEGORIES}
    for e in scored:
        for f in e["failures"]:
            taxonomy[f["category"]]["count"] += 1
            taxonomy[f["category"]]["causes"][f["cause"]] = taxonomy[f["category"]]["causes"].get(f["cause"], 0) + 1
    return {
        "runs": [str(r) for r in run_dirs], "seeds": sorted({e["seed"] for e in every}),
        "overall": _summary(scored), "per_task": {t: _summary([e for e in scored if e["task"] == t]) for t in tasks},
        "error_taxonomy": taxonomy,
        "verifier": confusion(r["truth"] for e in every for r in e["sessions"] if "truth" in r),
        "heartbeat_timeouts": {"episodes": [e["episode_id"] for e in lost],
                               "sessions": [s for e in lost for s in e["heartbeat_timeout_sessions"]],
                               "per_task": {t: sum(1 for e in lost if e["task"] == t) for t in tasks}},
        "harness_errors": [e["episode_id"] for e in every if e["harness_status"] != "completed"],
        "not_run": [f"{e['run']}/{e['episode_id']}" for e in not_run],
        "never_started_queue_timeout": [f"{e['run']}/{e['episode_id']}" for e in never_started],
    }


def markdown(m: dict) -> str:
    hb = m["heartbeat_timeouts"]["per_task"]
    tasks = []
    for t, s in [*m["per_task"].items(), ("**overall**", m["overall"])]:
        n = s["episodes"]
        lost = sum(hb.values()) if t == "**overall**" else hb.get(t, 0)
        tasks.append((t, n, f"{s['first_successes']} ({s['first_rate_pct'] or 0:.0f} %)", _ci(s["first_successes"], n),
                      f"{s['final_successes']} ({s['final_rate_pct'] or 0:.0f} %)", _ci(s["final_successes"], n),
                      s["rescued"], lost))
    lines = [markdown_table(("task", "episodes", "First", "95 % CI", "Final", "95 % CI", "rescued",
                             "heartbeat timeouts (not scored)"), tasks, "lrrrrrrr")]
    causes = [(c, t["count"], ", ".join(f"{k} ×{v}" for k, v in sorted(t["causes"].items())))
              for c, t in m["error_taxonomy"].items() if t["count"]]
    lines += ["", markdown_table(("category", "unsuccessful sessions", "causes"), causes, "lrl")]
    v = m["verifier"]
    sm = v["session_matrix"]
    lines += ["", f"Verifier, {v['sessions_scored']} verified sessions scored against ground_truth.yaml "
                  f"({v['sessions_unscored']} unscored):", "",
              markdown_table(("sessions", "truth met", "truth unmet"),
                             [("verdict success", sm["true_success"], f"{sm['false_success']} (false success)"),
                              ("verdict replan/failure", f"{sm['false_failure']} (false failure)", sm["true_failure"])],
                             "lrr"), ""]
    keys = ("true_success", "false_success", "true_failure", "false_failure", "unknown_met", "unscorable")
    lines.append(markdown_table(("criterion", "true success", "false success", "true failure", "false failure",
                                 "unknown (met)", "unscorable"),
                                [(name, *(row[k] for k in keys))
                                 for name, row in sorted(v["per_predicate"].items()) + [("**all**", v["criterion_matrix"])]],
                                "lrrrrrr"))
    return "\n".join(lines)


def main() -> int:
    ap = parser(__doc__, "suite_merge")
    ap.add_argument("runs", nargs="+", type=Path, help="bench run directories of one suite")
    args = ap.parse_args()
    m = merge(args.runs)
    print(markdown(m))
    print(f"\nseeds {m['seeds'][0]}-{m['seeds'][-1]} ({len(m['seeds'])}); heartbeat-timeout episodes "
          f"{m['heartbeat_timeouts']['episodes']}; harness errors {m['harness_errors']}; "
          f"not run or stopped: {len(m['not_run'])}; never started (queue timeout): "
          f"{len(m['never_started_queue_timeout'])}")
    write_json(args.out, m, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
