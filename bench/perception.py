"""Perception accuracy and latency on randomised tabletop scenes rendered by MuJoCo.

    .venv/bin/python bench/perception.py [--scenes 60] [--seed 0] [--clustering kdtree|sklearn]
                                         [--cameras near|overview]

Each scene draws 1-2 declared target objects and 0-4 undeclared distractors (box, cylinder
or sphere, 2-7 cm, random yaw and position over the reachable table; with distractors, half
the scenes put one against the first target: touching objects), renders two cameras
(``--cameras near``: :data:`phyagentos.perception.synthetic.DEFAULT_CAMERAS`,
320x240 RGB-D about 0.8 m away; ``overview``: the tabletop target's overview geometry, 640x480
about 1.2 m away, plus a 640x480 side camera) with camera noise
(depth sigma = 0.5 mm + 1.5 mm/m^2 z^2, RGB sigma 3, brightness gain +-10 %, 1 % depth
dropout), and runs one :meth:`Perceiver.observe` on the two frames with the targets declared by
shape, colour and size. Scored against the known true poses:

* association: a declared target counts as correct when its entity lies within the target's
  footprint radius of the true centre, wrong when it lies elsewhere (a distractor), missed
  when it is reported unseen or unknown;
* position error (xy and 3-D) of correct associations; yaw error of boxes (modulo the
  footprint's symmetry: pi, or pi/2 for a square); size error (full dimensions);
* shape classification over every object (targets and distractors) found within 2 cm;
* calibration: the fraction of xy errors within 2 reported sigmas (``position_std_m``);
* latency of the pipeline per observation (two cameras), wall clock and process CPU time,
  render time reported separately.

Prints a table and writes bench/results/perception.json.
"""

from __future__ import annotations

import math
import os
import platform
import time

from _harness import parser, write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)

# isort: split
import numpy as np

from phyagentos.perception import ObjectDescriptor, Perceiver, PerceptionConfig
from phyagentos.perception.synthetic import (
    DEFAULT_CAMERAS,
    CameraNoise,
    SyntheticCamera,
    SyntheticScene,
    random_objects,
)

#: Camera sets: ``near`` = DEFAULT_CAMERAS (two 320x240 cameras about 0.8 m from the
#: objects); ``overview`` = the tabletop target's overview camera geometry (eye
#: (1.25, 0, 0.95), fovy 55, 640x480, about 1.2 m away) plus a 640x480 side camera.
CAMERA_SETS = {
    "near": DEFAULT_CAMERAS,
    "overview": (
        SyntheticCamera("overview_rt", eye=(1.25, 0.0, 0.95), target=(0.5, 0.0, 0.0), fovy_deg=55.0, width=640, height=480),
        SyntheticCamera("side", eye=(0.55, -0.60, 0.60), target=(0.5, 0.0, 0.0), fovy_deg=45.0, width=640, height=480),
    ),
}


def _yaw_error(true_yaw: float, true_half, est_yaw: float) -> float:
    hx, hy = float(true_half[0]), float(true_half[1])
    if hy > hx:  # perceived yaw is the direction of the long side
        true_yaw += math.pi / 2.0
    period = math.pi / 2.0 if abs(hx - hy) < 0.1 * max(hx, hy) else math.pi
    d = (est_yaw - true_yaw + period / 2.0) % period - period / 2.0
    return abs(d)


