"""A bowl standing in an open drawer, on generated scenes: is it perceived, and does "the black
bowl in the top drawer of the wooden cabinet" name it and not its twin on the cabinet's top?

    .venv/bin/python bench/libero_drawer_refs.py [--seeds 90000-90009] [--workspace /tmp/ws_spatial]
        [--placement sites|sampler] [--plate-under] [--record tests/data/libero_drawer_bowl_frames.npz]
        [--out bench/results/libero_drawer_refs.json]

libero_spatial task 4's world (its instruction: "pick up the black bowl in the top drawer of the
wooden cabinet and place it on the plate"), scenes from LIBERO's placement sampler with seeds
from 90000 (never an init state; the sampler drops the bowl out of the drawer region, so each
scene then sets ``akita_black_bowl_1`` on the top drawer's region site and ``akita_black_bowl_2``
on the cabinet's top site and lets them settle 1.5 s; ``--placement sampler`` keeps the
sampler's scene as the bench's ``--generated`` episodes see it, the bowl anywhere in the open
drawer, at its back partly under the cabinet's body too; ``--plate-under`` then moves the plate
so that its rim lies on the table under the open top drawer, :data:`PLATE_UNDER_M` of it in
under the drawer's front, as LIBERO-PRO's ``libero_spatial_swap`` task 4 sets it, and scores
the plate too). The declared scene is the LIBERO bench's
(looks measured on generated scenes, cached in the workspace; the reference read by the rule
reader). One perception at the start pose (both cameras). Scoring (here only): which true bowl
the perceived ``akita_black_bowl_1`` is nearest, and its distance. ``--record`` writes the
first scene's camera frames, proprioception, declared scene and true bowl centres for
``tests/test_perception_drawer_inside.py``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import mujoco
import numpy as np
from _harness import index_range, parser, write_json
from _libero_scene import generated_scene

from phyagentos.bench.libero import instruction_plan
from phyagentos.primitives.observation import make_perceiver, perceive_now, robot_capsules
from phyagentos.targets.libero import LiberoTarget, parse_bddl, resolve_task
from phyagentos.targets.libero.descriptors import _drawer_joints, _free_adr, _handle_geom, drawer_opening, object_boxes

SUITE, TASK = "libero_spatial", 4
BOWLS = ("akita_black_bowl_1", "akita_black_bowl_2")
SITES = {"akita_black_bowl_1": ("wooden_cabinet_1_top_region", 0.02), "akita_black_bowl_2": ("wooden_cabinet_1_top_side", 0.03)}
PLATE = "plate_1"
#: How far the plate's rim reaches in under the open top drawer's front, m (LIBERO-PRO's
#: ``libero_spatial_swap`` task 4 init 1: about 2 cm).
PLATE_UNDER_M = 0.025
#: LIBERO's plate: its radius, m (the model's 13.85 cm across).
PLATE_RADIUS_M = 0.069


def _set_bowls(target) -> None:
    """Each bowl just above its site (see the module docstring), then 1.5 s of physics."""
    m, d = target.model, target._data
    for name, (site, dz) in SITES.items():
        body = m.body(target.object_body(name)).id
        qadr, _ = _free_adr(m, int(m.body_rootid[body]))
        d.qpos[qadr:qadr + 3] = d.site(site).xpos + np.array([0.0, 0.0, dz])
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=1.5)


def _plate_under(target) -> None:
    """Set the plate on the table in front of the open top drawer, its rim :data:`PLATE_UNDER_M`
    in under the drawer's front (the handle's bar: the front's outermost geom), then 1 s of
    physics."""
    m, d = target.model, target._data
    joint = next(j for j in _drawer_joints(target, "wooden_cabinet_1") if m.joint(j).name.endswith("top_level"))
    _, u, _ = drawer_opening(target, "wooden_cabinet_1", joint)
    front = d.geom_xpos[_handle_geom(target, joint)][:2]
    body = m.body(target.object_body(PLATE)).id
    qadr, _ = _free_adr(m, int(m.body_rootid[body]))
    xy = front + u * (PLATE_RADIUS_M - PLATE_UNDER_M)
    d.qpos[qadr:qadr + 3] = [xy[0], xy[1], target._support_top_z() + 0.01]
    d.qpos[qadr + 3:qadr + 7] = [1.0, 0.0, 0.0, 0.0]
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)
    target.hold(duration_s=1.0)


def _record(path: Path, target, declared: dict, truth: dict) -> None:
    frames = [target.capture(s) for s in target.camera_names()]
    pr = target.proprioception()
    arrays = {}
    for k, f in enumerate(frames):
        i = f.intrinsics
        # depth in 0.1 mm steps (uint16: up to 6.5 m), as the test reads it back
        arrays[f"rgb{k}"], arrays[f"depth{k}"] = f.rgb, np.round(f.depth_m * 1e4).clip(0, 65535).astype(np.uint16)
        arrays[f"T{k}"] = f.T_world_camera
        arrays[f"K{k}"] = np.array([i.width, i.height, i.fx, i.fy, i.cx, i.cy])
    meta = {"sensors": [f.sensor for f in frames], "frame_ids": [f.frame_id for f in frames],
            "stamp_s": frames[0].stamp_s, "joint_names": list(pr.joint_names),
            "joint_positions": pr.joint_positions.tolist(), "gripper_opening_m": pr.gripper_opening_m,
            "tcp_pose": pr.tcp_pose.tolist(), "declared": declared, "truth": truth,
            "table_z": float(target._support_top_z()),
            "perception_config": target.perception_config().model_dump(mode="json"),
            "robot_capsules": [[list(c.p0), list(c.p1), c.radius_m] for c in robot_capsules(target)]}
    np.savez_compressed(path, meta=json.dumps(meta), **arrays)


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_drawer_refs")
    ap.add_argument("--seeds", default="90000-90009")
    ap.add_argument("--workspace", default="/tmp/ws_spatial", help="where the looks are cached")
    ap.add_argument("--record", default=None, help="write the first scene's frames here (.npz)")
    ap.add_argument("--placement", choices=("sites", "sampler"), default="sites",
                    help="bowls set on the drawer's and the top's sites, or where LIBERO's sampler put them")
    ap.add_argument("--plate-under", action="store_true",
                    help="then the plate set with its rim under the open top drawer (module docstring)")
    args = ap.parse_args(argv)
    task = resolve_task(SUITE, TASK)
    problem = parse_bddl(task.bddl_path)
    _, where = instruction_plan(task.instruction, problem.objects, problem.fixtures)
    scene = generated_scene(args.workspace, SUITE, TASK, where=where)
    rows = []
    seeds = index_range(args.seeds)
    with LiberoTarget("drawer_refs", scene, seed=seeds[0]) as target:
        for n, seed in enumerate(seeds):
            t0 = time.perf_counter()
            target.generate_scene(seed)
            target.runtime_notes.pop("perception", None)  # a new scene: nothing remembered from the last
            if args.placement == "sites":
                _set_bowls(target)
            if args.plate_under:
                _plate_under(target)
            truth = {b: (0.5 * (lo + hi)).round(4).tolist() for b, (lo, hi) in object_boxes(target).items()
                     if b in BOWLS or b == PLATE}
            if args.record and n == 0:
                _record(Path(args.record), target, {"objects": list(scene.objects), "fixtures": list(scene.fixtures)}, truth)
            snap = perceive_now(target, make_perceiver(target))
            ref = (snap.get("references") or {}).get(BOWLS[0], {})
            seen = {e["name"]: e for e in snap["entities"] if e["kind"] == "object"}
            named, err = None, None
            if BOWLS[0] in seen:
                p = np.asarray(seen[BOWLS[0]]["position"][:2], float)
                dist = {b: float(np.linalg.norm(np.asarray(truth[b][:2]) - p)) for b in BOWLS}
                named = min(dist, key=dist.get)
                err = round(dist[named], 4)
            row = {"seed": seed, "resolved": bool(ref.get("resolved")), "reason": ref.get("reason"),
                   "named_true": named, "xy_error_m": err,
                   "confidence": seen.get(BOWLS[0], {}).get("attributes", {}).get("confidence"),
                   "plate_confidence": seen.get(PLATE, {}).get("attributes", {}).get("confidence"),
                   "plate_xy_error_m": (round(float(np.linalg.norm(np.asarray(seen[PLATE]["position"][:2])
                                                                   - np.asarray(truth[PLATE][:2]))), 4)
                                        if PLATE in seen else None),
                   "s": round(time.perf_counter() - t0, 1)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    resolved = [r for r in rows if r["resolved"]]
    right = [r for r in resolved if r["named_true"] == BOWLS[0]]
    totals = {"scenes": len(rows), "resolved": len(resolved), "right_bowl": len(right),
              "wrong_bowl": len(resolved) - len(right),
              "median_confidence": float(np.median([r["confidence"] for r in right])) if right else None,
              "plate_named": sum(r["plate_confidence"] is not None and r["plate_confidence"] >= 0.5 for r in rows)}
    print(json.dumps(totals))
    write_json(args.out, {"rows": rows, "totals": totals}, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
