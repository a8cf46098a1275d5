"""The rule ladder against the model reviser on the same real failures from randomised worlds.

    nice -n 10 .venv/bin/python bench/reviser_compare.py [--seeds 24] [--so101-seeds 12] [--first-seed 0] [--workers 2]

Failures are collected, not scripted: each episode is a randomised tabletop world
(:func:`phyagentos.bench.random_world.random_episodes`: the target draws the object's shape,
size, mass, friction, yaw and position and 0-4 distractors from the seed; no perturbations),

* ``franka``: pick, then place over a 30 cm wall into the goal region, on the Franka;
* ``so101``: the same world's pick alone, without the wall (the SO-101's home pose reaches
  into it), on the SO-101 (``--target so101_tabletop``), whose short arm does not reach every
  drawn position.

Phase 1 runs every episode with the rule ladder (``phyagentos run --reviser rules``, its own
process and fresh workspace, memory off); an episode whose run had any verdict other than
success is a *failure* (the first such session's node and cause identify it). Phase 2 runs
each failure again with the model reviser (``--reviser model``: the offline model, the ladder
as fallback, re-targeting through the selector); simulation, perception noise and the first
attempt are seeded, so the same failure recurs -- checked: an episode counts as *the same
failure* only when the model run's first unsuccessful session has the same node and cause.
Reported per reviser: rescued / attempted (final success of the run / same failures), by
cause, with who proposed each revision. Writes bench/results/reviser_compare.json.
Timings on a shared, loaded 2-core machine.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import yaml
from _harness import parser, write_json

import phyagentos  # noqa: F401  (headless GL before mujoco)
from phyagentos.bench.random_world import random_episodes
from phyagentos.protocol import Workspace

RESULTS = Path(__file__).resolve().parent / "results"


def _without_obstacles(ep):
    """The episode without its wall: the SO-101's home pose reaches into it (the graph check refuses
    the whole graph before anything moves), and the pick alone does not need it."""
    graph = {**ep.graph, "scene": {k: v for k, v in ep.graph["scene"].items() if k != "obstacles"}}
    return type(ep)(episode_id=ep.episode_id, kind=ep.kind, seed=ep.seed, graph=graph)


def run_episode(kind: str, ep, reviser: str, root: Path) -> dict[str, Any]:
    """One ``phyagentos run`` of episode ``ep`` with ``reviser``; its sessions summarised."""
    graph = root / f"{kind}-{ep.episode_id}.yaml"
    graph.write_text(yaml.safe_dump(ep.graph, sort_keys=False))
    ws = root / f"ws-{kind}-{ep.episode_id}-{reviser}"
    cmd = [str(Path(sys.executable).with_name("phyagentos")), "run", str(graph), "--workspace", str(ws), "--json",
           "--seed", str(ep.seed), "--memory", "off", "--reviser", reviser]
    if kind == "so101":
        cmd += ["--target", "so101_tabletop"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    row: dict[str, Any] = {"suite": kind, "episode": ep.episode_id, "seed": ep.seed, "reviser": reviser,
                           "rc": proc.returncode, "seconds": round(time.perf_counter() - t0, 1)}
    try:
        report = json.loads(proc.stdout)
    except json.JSONDecodeError:
        row.update(succeeded=False, refused=True, error=(proc.stderr or proc.stdout)[-300:])
        return row
    sessions = report["sessions"]
    bad = [s for s in sessions if s["verdict"] != "success"]
    row.update(succeeded=report["succeeded"], refused=False, sessions=len(sessions),
               failure=({"node": bad[0]["node"], "cause": bad[0]["cause"] or bad[0]["status"]} if bad else None),
               strategies=[s["strategy"] for s in sessions if s["strategy"]],
               targets=sorted({s["target"] for s in sessions}))
    w = Workspace.open(ws)
    proposed = []
    for s in sessions:
        rec = w.load_session(s["session_id"])
        v = rec.attempts[-1].verdict if rec.attempts else None
        if v is not None and v.revision is not None:
            proposed.append({"session": s["session_id"], "cause": v.revision.cause, "strategy": v.revision.strategy,
                             "proposed_by": v.revision.proposed_by, "target": v.revision.target})
    row["revisions"] = proposed
    return row


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "reviser_compare")
    ap.add_argument("--seeds", type=int, default=24, help="Franka pick-and-place episodes (N seeds from --first-seed)")
    ap.add_argument("--so101-seeds", type=int, default=12, help="SO-101 pick episodes (N seeds from --first-seed)")
    ap.add_argument("--first-seed", type=int, default=0, help="seeds start here (both suites)")
    ap.add_argument("--workers", type=int, default=2, help="runs at once (each its own process and workspace)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the workspaces under this directory")
    args = ap.parse_args(argv)
    first = args.first_seed
    jobs = [("franka", ep) for ep in random_episodes(range(first, first + args.seeds))]
    jobs += [("so101", _without_obstacles(ep))
             for ep in random_episodes(range(first, first + args.so101_seeds), place=False)]
    root = Path(tempfile.mkdtemp(prefix="phyagentos-revisers-")) if args.keep is None else args.keep
    root.mkdir(parents=True, exist_ok=True)

    def go(job, reviser):
        kind, ep = job
        row = run_episode(kind, ep, reviser, root)
        print(f"{reviser:5s} {kind:6s} {ep.episode_id:12s} succeeded={row['succeeded']} failure={row.get('failure')} "
              f"strategies={row.get('strategies')} {row['seconds']}s", file=sys.stderr, flush=True)
        return row

    with ThreadPoolExecutor(max_workers=max(1, args.workers)) as pool:
        rules = list(pool.map(lambda j: go(j, "rules"), jobs))
        failed = [(j, r) for j, r in zip(jobs, rules) if not r["refused"] and r["failure"] is not None]
        model = list(pool.map(lambda jr: go(jr[0], "model"), failed))
    pairs = []
    for (job, r), m in zip(failed, model):
        same = m.get("failure") == r["failure"]
        pairs.append({"suite": job[0], "episode": job[1].episode_id, "failure": r["failure"], "same_failure": same,
                      "model_failure": m.get("failure"), "rules": r, "model": m})
    summary: dict[str, Any] = {}
    for suite in ("franka", "so101", "all"):
        ps = [p for p in pairs if p["same_failure"] and (suite == "all" or p["suite"] == suite)]
        summary[suite] = {
            "episodes": sum(1 for j in jobs if suite == "all" or j[0] == suite),
            "refused_before_running": sum(1 for j, r in zip(jobs, rules) if r["refused"] and (suite == "all" or j[0] == suite)),
            "failures": sum(1 for p in pairs if suite == "all" or p["suite"] == suite),
            "same_failures": len(ps),
            "rules_rescued": sum(p["rules"]["succeeded"] for p in ps),
            "model_rescued": sum(p["model"]["succeeded"] for p in ps),
            "by_cause": {c: {"n": n, "rules": sum(p["rules"]["succeeded"] for p in ps if p["failure"]["cause"] == c),
                             "model": sum(p["model"]["succeeded"] for p in ps if p["failure"]["cause"] == c)}
                         for c, n in Counter(p["failure"]["cause"] for p in ps).most_common()},
            "model_proposals": dict(Counter(r["proposed_by"] for p in ps for r in p["model"]["revisions"])),
        }
    out = {"machine": "shared 2-core, loaded (other engineers' tests running)", "summary": summary, "pairs": pairs,
           "rules_runs": rules}
    write_json(args.out, out, indent=1, say=False)
    print(f"\n{'suite':7s} {'episodes':>8s} {'failures':>8s} {'same':>5s} {'rules rescued':>14s} {'model rescued':>14s}")
    for suite, s in summary.items():
        print(f"{suite:7s} {s['episodes']:8d} {s['failures']:8d} {s['same_failures']:5d} "
              f"{s['rules_rescued']:>7d}/{s['same_failures']:<6d} {s['model_rescued']:>7d}/{s['same_failures']:<6d}")
    for suite, s in summary.items():
        if suite == "all":
            continue
        for cause, c in s["by_cause"].items():
            print(f"  {suite:6s} {cause:20s} n={c['n']:2d} rules {c['rules']}/{c['n']} model {c['model']}/{c['n']}")
    print(f"model-run revisions by proposer: {summary['all']['model_proposals']}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
