"""Perception of LIBERO's fixtures (stove, cabinet, wine rack) on generated scenes, and of things set on them.

    .venv/bin/python bench/libero_fixtures.py [--suite libero_goal] [--task 1] [--seeds 10]
        [--record tests/data/libero_goal_fixtures_cloud.npz] [--out bench/results/libero_fixtures.json]

The fixtures' looks are measured first (:func:`~phyagentos.targets.libero.descriptors.measure_fixture_looks`,
each fixture alone on generated scenes from seed 23456). Then, for each seed (from 70000:
never an init state), LIBERO's placement sampler builds a scene
(:meth:`~phyagentos.targets.libero.LiberoTarget.generate_scene`) and a fresh perceiver, given
the fixtures with their looks and no object, observes both cameras at the start pose: each
fixture with a place site is scored by the distance of its reported place patch's centre to
the site's true centre (``found`` within 3 cm; ``off``; ``unseen``). Then the task's first
object is set on each place site in turn (centred, 1 cm above, settled 1 s) and observed by
the same perceiver: ``on`` when some segment over the site is reported ``on`` the fixture,
beside the site part of LIBERO's own ``On`` predicate (``SiteObject.under``: the object's origin over the
site, at most 10 cm above it). Ground truth (site
poses, LIBERO's predicate) is read here, for the scene generator and the scoring only.

``--record`` writes the first scene's raised-crop cloud (``points_mm``, ``heights_mm``: int16
millimetres; ``rgb``) with, as JSON in ``meta``, the true place-site centres and fixture boxes
(world m) and the looks, for the unit tests (``tests/test_perception_fixtures.py``).
"""

from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path

from _harness import parser, write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)

# isort: split
import mujoco
import numpy as np

from phyagentos.perception import Perceiver
from phyagentos.primitives.observation import robot_capsules
from phyagentos.targets.libero import LiberoScene, LiberoTarget
from phyagentos.targets.libero.descriptors import (
    FIXTURE_PLACE_SITES,
    _free_adr,
    fixture_boxes,
    measure_fixture_looks,
)

SEED = 70000


def _observe(target, perceiver) -> dict:
    frames = [target.capture(s) for s in target.camera_names()]
    return perceiver.observe(frames, target.proprioception(), robot_capsules=robot_capsules(target))


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_fixtures")
    ap.add_argument("--suite", default="libero_goal")
    ap.add_argument("--task", type=int, default=1)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--record", type=Path, default=None)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    with LiberoTarget("libero_fixtures", LiberoScene(suite=args.suite, task=args.task), seed=0) as target:
        looks = measure_fixture_looks(target)
        print(json.dumps({"looks": looks}), flush=True)
        cats = target._problem.fixtures
        declared = {"objects": [], "fixtures": [{"name": n, "class": c, **looks.get(c, {})} for n, c in cats.items()]}
        sites = {n: f"{n}_{FIXTURE_PLACE_SITES[c]}" for n, c in cats.items() if c in FIXTURE_PLACE_SITES}
        mover = next(iter(target._problem.objects))
        m, d = target.model, target.data
        u = target.env.env
        for k in range(args.seeds):
            seed = SEED + k
            target.generate_scene(seed)
            perceiver = Perceiver(target.perception_config(), declared)
            snap = _observe(target, perceiver)
            if args.record is not None and k == 0:
                cfg = target.perception_config()
                frames = [target.capture(s) for s in target.camera_names()]
                cloud, heights, _ = Perceiver(cfg, declared).object_cloud(
                    frames, target.proprioception(), robot_capsules=robot_capsules(target),
                    max_height_m=Perceiver(cfg, declared).fixture_ceiling_m())
                args.record.parent.mkdir(parents=True, exist_ok=True)
                np.savez_compressed(args.record, points_mm=np.round(cloud.points * 1000).astype(np.int16),
                                    rgb=cloud.rgb, heights_mm=np.round(heights * 1000).astype(np.int16),
                                    meta=np.array(json.dumps({
                                        "sites": {n: d.site_xpos[m.site(s).id][:2].tolist() for n, s in sites.items()},
                                        "boxes": {n: [lo.tolist(), hi.tolist()] for n, (lo, hi) in fixture_boxes(target).items()},
                                        "looks": looks, "seed": seed, "suite": args.suite, "task": args.task})))
                print(f"recorded {len(cloud)} points to {args.record}", flush=True)
            ents = {e["name"]: e for e in snap["entities"]}
            row: dict = {"seed": seed}
            for name, site in sites.items():
                truth = d.site_xpos[m.site(site).id][:2]
                e = ents.get(name)
                if e is None:
                    row[name] = {"outcome": "unseen"}
                    continue
                err = float(np.linalg.norm(np.asarray(e["position"][:2]) - truth))
                row[name] = {"outcome": "found" if err <= 0.03 else "off", "error_m": round(err, 4)}
            adr = _free_adr(m, target._obj_body[mover])
            state = (d.qpos.copy(), d.qvel.copy())
            for name, site in sites.items():
                d.qpos[:], d.qvel[:] = state
                sp = d.site_xpos[m.site(site).id].copy()
                d.qpos[adr[0]:adr[0] + 3] = (sp[0], sp[1], sp[2] + 0.01)
                d.qvel[adr[1]:adr[1] + 6] = 0.0
                mujoco.mj_forward(m, d)
                target.hold(duration_s=1.0)
                after = _observe(target, perceiver)
                over = [e["name"] for e in after["entities"] if e["kind"] in ("object", "unknown")
                        and np.linalg.norm(np.asarray(e["position"][:2]) - sp[:2]) < 0.06]
                on = any(r["relation"] == "on" and r["object"] == name and r["subject"] in over for r in after["relations"])
                libero_on = bool(u.object_sites_dict[site].under(d.site_xpos[m.site(site).id],
                                                                 d.site_xmat[m.site(site).id].reshape(3, 3),
                                                                 d.xpos[target._obj_body[mover]]))
                row[name]["set_on"] = {"perceived_on": on, "libero_on_site": libero_on}
            rows.append(row)
            print(json.dumps(row), flush=True)
    tally = Counter((n, r[n]["outcome"]) for r in rows for n in r if n != "seed")
    on = Counter((n, r[n]["set_on"]["perceived_on"], r[n]["set_on"]["libero_on_site"]) for r in rows for n in r
                 if n != "seed" and "set_on" in r[n])
    summary = {"found": {f"{n}:{o}": c for (n, o), c in tally.items()},
               "set_on (perceived, libero)": {f"{n}:{p}:{q}": c for (n, p, q), c in on.items()},
               "scenes": len(rows), "wall_s": round(time.perf_counter() - t0, 1)}
    print(json.dumps(summary))
    write_json(args.out, {"rows": rows, "summary": summary}, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