def run(n_scenes: int, seed: int, clustering: str, camera_set: str = "near") -> dict:
    cfg = PerceptionConfig.default()
    if clustering != cfg.clustering.method:
        cfg = cfg.model_copy(update={"clustering": cfg.clustering.model_copy(update={"method": clustering})})
    rng = np.random.default_rng(seed)
    cameras = CAMERA_SETS[camera_set]
    scene = SyntheticScene([], cameras=cameras, pool_per_shape=7)
    noise = CameraNoise()
    rows = []
    lat_wall, lat_cpu, render = [], [], []
    assoc = {"correct": 0, "wrong": 0, "missed": 0}
    pos_err, pos_err3, yaw_err, size_err, within2 = [], [], [], [], []
    shape_ok = shape_n = found = total_objects = 0
    unknown_distractors = 0
    confusion: dict[str, dict[str, int]] = {s: {t: 0 for t in ("box", "cylinder", "sphere", "missed")}
                                            for s in ("box", "cylinder", "sphere")}
    for k in range(n_scenes):
        n_t = int(rng.integers(1, 3))
        n_d = int(rng.integers(0, 5))
        objs = random_objects(rng, n_targets=n_t, n_distractors=n_d, touching=bool(n_d and rng.random() < 0.5))
        scene.place(objs)
        targets = objs[:n_t]
        declared = [ObjectDescriptor(o.name, shape=o.shape, colour_rgb=o.rgba[:3],
                                     size_m=tuple(round(2 * h, 3) for h in o.half_extents)) for o in targets]
        t0 = time.perf_counter()
        frames = [scene.capture(c.name, noise=noise, rng=rng) for c in cameras]
        render.append(time.perf_counter() - t0)
        proprio = scene.proprioception()
        perceiver = Perceiver(cfg, declared)
        if k == 0:  # warm caches (ray grids, imports) once
            perceiver.observe(frames, proprio)
            perceiver.reset()
        w0, c0 = time.perf_counter(), time.process_time()
        snap = perceiver.observe(frames, proprio)
        lat_wall.append(time.perf_counter() - w0)
        lat_cpu.append(time.process_time() - c0)
        ents = {e["name"]: e for e in snap["entities"] if e["kind"] in ("object", "unknown")}
        for o in targets:
            e = ents.get(o.name)
            true_c = np.array(o.centre)
            if e is None or e["kind"] != "object":
                assoc["missed"] += 1
                continue
            p = np.array(e["position"])
            err = float(np.linalg.norm(p[:2] - true_c[:2]))
            if err > max(o.half_extents[0], o.half_extents[1]):
                assoc["wrong"] += 1
                continue
            assoc["correct"] += 1
            pos_err.append(err)
            pos_err3.append(float(np.linalg.norm(p - true_c)))
            within2.append(err <= 2.0 * e["attributes"]["position_std_m"])
            size = 2.0 * np.array(e["size"])
            true_s = 2.0 * np.array(o.half_extents)
            est = np.array([max(size[0], size[1]), min(size[0], size[1]), size[2]])
            tru = np.array([max(true_s[0], true_s[1]), min(true_s[0], true_s[1]), true_s[2]])
            size_err.append(float(np.mean(np.abs(est - tru))))
        # shape classification and yaw over every object
        allents = list(ents.values())
        for o in objs:
            total_objects += 1
            true_c = np.array(o.centre)
            best = min(allents, key=lambda e: np.linalg.norm(np.array(e["position"][:2]) - true_c[:2]), default=None)
            if best is None or np.linalg.norm(np.array(best["position"][:2]) - true_c[:2]) > 0.02:
                confusion[o.shape]["missed"] += 1
                continue
            found += 1
            shape_n += 1
            shape_ok += best["attributes"]["shape"] == o.shape
            confusion[o.shape][best["attributes"]["shape"]] += 1
            if o.shape == "box" and best["attributes"]["shape"] == "box":
                q = best["quat_wxyz"]
                yaw = 2.0 * math.atan2(q[3], q[0])
                yaw_err.append(_yaw_error(o.yaw, o.half_extents, yaw))
            if o not in targets and best["kind"] == "unknown":
                unknown_distractors += 1
        rows.append({"scene": k, "targets": n_t, "distractors": n_d, "latency_ms": round(lat_wall[-1] * 1e3, 2)})
    scene.close()
    n_decl = sum(assoc.values())

    def med(a, scale=1.0, nd=2):
        return round(float(np.median(a)) * scale, nd) if a else None

    def p90(a, scale=1.0, nd=2):
        return round(float(np.percentile(a, 90)) * scale, nd) if a else None

    return {
        "scenes": n_scenes,
        "seed": seed,
        "clustering": clustering,
        "cameras": [{"name": c.name, "eye": c.eye, "fovy_deg": c.fovy_deg, "width": c.width, "height": c.height}
                    for c in cameras],
        "declared_targets": n_decl,
        "objects": total_objects,
        "association_accuracy": round(assoc["correct"] / max(n_decl, 1), 4),
        "association": assoc,
        "position_error_mm": {"median": med(pos_err, 1e3), "p90": p90(pos_err, 1e3)},
        "position_error_3d_mm": {"median": med(pos_err3, 1e3), "p90": p90(pos_err3, 1e3)},
        "yaw_error_deg": {"median": med(yaw_err, 180 / math.pi), "p90": p90(yaw_err, 180 / math.pi),
                          "boxes": len(yaw_err)},
        "size_error_mm": {"median": med(size_err, 1e3), "p90": p90(size_err, 1e3)},
        "within_2_sigma": round(float(np.mean(within2)), 3) if within2 else None,
        "shape_accuracy": round(shape_ok / max(shape_n, 1), 4),
        "shape_confusion": confusion,
        "detection_rate": round(found / max(total_objects, 1), 4),
        "latency_ms": {"median": med(lat_wall, 1e3), "p90": p90(lat_wall, 1e3),
                       "cpu_median": med(lat_cpu, 1e3)},
        "render_ms_two_cameras": {"median": med(render, 1e3)},
        "machine": {"cpus": os.cpu_count(), "load_avg_1m": round(os.getloadavg()[0], 2),
                    "python": platform.python_version()},
        "scenes_detail": rows,
    }


