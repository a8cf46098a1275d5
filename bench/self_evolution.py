"""Self-evolution on randomised tabletop worlds: does memory beat no memory and the best fixed defaults?

    nice -n 10 .venv/bin/python bench/self_evolution.py [--train 30] [--heldout 30] [--defaults FILE]

Episodes: pick-and-place goal graphs over randomised scenes
(:mod:`phyagentos.bench.random_world`; failures arise from the drawn world -- size,
shape, mass, friction, distractors -- nothing is scripted), through the ordinary path
(``run_goal_graph``: supervisor, runner, verifier, recovery, memory). Passes:

1. **learn**: training seeds (0..``--train``-1 + ``--seed-offset``), memory retrieved
   and consolidated as it grows (the agent learns as it goes);
2. **memory (frozen)**: held-out seeds (10000..), starting from a copy of pass 1's
   memory, retrieved but never written;
3. **no memory**: the same held-out seeds, nothing retrieved or written;
4. **best fixed defaults**: the same held-out seeds, no memory, every node run with the
   fixed per-skill parameters of ``--defaults`` (a YAML/JSON mapping ``skill -> {param:
   value}``, e.g. the runtime's documented sweep). Without ``--defaults`` the shipped
   tree defaults are the fixed defaults and pass 4 is pass 3; the table says so.

A memory gain counts only where pass 2 beats both pass 3 and pass 4 on the held-out
seeds. First: every node succeeded with its first session; Final: after verifier-driven
recovery. Prints a table and writes ``bench/results/self_evolution.json`` (every episode
with its session ids and the memory items applied). Whatever comes out is reported,
including no gain; the machine is shared, so wall times are indicative only.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path


from phyagentos.bench.random_world import random_episodes, with_defaults
from phyagentos.protocol import Workspace
from phyagentos.self_evolution import run_pass
from phyagentos.errors import BenchError
from phyagentos.yamlsource import read_yaml

HERE = Path(__file__).resolve().parent


def _wilson(k: int, n: int) -> tuple[float, float]:
    """95 % Wilson score interval of a rate k/n (Wilson 1927), as fractions."""
    if not n:
        return (0.0, 0.0)
    z, p = 1.96, k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / d
    return (round(c - h, 3), round(c + h, 3))


def _episodes_of(workspace: Path) -> dict[str, dict]:
    """Episode (graph name) -> First / Final / sessions / memory items, from a pass workspace's sessions."""
    ws = Workspace.open(workspace)
    runs: dict[str, list] = {}
    for s in ws.list_sessions():
        runs.setdefault(s.run_id, []).append(s)
    out = {}
    # passes run their episodes in list order, one run each: the n-th run is the n-th episode
    for index, run_id in enumerate(sorted(runs)):
        sessions = runs[run_id]
        name = f"episode-{index}"
        nodes = {s.node for s in sessions}
        latest = {n: max((s for s in sessions if s.node == n), key=lambda s: int(s.session_id.rsplit("-", 1)[1]))
                  for n in nodes}
        terminal = ("succeeded", "failed", "rejected", "timed_out", "cancelled")
        if any(s.state not in terminal for s in latest.values()) or \
                (len(nodes) < 2 and all(s.state == "succeeded" for s in latest.values())):
            continue  # unfinished episode (interrupted run)
        first = all(any(s.parent_session_id is None and s.state == "succeeded" for s in sessions if s.node == n)
                    for n in nodes) and len(nodes) == 2
        final = all(latest[n].state == "succeeded" for n in nodes) and len(nodes) == 2
        used = sorted({i.id for s in sessions if s.context for i in s.context.items if i.applied})
        out[name] = {"first": first, "final": final, "sessions": [s.session_id for s in sessions], "memory": used,
                     "causes": [s.attempts[-1].verdict.diagnosis.cause for s in sessions if s.attempts
                                and s.attempts[-1].verdict and s.attempts[-1].verdict.diagnosis]}
    return out


