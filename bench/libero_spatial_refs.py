"""Which bowl perception names in libero_spatial's worlds, scored against the true poses.

    .venv/bin/python bench/libero_spatial_refs.py [--tasks 0-9] [--inits 0-4] [--workspace /tmp/ws_spatial]
        [--out bench/results/libero_spatial_refs.json]

For each task and init state: the goal graph's declared scene as the LIBERO bench writes it
(looks of the categories measured on generated scenes, cached in the workspace; the bowl the
instruction's relation picks out declared with ``where`` by the rule reader), one perception
of the world at its start pose (``perceive_now``, both cameras), and the resolution the
snapshot reports. Scoring (this script only, never the Agent plane): the perceived
``akita_black_bowl_1`` is compared with the true positions of both bowls; LIBERO's goal names
the bowl it means. Prints one line per world and the totals: worlds, resolved, resolved to the
bowl LIBERO means, resolved to the other.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from _harness import index_range, parser, write_json

from phyagentos.bench.libero import _descriptors, instruction_plan
from phyagentos.primitives.observation import make_perceiver, perceive_now
from phyagentos.targets.libero import LiberoScene, LiberoTarget, parse_bddl, resolve_task

SUITE = "libero_spatial"
BOWLS = ("akita_black_bowl_1", "akita_black_bowl_2")


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_spatial_refs")
    ap.add_argument("--tasks", default="0-9")
    ap.add_argument("--inits", default="0-4")
    ap.add_argument("--workspace", default="/tmp/ws_spatial", help="where the looks are cached")
    args = ap.parse_args(argv)
    ws = Path(args.workspace)
    (ws / "libero").mkdir(parents=True, exist_ok=True)
    tasks = index_range(args.tasks)
    looks = _descriptors(ws, SUITE, tasks)
    rows = []
    for i in tasks:
        task = resolve_task(SUITE, i)
        problem = parse_bddl(task.bddl_path)
        _, where = instruction_plan(task.instruction, problem.objects, problem.fixtures)
        declared = problem.declared()
        objects = tuple({**o, **looks.get(o["class"], {}), **({"where": where[o["name"]]} if o["name"] in where else {})}
                        for o in declared["objects"])
        for k in index_range(args.inits):
            t0 = time.perf_counter()
            scene = LiberoScene(suite=SUITE, task=i, init=k, objects=objects, fixtures=tuple(declared["fixtures"]))
            with LiberoTarget("spatial_refs", scene, seed=k) as target:
                snap = perceive_now(target, make_perceiver(target))
                truth = target.ground_truth()  # scoring only
            ref = (snap.get("references") or {}).get(BOWLS[0], {})
            seen = {e["name"]: e for e in snap["entities"] if e["kind"] == "object"}
            named = None
            if BOWLS[0] in seen:
                p = np.asarray(seen[BOWLS[0]]["position"][:2], float)
                named = min(BOWLS, key=lambda n: float(np.linalg.norm(np.asarray(truth["objects"][n]["position"][:2]) - p)))
            row = {"task": i, "init": k, "relation": where.get(BOWLS[0], {}).get("relation"),
                   "resolved": bool(ref.get("resolved")), "reason": ref.get("reason"), "named_true": named,
                   "goal": truth["bddl"]["goal"], "unseen": snap["unseen"], "s": round(time.perf_counter() - t0, 1)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    # LIBERO's goal of every libero_spatial task is (On akita_black_bowl_1 plate_1)
    resolved = [r for r in rows if r["resolved"]]
    right = [r for r in resolved if r["named_true"] == BOWLS[0]]
    totals = {"worlds": len(rows), "resolved": len(resolved), "right_bowl": len(right),
              "wrong_bowl": len(resolved) - len(right)}
    print(json.dumps(totals))
    write_json(args.out, {"rows": rows, "totals": totals}, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
