"""Verifier accuracy on randomised tabletop worlds: the confusion matrix against ground truth.

    nice -n 10 .venv/bin/python bench/verifier_accuracy.py [--episodes 100] [--first-seed 20000] \\
        [--workspace DIR [--chunk 10]]
    .venv/bin/python bench/verifier_accuracy.py --score-only DIR [DIR ...] [--replay]

Episodes are pick-and-place goal graphs over randomised scenes
(:mod:`phyagentos.bench.random_world`: shape, size 2-7 cm, mass 0.02-1.5 kg, friction
0.1-1.2, yaw, position, 0-4 distractors, some touching), each run through the ordinary
path (``run_goal_graph``: WatchdogSupervisor, SessionRunner, SessionVerifier, recovery)
with memory off, so every session is judged independently. Every verified session
(roots and verifier-triggered children) is then scored against its own
``ground_truth.yaml`` (:mod:`phyagentos.bench.verifier_scoring`): verdict success versus
every criterion met in truth, and per criterion.

With ``--workspace DIR`` the episodes run in chunks of ``--chunk`` seeds, each in its own
workspace ``DIR/chunk-<first seed>/ws``, marked finished by ``DIR/chunk-<first seed>/done.json``;
re-running the same command skips finished chunks (resume after an interruption, or run
more seeds into the same DIR with another ``--first-seed``). Scoring merges every chunk
under DIR, finished or not (a verified session counts whether or not its episode ended).
``--score-only`` merges the chunks (or plain workspaces) it is given without running
anything; with ``--replay`` it judges the recorded evidence again with the current
verifier's predicates (success iff every criterion is satisfied and no safety event), to
measure a verifier change on the very same sessions.

Every session runs with ``limits.heartbeat_timeout_s`` raised to ``--heartbeat-timeout``
(60 s; the shipped 10 s is for a robot's own computer) so that machine load does not end
sessions; sessions that still end on a heartbeat timeout are listed apart.

Goals (issue 9): false success ("self-deception") <= 1 % and false failure <= 5 % of at
least 200 scored sessions. Prints the matrices with Wilson 95 % intervals, per predicate,
and every false failure with the criteria behind it; writes
``bench/results/verifier_accuracy.json`` (every session id with its cell) and ``.md``. The
machine is shared: wall times are indicative only.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from _harness import parser, write_json

from phyagentos.agent.verifier import PredicateVerifier, load_evidence
from phyagentos.bench.random_world import random_episodes, with_limits
from phyagentos.bench.report import verifier_markdown
from phyagentos.bench.self_evolution import run_pass
from phyagentos.bench.verifier_scoring import (
    acting_ancestor,
    confusion,
    judged_ground_truth,
    load_ground_truth,
    score_session,
)
from phyagentos.protocol import Workspace


def _replayed(ws: Workspace, rec, attempt) -> dict:
    """The verdict the current SessionVerifier's predicates give on the session's recorded
    evidence (for an *another view* child: the acting ancestor's evidence with this view's
    terminal snapshot, as the coordinator judges it): ``success`` iff every criterion is
    satisfied and no safety event, as in :meth:`SessionVerifier.verify`."""
    evidence = load_evidence(ws.root / attempt.evidence)
    judged = rec
    anc = acting_ancestor(rec, ws.load_session)
    if anc is not None:
        base = load_evidence(ws.root / anc.attempts[-1].evidence)
        evidence, judged = replace(base, terminal=evidence.terminal), anc
    outcomes = PredicateVerifier().judge(judged, evidence)
    safety = any(str(e.get("code", "")).startswith("safety.") for e in evidence.events)
    ok = bool(outcomes) and all(o.status == "satisfied" for o in outcomes) and not safety
    return {"verdict": "success" if ok else "failure", "replayed": True,
            "criteria": [{"predicate": o.criterion.text, "status": o.status, "reason": o.reason} for o in outcomes]}


def score_pass(workspace: Path, session_ids=None, *, replay: bool = False) -> list[dict]:
    """Score every verified session of a workspace (or those of ``session_ids``) against its
    ground truth; with ``replay`` the verdicts are those of the current verifier on the
    recorded evidence (:func:`_replayed`) instead of the recorded ones."""
    ws = Workspace.open(workspace)
    if session_ids is None:
        session_ids = [s.session_id for s in ws.list_sessions()]
    scores = []
    for sid in session_ids:
        rec = ws.load_session(sid)
        attempt = rec.attempts[-1] if rec.attempts else None
        if attempt is None or attempt.verdict is None:
            continue
        gt = load_ground_truth(ws.root / attempt.evidence) if attempt.evidence else None
        anc = acting_ancestor(rec, ws.load_session)
        if anc is not None:  # scored against the acting session's start, as it is judged
            gt = judged_ground_truth(gt, load_ground_truth(ws.root / anc.attempts[-1].evidence))
        verdict = _replayed(ws, rec, attempt) if replay else attempt.verdict.model_dump()
        scores.append({"session_id": sid, "node": rec.node, "skill": rec.skill, "verdict": verdict["verdict"],
                       "cause": attempt.verdict.diagnosis.cause if attempt.verdict.diagnosis else None,
                       "reasons": {c["predicate"]: c["reason"] for c in verdict.get("criteria") or ()},
                       **score_session(accept=rec.accept, verdict=verdict, gt=gt)})
    return scores


def _pct(v) -> str:
    """A rate in %, or ``-`` when nothing was scored (every such criterion unscorable)."""
    return "-" if v is None else f"{v}%"


def _ci(v) -> str:
    return "-" if v is None else f"[{v[0]:.1f}, {v[1]:.1f}] %"


def report(v: dict, scores: list[dict], out: Path, extra: dict) -> None:
    """Print the matrices, the rates with Wilson intervals, per predicate, and the false
    failures; write ``out`` (JSON) and its ``.md``."""
    m = v["session_matrix"]
    print(f"{'':<26}{'truth met':>12}{'truth unmet':>14}")
    print(f"{'verdict success':<26}{m['true_success']:>12}{m['false_success']:>14}")
    print(f"{'verdict replan/failure':<26}{m['false_failure']:>12}{m['true_failure']:>14}")
    print(f"\nfalse success: {m['false_success']}/{v['sessions_scored']} = {v['false_success_rate_pct']}% of sessions, "
          f"95% CI {_ci(v['false_success_ci95_pct'])} (goal <= 1 %); "
          f"{v['false_success_given_unmet_pct']}% of truly failed ones")
    print(f"false failure: {m['false_failure']}/{v['sessions_scored']} = {v['false_failure_rate_pct']}% of sessions, "
          f"95% CI {_ci(v['false_failure_ci95_pct'])} (goal <= 5 %); "
          f"{v['false_failure_given_met_pct']}% of truly successful ones")
    print(f"\n{'criterion':<12}" + "".join(f"{k:>15}" for k in v["criterion_matrix"]))
    for name, row in sorted(v["per_predicate"].items()):
        print(f"{name:<12}" + "".join(f"{row[k]:>15}" for k in v["criterion_matrix"]))
    print(f"\n{'criterion':<12}{'scored':>8}{'false success':>16}{'95% CI':>18}{'false failure':>16}{'95% CI':>18}")
    for name, r in sorted(v["per_predicate_rates"].items()):
        print(f"{name:<12}{r['scored']:>8}{_pct(r['false_success_pct']):>16}{_ci(r['false_success_ci95_pct']):>18}"
              f"{_pct(r['false_failure_pct']):>16}{_ci(r['false_failure_ci95_pct']):>18}")
    hb = list(extra.get("heartbeat_timeout_sessions") or ())
    if hb:
        print(f"\nsessions that ended on a runner heartbeat timeout (machine load, never verified, not scored): "
              f"{len(hb)}")
    behind = []
    for s in scores:
        if s.get("session") != "false_failure":
            continue
        wrong = [c for c in s["criteria"] if c["truth"] and c["status"] != "satisfied"]
        behind.append({"session_id": s["session_id"], "skill": s.get("skill"), "verdict": s["verdict"],
                       "cause": s["cause"], "criteria": [{**c, "reason": (s.get("reasons") or {}).get(c["predicate"])}
                                                         for c in wrong]})
    if behind:
        print(f"\nfalse failures ({len(behind)}): the criteria met in truth that the verifier did not accept")
        for b in behind:
            for c in b["criteria"]:
                print(f"  {b['session_id']} ({b['skill']}, {b['verdict']}, cause {b['cause']}): {c['predicate']} "
                      f"{c['status']}: {(c['reason'] or '')[:160]}")
    write_json(out, {"benchmark": "verifier_accuracy", **extra, "verifier": v, "false_failures": behind,
                     "heartbeat_timeout_sessions": hb, "sessions": scores}, indent=1, say=False)
    md = verifier_markdown(v)
    md += ["| criterion | scored | false success | 95 % CI | false failure (incl. unknown while met) | 95 % CI |",
           "|---|---:|---:|---:|---:|---:|"]
    for name, r in sorted(v["per_predicate_rates"].items()):
        md.append(f"| {name} | {r['scored']} | {r['false_success_pct']} % | {_ci(r['false_success_ci95_pct'])} | "
                  f"{r['false_failure_pct']} % | {_ci(r['false_failure_ci95_pct'])} |")
    out.with_suffix(".md").write_text("\n".join(md) + "\n", encoding="utf-8")
    print(f"wrote {out}")


def _workspaces(paths) -> list[Path]:
    """Workspaces named by ``paths``: a workspace itself, or a chunked root (``chunk-*/ws``)."""
    out = []
    for p in paths:
        p = Path(p)
        if (p / "SESSIONS.md").is_file():
            out.append(p)
        out.extend(sorted(w for w in p.glob("chunk-*/ws") if (w / "SESSIONS.md").is_file()))
    return out


def score_only(paths, out: Path, extra: dict | None = None, *, replay: bool = False) -> int:
    """Score and merge every verified session in the workspaces under ``paths`` (``replay``:
    with the current verifier's verdicts on the recorded evidence)."""
    workspaces = _workspaces(paths)
    if not workspaces:
        print(f"no workspace under {[str(p) for p in paths]}", file=sys.stderr)
        return 2
    scores, runs, heartbeat = [], set(), []
    for w in workspaces:
        ws = Workspace.open(w)
        sessions = ws.list_sessions()
        runs |= {(str(w), s.run_id) for s in sessions}
        heartbeat += [s.session_id for s in sessions if any(a.error is not None and str(a.error.code).startswith(
            "heartbeat.") for a in ws.load_session(s.session_id).attempts)]
        scores.extend(score_pass(w, replay=replay))
    v = confusion(scores)
    print(f"verifier accuracy{' (REPLAYED: the current verifier on recorded evidence)' if replay else ''} "
          f"(scored from {len(workspaces)} workspace(s)): {len(runs)} episode runs, "
          f"{v['sessions_scored']} sessions scored ({v['sessions_unscored']} unscored)")
    report(v, scores, out, {**(extra or {}), "scored_from": [str(w) for w in workspaces], "episode_runs": len(runs),
                            "heartbeat_timeout_sessions": heartbeat, "replayed": replay})
    return 0


def main() -> int:
    ap = parser(__doc__, "verifier_accuracy")
    ap.add_argument("--episodes", type=int, default=100, help="randomised pick-and-place episodes (default 100)")
    ap.add_argument("--first-seed", type=int, default=20000, help="seed of the first episode (default 20000)")
    ap.add_argument("--workspace", type=Path, help="keep the chunk workspaces here and resume finished chunks "
                                                   "(default: a temporary directory)")
    ap.add_argument("--chunk", type=int, default=10, help="seeds per chunk workspace (default 10)")
    ap.add_argument("--heartbeat-timeout", type=float, default=60.0,
                    help="runner heartbeat timeout of every session, s (default 60: machine load must not end "
                         "sessions; the timeouts left are counted apart)")
    ap.add_argument("--score-only", type=Path, nargs="+", metavar="DIR",
                    help="score and merge the verified sessions already in DIR (a workspace or a chunked root), exit")
    ap.add_argument("--replay", action="store_true",
                    help="with --score-only: judge the recorded evidence again with the current verifier's predicates "
                         "(the session set stays the recorded one)")
    args = ap.parse_args()
    if args.score_only:
        return score_only(args.score_only, args.out, replay=args.replay)
    tmp = None if args.workspace else tempfile.TemporaryDirectory(prefix="verifier_accuracy_")
    root = args.workspace or Path(tmp.name)
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    started = time.perf_counter()
    seeds = list(range(args.first_seed, args.first_seed + args.episodes))
    episode_results = []
    for i in range(0, len(seeds), max(1, args.chunk)):
        chunk = seeds[i:i + max(1, args.chunk)]
        cdir = root / f"chunk-{chunk[0]}"
        done = cdir / "done.json"
        if done.is_file():
            earlier = json.loads(done.read_text(encoding="utf-8"))
            if earlier.get("seeds") != chunk:
                raise SystemExit(f"{cdir} holds seeds {earlier.get('seeds')}, not {chunk}: use the same --chunk "
                                 "as before or another --workspace")
            say(f"chunk {chunk[0]}..{chunk[-1]}: finished earlier, skipped")
            episode_results.extend(earlier["episodes"])
            continue
        if (cdir / "ws").exists():  # an interrupted chunk: run it again from scratch
            import shutil

            shutil.rmtree(cdir / "ws")
        cdir.mkdir(parents=True, exist_ok=True)
        episodes = with_limits(random_episodes(chunk), heartbeat_timeout_s=args.heartbeat_timeout)
        p = run_pass(f"verifier accuracy {chunk[0]}..{chunk[-1]}", episodes, cdir / "ws",
                     use_memory=False, consolidate=False, progress=say)
        eps = [{"episode_id": e.episode_id, "first": e.first_attempt_success, "final": e.final_success,
                "sessions": list(e.session_ids), "causes": list(e.causes)} for e in p.episodes]
        done.write_text(json.dumps({"seeds": chunk, "episodes": eps}) + "\n", encoding="utf-8")
        episode_results.extend(eps)
    wall = time.perf_counter() - started
    n = len(episode_results)
    first = sum(e["first"] for e in episode_results) / n if n else 0.0
    final = sum(e["final"] for e in episode_results) / n if n else 0.0
    print(f"\n{n} randomised episodes (seeds {seeds[0]}..{seeds[-1]}), {wall:.0f} s wall on a shared machine; "
          f"first-attempt success {first:.0%}, final {final:.0%}")
    rc = score_only([root], args.out, {"episodes": n, "first_seed": args.first_seed, "wall_time_s": round(wall, 1),
                                       "first_attempt_rate": round(first, 4), "final_rate": round(final, 4),
                                       "episode_results": episode_results})
    if tmp is not None:
        tmp.cleanup()
    return rc


if __name__ == "__main__":
    raise SystemExit(main())