def score_only(root: Path, out: Path) -> int:
    """Summarise the pass workspaces (pass1..pass4) under ``root``; held-out passes are
    compared on the episodes every one of them finished."""
    passes = {p.name: _episodes_of(p) for p in sorted(root.glob("pass*")) if (p / "SESSIONS.md").is_file()}
    held = [k for k in passes if k != "pass1"]
    common = set.intersection(*(set(passes[k]) for k in held)) if held else set()
    rows = []
    print(f"self-evolution (scored from {root}); held-out passes compared on {len(common)} common episode(s)")
    print(f"{'pass':<8}{'episodes':>9}{'first':>8}{'95% CI':>15}{'final':>8}{'memory used':>13}")
    for name, eps in passes.items():
        chosen = {k: v for k, v in eps.items() if name == "pass1" or k in common}
        n, k = len(chosen), sum(v["first"] for v in chosen.values())
        final = sum(v["final"] for v in chosen.values())
        used = sum(1 for v in chosen.values() if v["memory"])
        rows.append({"pass": name, "episodes": n, "first": k, "final": final, "first_ci95": _wilson(k, n),
                     "episodes_with_memory_applied": used, "results": chosen})
        print(f"{name:<8}{n:>9}{(k / n if n else 0):>8.0%}{str(_wilson(k, n)):>15}{(final / n if n else 0):>8.0%}"
              f"{used:>13}")
    mem = Workspace.open(root / "pass1") if (root / "pass1" / "SESSIONS.md").is_file() else None
    if mem is not None:
        lessons = mem.read("LESSONS").data
        print(f"memory after pass 1: {len(lessons.lessons)} verified lessons, {len(lessons.candidates)} candidates, "
              f"{len(mem.read('KNOWLEDGE').data.entries)} knowledge entries")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"benchmark": "self_evolution", "scored_from": str(root), "passes": rows}, indent=1)
                   + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", type=int, default=30, help="training episodes for pass 1 (default 30)")
    ap.add_argument("--heldout", type=int, default=30, help="held-out episodes for passes 2-4 (default 30)")
    ap.add_argument("--seed-offset", type=int, default=0, help="first training seed (held-out: offset + 10000)")
    ap.add_argument("--defaults", type=Path, help="best fixed defaults, YAML/JSON skill -> {param: value}")
    ap.add_argument("--workspace", type=Path, help="keep the workspaces here (default: a temporary directory)")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "self_evolution.json")
    ap.add_argument("--score-only", type=Path, metavar="ROOT",
                    help="summarise the pass workspaces under ROOT (e.g. an interrupted --workspace run) and exit")
    args = ap.parse_args()
    if args.score_only:
        return score_only(args.score_only, args.out)
    train = random_episodes(range(args.seed_offset, args.seed_offset + args.train))
    heldout = random_episodes(range(args.seed_offset + 10000, args.seed_offset + 10000 + args.heldout))
    defaults = read_yaml(args.defaults, error=BenchError) if args.defaults else None
    tmp = None if args.workspace else tempfile.TemporaryDirectory(prefix="self_evolution_")
    root = args.workspace or Path(tmp.name)
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    started = time.perf_counter()
    p1 = run_pass("1 learn (train)", train, root / "pass1", use_memory=True, consolidate=True, progress=say)
    memory = Workspace.open(p1.workspace)
    p2 = run_pass("2 memory frozen", heldout, root / "pass2", use_memory=True, consolidate=False, memory_from=memory,
                  progress=say)
    p3 = run_pass("3 no memory", heldout, root / "pass3", use_memory=False, consolidate=False, progress=say)
    passes = [p1, p2, p3]
    if defaults:
        passes.append(run_pass("4 fixed defaults", with_defaults(heldout, defaults), root / "pass4", use_memory=False,
                               consolidate=False, progress=say))
    wall = time.perf_counter() - started

    print(f"\nself-evolution on randomised worlds: {len(train)} training + {len(heldout)} held-out episodes, "
          f"{wall:.0f} s wall (shared machine)")
    head = f"{'pass':<20}{'episodes':>9}{'first':>8}{'95% CI':>15}{'final':>8}{'sessions':>10}{'memory used':>13}"
    print(head + "\n" + "-" * len(head))
    rows = []
    for p in passes:
        k = sum(e.first_attempt_success for e in p.episodes)
        ci = _wilson(k, len(p.episodes))
        used = sum(1 for e in p.episodes if e.memory_items)
        rows.append({**p.to_dict(), "first_ci95": ci, "episodes_with_memory_applied": used})
        print(f"{p.name:<20}{len(p.episodes):>9}{p.first_attempt_rate:>8.0%}{str(ci):>15}{p.final_rate:>8.0%}"
              f"{p.sessions:>10}{used:>13}")
    if not defaults:
        print("fixed defaults: none given (--defaults); the shipped tree defaults are the fixed defaults, "
              "i.e. pass 3")
    base = max(r["first_attempt_rate"] for r in rows[2:])
    gain = round(rows[1]["first_attempt_rate"] - base, 4)
    print(f"\nmemory gain on held-out seeds (First, pass 2 minus the best baseline): {gain:+.1%}"
          f"{'' if gain > 0 else ' -- no gain'}")
    print(f"memory after pass 1: {p1.lessons} verified lessons, {p1.candidates} candidates, {p1.knowledge} knowledge "
          f"entries, {p1.procedures} promoted procedures")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": "self_evolution", "world": "phyagentos.bench.random_world", "train": args.train,
              "heldout": args.heldout, "seed_offset": args.seed_offset, "defaults": defaults,
              "wall_time_s": round(wall, 1), "memory_gain_first_points": round(100 * gain, 2), "passes": rows}
    args.out.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
