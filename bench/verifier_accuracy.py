"""Verifier accuracy on randomised tabletop worlds: the confusion matrix against ground truth.

    nice -n 10 .venv/bin/python bench/verifier_accuracy.py [--episodes 100] [--first-seed 20000]

Episodes are pick-and-place goal graphs over randomised scenes
(:mod:`phyagentos.bench.random_world`: shape, size 2-7 cm, mass 0.02-1.5 kg, friction
0.1-1.2, yaw, position, 0-4 distractors, some touching), each run through the ordinary
path (``run_goal_graph``: WatchdogSupervisor, SessionRunner, SessionVerifier, recovery)
with memory off, so every session is judged independently. Every verified session
(roots and verifier-triggered children) is then scored against its own
``ground_truth.yaml`` (:mod:`phyagentos.bench.verifier_scoring`): verdict success versus
every criterion met in truth, and per criterion.

Goals (issue 9): false success ("self-deception") <= 1 % and false failure <= 5 % of at
least 200 scored sessions. Prints the matrices and writes
``bench/results/verifier_accuracy.json`` (every session id with its cell). The machine is
shared: wall times are indicative only.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from phyagentos.bench.random_world import random_episodes
from phyagentos.bench.report import verifier_markdown
from phyagentos.bench.verifier_scoring import confusion, load_ground_truth, score_session
from phyagentos.protocol import Workspace
from phyagentos.self_evolution import run_pass

HERE = Path(__file__).resolve().parent


def score_pass(workspace: Path, session_ids) -> list[dict]:
    """Score every verified session of a pass's workspace against its ground truth."""
    ws = Workspace.open(workspace)
    scores = []
    for sid in session_ids:
        rec = ws.load_session(sid)
        attempt = rec.attempts[-1] if rec.attempts else None
        if attempt is None or attempt.verdict is None:
            continue
        gt = load_ground_truth(ws.root / attempt.evidence) if attempt.evidence else None
        scores.append({"session_id": sid, "node": rec.node, "verdict": attempt.verdict.verdict,
                       "cause": attempt.verdict.diagnosis.cause if attempt.verdict.diagnosis else None,
                       **score_session(accept=rec.accept, verdict=attempt.verdict.model_dump(), gt=gt)})
    return scores


def report(v: dict, out: Path, extra: dict) -> None:
    m = v["session_matrix"]
    print(f"{'':<26}{'truth met':>12}{'truth unmet':>14}")
    print(f"{'verdict success':<26}{m['true_success']:>12}{m['false_success']:>14}")
    print(f"{'verdict replan/failure':<26}{m['false_failure']:>12}{m['true_failure']:>14}")
    print(f"\nfalse success: {v['false_success_rate_pct']}% of sessions (goal <= 1 %), "
          f"{v['false_success_given_unmet_pct']}% of truly failed ones")
    print(f"false failure: {v['false_failure_rate_pct']}% of sessions (goal <= 5 %), "
          f"{v['false_failure_given_met_pct']}% of truly successful ones")
    print(f"\n{'criterion':<12}" + "".join(f"{k:>15}" for k in v["criterion_matrix"]))
    for name, row in sorted(v["per_predicate"].items()):
        print(f"{name:<12}" + "".join(f"{row[k]:>15}" for k in v["criterion_matrix"]))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"benchmark": "verifier_accuracy", **extra, "verifier": v}, indent=1) + "\n",
                   encoding="utf-8")
    out.with_suffix(".md").write_text("\n".join(verifier_markdown(v)) + "\n", encoding="utf-8")
    print(f"wrote {out}")


def score_only(workspace: Path, out: Path) -> int:
    """Score every verified session in ``workspace`` (an interrupted or finished run)."""
    ws = Workspace.open(workspace)
    sessions = ws.list_sessions()
    scores = score_pass(workspace, [s.session_id for s in sessions])
    runs = sorted({s.run_id for s in sessions})
    v = confusion(scores)
    print(f"verifier accuracy (scored from {workspace}): {len(runs)} episode runs, {v['sessions_scored']} sessions "
          f"scored ({v['sessions_unscored']} unscored)")
    report(v, out, {"scored_from": str(workspace), "episode_runs": len(runs), "sessions": scores})
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100, help="randomised pick-and-place episodes (default 100)")
    ap.add_argument("--first-seed", type=int, default=20000, help="seed of the first episode (default 20000)")
    ap.add_argument("--workspace", type=Path, help="keep the workspace here (default: a temporary directory)")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "verifier_accuracy.json")
    ap.add_argument("--score-only", type=Path, metavar="WORKSPACE",
                    help="score the verified sessions already in WORKSPACE (e.g. an interrupted run) and exit")
    args = ap.parse_args()
    if args.score_only:
        return score_only(args.score_only, args.out)
    episodes = random_episodes(range(args.first_seed, args.first_seed + args.episodes))
    tmp = None if args.workspace else tempfile.TemporaryDirectory(prefix="verifier_accuracy_")
    root = args.workspace or Path(tmp.name)
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    started = time.perf_counter()
    p = run_pass("verifier accuracy", episodes, root / "ws", use_memory=False, consolidate=False, progress=say)
    scores = score_pass(p.workspace, [sid for e in p.episodes for sid in e.session_ids])
    wall = time.perf_counter() - started
    v = confusion(scores)
    m = v["session_matrix"]
    print(f"\nverifier accuracy: {len(episodes)} randomised episodes, {v['sessions_scored']} sessions scored "
          f"({v['sessions_unscored']} unscored), {wall:.0f} s wall on a shared machine")
    print(f"{'':<26}{'truth met':>12}{'truth unmet':>14}")
    print(f"{'verdict success':<26}{m['true_success']:>12}{m['false_success']:>14}")
    print(f"{'verdict replan/failure':<26}{m['false_failure']:>12}{m['true_failure']:>14}")
    print(f"\nfalse success: {v['false_success_rate_pct']}% of sessions (goal <= 1 %), "
          f"{v['false_success_given_unmet_pct']}% of truly failed ones")
    print(f"false failure: {v['false_failure_rate_pct']}% of sessions (goal <= 5 %), "
          f"{v['false_failure_given_met_pct']}% of truly successful ones")
    print(f"\n{'criterion':<12}" + "".join(f"{k:>15}" for k in v["criterion_matrix"]))
    for name, row in sorted(v["per_predicate"].items()):
        print(f"{name:<12}" + "".join(f"{row[k]:>15}" for k in v["criterion_matrix"]))
    print(f"\nfirst-attempt success {p.first_attempt_rate:.0%}, final {p.final_rate:.0%} over {len(p.episodes)} episodes")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": "verifier_accuracy", "episodes": len(episodes), "first_seed": args.first_seed,
              "wall_time_s": round(wall, 1), "first_attempt_rate": round(p.first_attempt_rate, 4),
              "final_rate": round(p.final_rate, 4), "verifier": v, "sessions": scores,
              "episode_results": [{"episode_id": e.episode_id, "shape": e.kind, "first": e.first_attempt_success,
                                   "final": e.final_success, "sessions": list(e.session_ids), "causes": list(e.causes)}
                                  for e in p.episodes]}
    args.out.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    (args.out.with_suffix(".md")).write_text("\n".join(verifier_markdown(v)) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
