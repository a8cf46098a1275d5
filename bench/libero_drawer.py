"""How well perception reads LIBERO's cabinet drawers, on generated scenes (issue 28).

    .venv/bin/python bench/libero_drawer.py [--tasks libero_goal/0,libero_90/0] [--seeds 3]
        [--openings 0,0.04,0.08,0.12,0.16] [--stop] [--out bench/results/libero_drawer.json]

``--stop``: where each drawer rests when pushed home (the model's shut stop, what a close's
push meets: docs/libero.md, "Closing a drawer"): set 8 cm out, then pushed toward shut along
its joint with 5, 20 and 60 N for 1 s each; its opening after each, m (negative: past the
joint's zero).

For each task the fixtures' looks are measured first
(:func:`~phyagentos.targets.libero.descriptors.measure_fixture_looks`: each fixture alone on
generated scenes; a cabinet's ``drawers`` from its model). Then, for each seed (from 72000:
never an init state), LIBERO's placement sampler builds a scene and, for each drawer and each
opening, that drawer is set that far out and the others shut (the simulator: this is the scene
generator; all shut once), the world settles 0.2 s, and a fresh perceiver, given the fixtures
with their looks, observes both cameras at the start pose. Scored per drawer: whether the cabinet is found, whether the
drawer's entity is reported (its handle read), and the error of its perceived opening
(``attributes.joint_position``) against the simulator's. Ground truth is read here for the
generator and the scoring only.
"""

from __future__ import annotations

import json
import time

from _harness import parser, write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)

# isort: split
import mujoco
import numpy as np

from phyagentos.perception import Perceiver
from phyagentos.perception.fixtures import drawer_entity_name
from phyagentos.primitives.observation import robot_capsules
from phyagentos.targets.libero import LiberoScene, LiberoTarget
from phyagentos.targets.libero.descriptors import (
    _drawer_joints,
    _drawer_name,
    drawer_opening,
    drawer_sign,
    measure_fixture_looks,
)

SEED = 72000


def _set_openings(target, cabinet: str, joints: list[int], moved: int, opening: float) -> dict[int, float]:
    """Set drawer ``moved`` (a joint id) of ``cabinet`` ``opening`` m out and the others shut,
    settle 0.2 s; each drawer's true opening after (m)."""
    m, d = target.model, target.data
    for j in joints:
        d.qpos[m.jnt_qposadr[j]] = drawer_sign(target, cabinet, j) * (opening if j == moved else 0.0)
        d.qvel[m.jnt_dofadr[j]] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=0.2)
    return {j: drawer_opening(target, cabinet, j)[0] for j in joints}


def _pushed_home(target, cabinet: str, joints: list[int], forces=(5.0, 20.0, 60.0)) -> list[dict]:
    """Each drawer of ``cabinet`` set 8 cm out, then pushed toward shut with each of ``forces``
    N (a generalised force on its slide) for 1 s: its opening after each, m."""
    m, d = target.model, target.data
    rows = []
    for j in joints:
        _set_openings(target, cabinet, joints, j, 0.08)
        sign = drawer_sign(target, cabinet, j)  # the joint's sign of "out"
        for force in forces:
            for _ in range(int(round(1.0 / m.opt.timestep))):
                d.qfrc_applied[m.jnt_dofadr[j]] = -sign * force
                mujoco.mj_step(m, d)
            d.qfrc_applied[m.jnt_dofadr[j]] = 0.0
            rows.append({"drawer": drawer_entity_name(cabinet, _drawer_name(m.joint(j).name, cabinet)),
                         "force_n": force, "rest_m": round(drawer_opening(target, cabinet, j)[0], 5)})
            print(json.dumps(rows[-1]), flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_drawer")
    ap.add_argument("--tasks", default="libero_goal/0,libero_90/0")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--openings", default="0,0.04,0.08,0.12,0.16")
    ap.add_argument("--stop", action="store_true", help="only where each drawer rests pushed home")
    args = ap.parse_args(argv)
    if args.stop:
        stops = []
        for spec in args.tasks.split(","):
            suite, task = spec.split("/")
            with LiberoTarget("libero_drawer", LiberoScene(suite=suite, task=int(task)), seed=0) as target:
                target.reset(seed=0)
                cabinet = next(n for n, c in target._problem.fixtures.items() if "cabinet" in c)
                stops += [{"task": spec, **r} for r in _pushed_home(target, cabinet, _drawer_joints(target, cabinet))]
        print("| task | drawer | force (N) | rests at (m out of shut) |")
        print("|---|---|---|---|")
        for r in stops:
            print(f"| {r['task']} | {r['drawer']} | {r['force_n']:g} | {r['rest_m']:+.4f} |")
        write_json(args.out, {"stops": stops, "tasks": args.tasks})
        return 0
    openings = [float(a) for a in args.openings.split(",")]
    t0 = time.perf_counter()
    rows: list[dict] = []
    for spec in args.tasks.split(","):
        suite, task = spec.split("/")
        with LiberoTarget("libero_drawer", LiberoScene(suite=suite, task=int(task)), seed=0) as target:
            looks = measure_fixture_looks(target)
            cats = target._problem.fixtures
            cabinet = next(n for n, c in cats.items() if "drawers" in looks.get(c, {}))
            declared = {"objects": [], "fixtures": [{"name": n, "class": c, **looks.get(c, {})} for n, c in cats.items()]}
            joints = _drawer_joints(target, cabinet)
            print(json.dumps({"task": spec, "drawers": looks[cats[cabinet]]["drawers"]}), flush=True)
            for k in range(args.seeds):
                seed = SEED + k
                target.generate_scene(seed)
                for moved, opening in ((j, o) for j in joints for o in openings if o > 0 or j == joints[0]):
                    truth = _set_openings(target, cabinet, joints, moved, opening)
                    perceiver = Perceiver(target.perception_config(), declared)
                    snap = perceiver.observe([target.capture(s) for s in target.camera_names()],
                                             target.proprioception(), robot_capsules=robot_capsules(target))
                    ents = {e["name"]: e for e in snap["entities"]}
                    for j, true_opening in truth.items():
                        name = drawer_entity_name(cabinet, _drawer_name(target.model.joint(j).name, cabinet))
                        row = {"task": spec, "seed": seed, "drawer": name, "opening_m": round(true_opening, 4),
                               "cabinet": cabinet in ents}
                        ent = ents.get(name)
                        read = None if ent is None else ent["attributes"].get("joint_position")
                        row.update(read_m=read, error_m=None if read is None else round(abs(read - true_opening), 4))
                        rows.append(row)
                        print(json.dumps(row), flush=True)
    read = [r for r in rows if r["error_m"] is not None]
    errs = np.array([r["error_m"] for r in read]) if read else np.zeros(0)
    summary = {"drawer_observations": len(rows), "cabinet_found": sum(r["cabinet"] for r in rows),
               "read": len(read), "error_median_m": round(float(np.median(errs)), 4) if len(errs) else None,
               "error_p95_m": round(float(np.percentile(errs, 95)), 4) if len(errs) else None,
               "error_max_m": round(float(errs.max()), 4) if len(errs) else None,
               "wall_s": round(time.perf_counter() - t0, 1)}
    print("| drawer observations | cabinet found | drawer read | error median / p95 / max (m) |")
    print("|---|---|---|---|")
    print(f"| {summary['drawer_observations']} | {summary['cabinet_found']} | {summary['read']} | "
          f"{summary['error_median_m']} / {summary['error_p95_m']} / {summary['error_max_m']} |")
    write_json(args.out, {"summary": summary, "rows": rows, "openings": openings, "seed": SEED, "tasks": args.tasks})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