def main() -> int:
    ap = parser(__doc__, "perception")
    ap.add_argument("--scenes", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--clustering", choices=("kdtree", "sklearn"), default="kdtree")
    ap.add_argument("--cameras", choices=tuple(CAMERA_SETS), default="near")
    args = ap.parse_args()
    res = run(args.scenes, args.seed, args.clustering, args.cameras)
    write_json(args.out, res, say=False)
    lines = [
        ("scenes / declared targets / objects", f"{res['scenes']} / {res['declared_targets']} / {res['objects']}"),
        ("association accuracy", f"{res['association_accuracy']:.3f}  {res['association']}"),
        ("position error xy, median / p90", f"{res['position_error_mm']['median']} / {res['position_error_mm']['p90']} mm"),
        ("position error 3-D, median / p90", f"{res['position_error_3d_mm']['median']} / {res['position_error_3d_mm']['p90']} mm"),
        ("yaw error (boxes), median / p90", f"{res['yaw_error_deg']['median']} / {res['yaw_error_deg']['p90']} deg"
                                            f"  ({res['yaw_error_deg']['boxes']} boxes)"),
        ("size error, median / p90", f"{res['size_error_mm']['median']} / {res['size_error_mm']['p90']} mm"),
        ("xy error within 2 sigma", f"{res['within_2_sigma']}"),
        ("shape accuracy", f"{res['shape_accuracy']:.3f}  (detection rate {res['detection_rate']:.3f})"),
        ("pipeline latency, 2 cameras, median / p90", f"{res['latency_ms']['median']} / {res['latency_ms']['p90']} ms"
                                                      f"  (CPU {res['latency_ms']['cpu_median']} ms)"),
        ("render, 2 cameras (not in latency), median", f"{res['render_ms_two_cameras']['median']} ms"),
        ("machine", f"{res['machine']['cpus']} CPUs, load {res['machine']['load_avg_1m']}"),
    ]
    width = max(len(a) for a, _ in lines)
    print(f"perception bench (clustering: {res['clustering']}, cameras: {args.cameras})")
    for a, b in lines:
        print(f"  {a:<{width}}  {b}")
    print("  shape confusion (true -> perceived):")
    for s, row in res["shape_confusion"].items():
        print(f"    {s:<9}" + "  ".join(f"{k}={v}" for k, v in row.items()))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
