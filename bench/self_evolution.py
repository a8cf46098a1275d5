"""Self-evolution on the MuJoCo Franka: first-attempt and final success, before and after memory.

    .venv/bin/python bench/self_evolution.py [--seeds 5] [--heldout 5] [--pick-only]

Episodes: every perturbation kind of phyagentos.targets.perturbations (perception noise,
low friction, displaced, heavy object) plus unperturbed ones, each over ``--seeds``
seeds (cube position and perturbation draws), as pick-and-place goal graphs. Passes,
through the ordinary path (run_goal_graph: supervisor, runner, verifier, recovery):

1. empty memory (nothing retrieved), verdicts consolidated into LESSONS/KNOWLEDGE/SKILL.md;
2. the same episodes with pass 1's memory, frozen;
3. held-out episodes (seeds never seen in pass 1) with pass 1's memory, frozen.

First-attempt success: every node's first session succeeded; final: every node
succeeded after verifier-driven recovery (at most 2 replans per node). Prints a table
and writes bench/results/self_evolution.json (every episode with its session ids).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from phyagentos.protocol import Workspace
from phyagentos.self_evolution import PERTURBATION_KINDS, perturbed_episodes, run_pass

HERE = Path(__file__).resolve().parent


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="seeds per episode kind in passes 1 and 2 (default 5)")
    ap.add_argument("--heldout", type=int, default=5, help="held-out seeds per kind in pass 3 (default 5, 0 skips)")
    ap.add_argument("--pick-only", action="store_true", help="pick graphs instead of pick and place")
    ap.add_argument("--workspace", type=Path, help="keep the workspaces here (default: a temporary directory)")
    ap.add_argument("--out", type=Path, default=HERE / "results" / "self_evolution.json")
    args = ap.parse_args()
    kinds = (*PERTURBATION_KINDS, None)
    place = not args.pick_only
    episodes = perturbed_episodes(range(args.seeds), kinds=kinds, place=place)
    heldout = perturbed_episodes(range(1000, 1000 + args.heldout), kinds=kinds, place=place) if args.heldout else []
    tmp = None if args.workspace else tempfile.TemporaryDirectory(prefix="self_evolution_")
    root = args.workspace or Path(tmp.name)
    started = time.perf_counter()
    say = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    p1 = run_pass("1 empty memory", episodes, root / "pass1", use_memory=False, consolidate=True, progress=say)
    memory = Workspace.open(p1.workspace)
    p2 = run_pass("2 with memory", episodes, root / "pass2", use_memory=True, consolidate=False, memory_from=memory,
                  progress=say)
    passes = [p1, p2]
    if heldout:
        passes.append(run_pass("3 held-out, memory", heldout, root / "pass3", use_memory=True, consolidate=False,
                               memory_from=memory, progress=say))
    wall = time.perf_counter() - started

    print(f"\nself-evolution: {len(episodes)} episodes ({args.seeds} seeds x {len(kinds)} kinds, "
          f"{'pick and place' if place else 'pick'}), {wall:.0f} s")
    head = f"{'pass':<22}{'episodes':>9}{'first':>8}{'final':>8}{'sessions':>10}{'wall s':>8}"
    print(head + "\n" + "-" * len(head))
    for p in passes:
        print(f"{p.name:<22}{len(p.episodes):>9}{p.first_attempt_rate:>8.0%}{p.final_rate:>8.0%}{p.sessions:>10}"
              f"{p.wall_time_s:>8.0f}")
    print(f"\n{'kind':<18}" + "".join(f"{'pass ' + p.name.split()[0]:>18}" for p in passes))
    print(f"{'':<18}" + "".join(f"{'first / final':>18}" for _ in passes))
    for kind in [k or "none" for k in kinds]:
        cells = []
        for p in passes:
            k = p.by_kind.get(kind, {})
            cells.append(f"{k.get('first_attempt_rate', 0):>6.0%} / {k.get('final_rate', 0):<6.0%}")
        print(f"{kind:<18}" + "".join(f"{c:>18}" for c in cells))
    print(f"\nmemory after pass 1: {p1.lessons} verified lessons, {p1.candidates} candidates, {p1.knowledge} knowledge "
          f"entries, {p1.procedures} promoted procedures")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": "self_evolution", "graph": "pick_and_place" if place else "pick", "kinds": [k or "none" for k in kinds],
              "seeds": args.seeds, "heldout_seeds": args.heldout, "wall_time_s": round(wall, 1),
              "passes": [p.to_dict() for p in passes]}
    args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
