"""Perception accuracy per LIBERO object category on generated scenes, against the true poses.

    .venv/bin/python bench/libero_perception.py [--suite libero_object] [--tasks 0-9] [--scenes 4]
        [--config '{"clustering": {...}}'] [--out bench/results/libero_perception.json]

For each task world: the looks of its categories are measured on generated cluttered scenes
(:func:`phyagentos.targets.libero.descriptors.measure_descriptors`, seeds from 12345), then the
perceiver, given the task's objects by name, category and look, observes ``--scenes`` further
generated scenes (seeds from 50000: every object of the task at a random free spot and yaw,
the arm at its start pose, both cameras) and each object is scored against the true
footprint (:func:`~phyagentos.targets.libero.descriptors.perception_accuracy`): correct,
wrong (named but elsewhere), unknown (below confidence 0.5) or unseen. Never an init state.

Ground truth is read here (scoring code), never by the Agent plane. Prints the table per
category and writes the JSON (rows, per-category counts, looks, wall time).
"""

from __future__ import annotations

import time
from collections import Counter, defaultdict

from _harness import index_range, parser, with_overrides, write_json

from phyagentos.targets.libero import LiberoScene, LiberoTarget
from phyagentos.targets.libero.descriptors import measure_descriptors, perception_accuracy

EVAL_SEED = 50000


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_perception")
    ap.add_argument("--suite", default="libero_object")
    ap.add_argument("--tasks", default="0-9")
    ap.add_argument("--scenes", type=int, default=4, help="generated evaluation scenes per task world")
    ap.add_argument("--config", default=None, help="perception config overrides (JSON), else the target's")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows, all_looks = [], {}
    for task in index_range(args.tasks):
        with LiberoTarget("libero_perception", LiberoScene(suite=args.suite, task=task), seed=0) as target:
            cfg = with_overrides(target.perception_config(), args.config)
            looks = measure_descriptors(target, config=cfg)
            all_looks.update(looks)
            seeds = [EVAL_SEED + 100 * task + k for k in range(args.scenes)]
            got = perception_accuracy(target, looks, seeds, config=cfg)
            for r in got:
                r["task"] = task
            rows.extend(got)
            c = Counter(r["outcome"] for r in got)
            print(f"task {task}: {dict(c)}  ({time.perf_counter() - t0:.0f} s)", flush=True)
    per = defaultdict(Counter)
    for r in rows:
        per[r["category"]][r["outcome"]] += 1
    print(f"\n{'category':18s} {'n':>3s} correct wrong unknown unseen")
    for cat in sorted(per):
        c = per[cat]
        n = sum(c.values())
        print(f"{cat:18s} {n:3d} {c['correct'] / n:7.2f} {c['wrong']:5d} {c['unknown']:7d} {c['unseen']:6d}")
    tot = Counter(r["outcome"] for r in rows)
    n = sum(tot.values())
    print(f"{'all':18s} {n:3d} {tot['correct'] / n:7.2f} {tot['wrong']:5d} {tot['unknown']:7d} {tot['unseen']:6d}")
    wall = time.perf_counter() - t0
    print(f"wall {wall:.0f} s")
    write_json(args.out, {"suite": args.suite, "tasks": args.tasks, "scenes": args.scenes,
                          "config": args.config, "per_category": {k: dict(v) for k, v in per.items()},
                          "total": dict(tot), "looks": all_looks, "rows": rows, "wall_s": round(wall, 1)}, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
