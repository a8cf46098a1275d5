"""How well perception reads LIBERO's stove knob, on generated scenes (issue 28).

    .venv/bin/python bench/libero_knob.py [--tasks libero_90/20,libero_90/44,libero_goal/7]
        [--seeds 4] [--angles 0,0.3,0.6,1.0,1.5,2.0] [--record tests/data/libero_knob_cloud.npz]
        [--out bench/results/libero_knob.json]

For each task the fixtures' looks are measured first
(:func:`~phyagentos.targets.libero.descriptors.measure_fixture_looks`: each fixture alone on
generated scenes; the stove's ``knob`` from its model). Then, for each seed (from 71000: never
an init state), LIBERO's placement sampler builds a scene and, for each angle, the knob's
joint is set there (the simulator: this is the scene generator), the world settles 0.2 s,
and a fresh perceiver, given the fixtures with their looks, observes both cameras at the
start pose. Scored: whether the stove is found (within 3 cm of its true cook region) and by
which route (its body's size, or its knob: :func:`~phyagentos.perception.fixtures.find_by_knob`),
and the error of the knob's joint position as perceived (``attributes.joint_position``)
against the simulator's. Ground truth is read here for the generator and the scoring only.

``--record`` writes the first scene's raised-crop cloud at the angle 0.9 rad (``points_mm``,
``heights_mm``: int16 millimetres; ``rgb``) with, as JSON in ``meta``, the true knob angle and
axis, the cook region's centre and the looks, for ``tests/test_perception_knob.py``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from _harness import parser, write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)

# isort: split
import mujoco
import numpy as np

from phyagentos.perception import Perceiver
from phyagentos.primitives.observation import robot_capsules
from phyagentos.targets.libero import LiberoScene, LiberoTarget
from phyagentos.targets.libero.descriptors import _knob_joint, measure_fixture_looks

SEED = 71000
RECORD_ANGLE = 0.9


def _set_knob(target, joint: int, angle: float) -> float:
    """Set the knob's joint to ``angle`` rad, settle 0.2 s; the angle it settled at (rad)."""
    m, d = target.model, target.data
    d.qpos[m.jnt_qposadr[joint]] = angle
    d.qvel[m.jnt_dofadr[joint]] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=0.2)
    return float(d.qpos[m.jnt_qposadr[joint]])


def _row(target, declared, stove: str, joint: int, angle: float) -> dict:
    m, d = target.model, target.data
    truth = _set_knob(target, joint, angle)
    perceiver = Perceiver(target.perception_config(), declared)
    frames = [target.capture(s) for s in target.camera_names()]
    snap = perceiver.observe(frames, target.proprioception(), robot_capsules=robot_capsules(target))
    ent = next((e for e in snap["entities"] if e["name"] == stove), None)
    site = d.site_xpos[m.site(f"{stove}_cook_region").id][:2]
    row = {"angle_rad": round(truth, 4)}
    if ent is None:
        return {**row, "outcome": "unseen"}
    err = float(np.linalg.norm(np.asarray(ent["position"][:2]) - site))
    sighting = perceiver.fixture_tracks[stove][0]
    row.update(outcome="found" if err <= 0.03 else "off", place_error_m=round(err, 4), route=sighting.found_by)
    q = ent["attributes"].get("joint_position")
    row["read_rad"] = q
    row["error_rad"] = None if q is None else round(abs(float(q) - truth), 4)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_knob")
    ap.add_argument("--tasks", default="libero_90/20,libero_90/44,libero_goal/7")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--angles", default="0,0.3,0.6,1.0,1.5,2.0")
    ap.add_argument("--record", type=Path, default=None)
    args = ap.parse_args(argv)
    angles = [float(a) for a in args.angles.split(",")]
    t0 = time.perf_counter()
    rows: list[dict] = []
    for spec in args.tasks.split(","):
        suite, task = spec.split("/")
        with LiberoTarget("libero_knob", LiberoScene(suite=suite, task=int(task)), seed=0) as target:
            looks = measure_fixture_looks(target)
            cats = target._problem.fixtures
            stove = next(n for n, c in cats.items() if c == "flat_stove")
            declared = {"objects": [], "fixtures": [{"name": n, "class": c, **looks.get(c, {})} for n, c in cats.items()]}
            joint = _knob_joint(target, stove)
            print(json.dumps({"task": spec, "knob": looks["flat_stove"].get("knob")}), flush=True)
            for k in range(args.seeds):
                seed = SEED + k
                target.generate_scene(seed)
                for angle in angles:
                    row = {"task": spec, "seed": seed, **_row(target, declared, stove, joint, angle)}
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                if args.record is not None and k == 0 and spec == args.tasks.split(",")[0]:
                    _record(target, declared, stove, joint, looks, args.record, seed, spec)
    read = [r for r in rows if r.get("error_rad") is not None]
    errs = np.array([r["error_rad"] for r in read]) if read else np.zeros(0)
    summary = {"observations": len(rows), "stove_found": sum(r["outcome"] == "found" for r in rows),
               "found_by_knob": sum(r.get("route") == "knob" for r in rows),
               "stove_off": sum(r["outcome"] == "off" for r in rows),
               "stove_unseen": sum(r["outcome"] == "unseen" for r in rows), "knob_read": len(read),
               "error_median_rad": round(float(np.median(errs)), 4) if len(errs) else None,
               "error_p95_rad": round(float(np.percentile(errs, 95)), 4) if len(errs) else None,
               "error_max_rad": round(float(errs.max()), 4) if len(errs) else None,
               "wall_s": round(time.perf_counter() - t0, 1)}
    print("| observations | stove found / off / unseen (found by its knob) | knob read | error median / p95 / max (rad) |")
    print("|---|---|---|---|")
    print(f"| {summary['observations']} | {summary['stove_found']} / {summary['stove_off']} / "
          f"{summary['stove_unseen']} ({summary['found_by_knob']}) | {summary['knob_read']} | {summary['error_median_rad']} / "
          f"{summary['error_p95_rad']} / {summary['error_max_rad']} |")
    write_json(args.out, {"summary": summary, "rows": rows, "angles": angles, "seed": SEED, "tasks": args.tasks})
    return 0


def _record(target, declared, stove, joint, looks, path: Path, seed: int, spec: str) -> None:
    m, d = target.model, target.data
    _set_knob(target, joint, RECORD_ANGLE)
    cfg = target.perception_config()
    p = Perceiver(cfg, declared)
    frames = [target.capture(s) for s in target.camera_names()]
    cloud, heights, _ = p.object_cloud(frames, target.proprioception(), robot_capsules=robot_capsules(target),
                                       max_height_m=p.fixture_ceiling_m())
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, points_mm=np.round(cloud.points * 1000).astype(np.int16), rgb=cloud.rgb,
                        heights_mm=np.round(heights * 1000).astype(np.int16),
                        meta=np.array(json.dumps({
                            "angle_rad": float(d.qpos[m.jnt_qposadr[joint]]), "axis": d.xanchor[joint][:2].tolist(),
                            "cook_region": d.site_xpos[m.site(f"{stove}_cook_region").id][:2].tolist(),
                            "looks": looks, "seed": seed, "task": spec, "stove": stove})))
    print(f"recorded {len(cloud)} points to {path}", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
