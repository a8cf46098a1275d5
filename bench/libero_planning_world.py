"""How near the motion planner's perceived world stands to the simulator's, on generated LIBERO scenes.

    .venv/bin/python bench/libero_planning_world.py [--tasks libero_goal/0-9,libero_10/0-9]
        [--seeds 73000-73001] [--workspace /tmp/ws_pw] [--out bench/results/libero_planning_world.json]

Since the nineteenth pass of issue 28 the Runtime plane plans LIBERO's motions in the world its
robot perceived (:mod:`phyagentos.primitives.planning_world`), not the simulator's state. This
measures that world where each session starts: for each task (its BDDL objects and fixtures
declared with their looks, measured on generated scenes and cached in ``--workspace``; no
spatial references, so of two identical objects either may take either name) and each seed
(LIBERO's placement sampler, seeds from 73000: never an init state), one perception at the start
pose with both cameras, then the planning world built from it is compared with the simulator
(read here for scoring only): for each object and fixture, the box of its collision geometry
(world axes) against the true one, or the nearest true one of its category for identical twins:
the distance between their centres (m) and their intersection over union; or that it was left
out (not perceived); for each drawer, its opening against the true one (m). Prints a table per
category and the totals; writes every placement to ``--out``.
"""

from __future__ import annotations

import time
from collections import defaultdict
from types import SimpleNamespace

import mujoco
import numpy as np
from _harness import index_range, parser, percentile, print_table, write_json
from _libero_scene import fresh_perceiver, generated_scene

from phyagentos.primitives import planning_world
from phyagentos.primitives.motion import session_checker
from phyagentos.primitives.observation import perceive_now
from phyagentos.targets.libero import LiberoTarget

SEED = 73000


def _box(model, data, root: int) -> tuple[np.ndarray, np.ndarray]:
    """``(lo (3,), hi (3,))`` world m: the axis-aligned box of the collision geoms of every
    body under root body ``root`` in ``data``."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for g in range(model.ngeom):
        if int(model.body_rootid[int(model.geom_bodyid[g])]) != root or not (model.geom_contype[g]
                                                                             or model.geom_conaffinity[g]):
            continue
        R = data.geom_xmat[g].reshape(3, 3)
        c = data.geom_xpos[g] + R @ model.geom_aabb[g, :3]
        h = np.abs(R) @ model.geom_aabb[g, 3:]
        lo, hi = np.minimum(lo, c - h), np.maximum(hi, c + h)
    return lo, hi


def _iou(a, b) -> float:
    inter = np.clip(np.minimum(a[1], b[1]) - np.maximum(a[0], b[0]), 0.0, None).prod()
    vol = (a[1] - a[0]).prod() + (b[1] - b[0]).prod() - inter
    return float(inter / vol) if vol > 0 else 0.0


def measure(workspace: str, suite: str, task: int, seeds: list[int]) -> list[dict]:
    """One row per object, fixture and drawer of ``suite`` task ``task`` on each generated
    scene ``seeds``: how the planning world from one look at the start pose stands to the
    simulator's state."""
    scene = generated_scene(workspace, suite, task)
    rows = []
    with LiberoTarget("planning_world", scene, seed=seeds[0]) as target:
        bodies = target.planning_bodies()
        m = target.model
        for seed in seeds:
            perceiver = fresh_perceiver(target, seed)
            target.runtime_notes.pop(planning_world.WORLD_NOTE, None)
            perceive_now(target, perceiver)
            checker = session_checker(SimpleNamespace(target=target))
            mujoco.mj_kinematics(checker.model, checker.data)
            truth = {name: _box(m, target.data, m.body(body).id)
                     for name, body in (*bodies.objects.items(), *bodies.fixtures.items())}
            category = {name: scene_category(scene, name) for name in truth}
            for kind, names in (("object", bodies.objects), ("fixture", bodies.fixtures)):
                for name, body in names.items():
                    row = {"suite": suite, "task": task, "seed": seed, "kind": kind, "name": name,
                           "category": category[name]}
                    b = m.body(body).id
                    if checker.data.xpos[b][2] < -planning_world.PARK_M / 2:
                        rows.append({**row, "placed": False})
                        continue
                    seen = _box(checker.model, checker.data, b)
                    # identical twins (two black bowls) are interchangeable in the world: the nearest
                    twins = [n for n in truth if category[n] == category[name]]
                    near = min(twins, key=lambda n: float(np.linalg.norm(
                        0.5 * (truth[n][0] + truth[n][1]) - 0.5 * (seen[0] + seen[1]))))
                    t = truth[near]
                    rows.append({**row, "placed": True, "twin": near if near != name else None,
                                 "error_m": float(np.linalg.norm(0.5 * (seen[0] + seen[1]) - 0.5 * (t[0] + t[1]))),
                                 "iou": _iou(seen, t)})
            for ent, (joint, _sign) in bodies.slides.items():
                adr = int(m.jnt_qposadr[m.joint(joint).id])
                rows.append({"suite": suite, "task": task, "seed": seed, "kind": "drawer", "name": ent,
                             "category": "drawer", "placed": True,
                             "error_m": abs(float(checker.data.qpos[adr]) - float(target.data.qpos[adr]))})
    return rows


def scene_category(scene, name: str) -> str:
    for o in (*scene.objects, *scene.fixtures):
        if o["name"] == name:
            return str(o.get("class"))
    return name


def main() -> int:
    ap = parser(__doc__, "libero_planning_world")
    ap.add_argument("--tasks", default="libero_goal/0-9,libero_10/0-9,libero_spatial/0-9,libero_object/0-9",
                    help="suite/tasks, comma-separated (default: the four suites' ten tasks each)")
    ap.add_argument("--seeds", default=f"{SEED}-{SEED + 1}", help="generated-scene seeds (never an init state)")
    ap.add_argument("--workspace", default="/tmp/ws_planning_world", help="where the looks are measured and cached")
    args = ap.parse_args()
    seeds = index_range(args.seeds)
    jobs = []
    for part in args.tasks.split(","):
        suite, _, tasks = part.partition("/")
        jobs += [(suite, t) for t in index_range(tasks)]
    rows, t0 = [], time.perf_counter()
    for k, (suite, task) in enumerate(jobs, start=1):
        rows += measure(args.workspace, suite, task, seeds)
        print(f"[{k}/{len(jobs)}] {suite}/{task}: {time.perf_counter() - t0:.0f} s", flush=True)
    by = defaultdict(list)
    for r in rows:
        by[(r["kind"], r["category"])].append(r)
    table = []
    for (kind, cat), rs in sorted(by.items()):
        placed = [r for r in rs if r["placed"]]
        errs = [100.0 * r["error_m"] for r in placed]
        ious = [r["iou"] for r in placed if r.get("iou") is not None]
        table.append([kind, cat, len(rs), len(rs) - len(placed),
                      f"{percentile(errs, 50):.1f}" if errs else "-", f"{percentile(errs, 90):.1f}" if errs else "-",
                      f"{max(errs):.1f}" if errs else "-", f"{percentile(ious, 50):.2f}" if ious else "-",
                      f"{min(ious):.2f}" if ious else "-"])
    print_table(["kind", "category", "n", "left out", "median cm", "p90 cm", "max cm", "median IoU", "min IoU"],
                table, align=["l", "l", "r", "r", "r", "r", "r", "r", "r"])
    totals = {}
    for kind in ("object", "fixture", "drawer"):
        rs = [r for r in rows if r["kind"] == kind]
        placed = [r for r in rs if r["placed"]]
        errs = [r["error_m"] for r in placed]
        totals[kind] = {"n": len(rs), "left_out": len(rs) - len(placed), "median_m": percentile(errs, 50),
                        "p90_m": percentile(errs, 90), "max_m": max(errs) if errs else None}
        print(f"{kind}: {len(rs)}, left out {len(rs) - len(placed)}, error median "
              f"{100 * (totals[kind]['median_m'] or 0):.1f} cm, p90 {100 * (totals[kind]['p90_m'] or 0):.1f} cm")
    write_json(args.out, {"seeds": seeds, "tasks": args.tasks, "totals": totals, "rows": rows,
                          "wall_time_s": time.perf_counter() - t0})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
