"""One pick-and-place through the whole framework vs a bare script doing the same motions.

    .venv/bin/python bench/pick_and_place.py [--runs 7]

Framework: ``run_goal_graph(phyagentos/data/goal_graphs/pick_and_place.yaml)`` (workspace creation,
session compile and submit, claim, preflight, tree build and ticking, evidence,
verification, every protocol write with fsync). Bare: the same motion sequence as
``trees/pick.yaml`` + ``trees/place.yaml`` (same grasp, heights, velocity scales,
planner, margins and settling) as straight calls into ``phyagentos.motion`` and
the target, no trees, no protocol files.

Wall time is split into IK, planning, timing (toppra), simulation and the rest
("framework overhead" for the framework, "setup and glue" for bare). Reported:
medians over ``--runs`` runs after one warm-up, and the ratio of median framework
wall time to median bare wall time (goal: <= 1.20). Writes
bench/results/pick_and_place.json.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from _harness import parser as bench_parser
from _harness import write_json
from bare_pick_and_place import SkillMotions  # the trees' heights and speeds

import phyagentos  # noqa: F401  (selects the headless GL backend before mujoco loads)
from phyagentos.app.orchestrator import run_goal_graph
from phyagentos.errors import BenchError
from phyagentos.motion.cartesian import cartesian_path
from phyagentos.motion.collision import CollisionChecker
from phyagentos.motion.grasp import place_pose, top_down_grasp
from phyagentos.motion.ik import solve_ik
from phyagentos.motion.planner import plan_path
from phyagentos.motion.retime import DEFAULT_ACCELERATION_LIMITS, retime
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir
from phyagentos.targets import MuJoCoTarget, SceneSpec
from phyagentos.yamlsource import read_yaml

GRAPH = goal_graphs_dir() / "pick_and_place.yaml"
CATEGORIES = ("ik", "planning", "timing", "simulation")


class Clock:
    def __init__(self) -> None:
        self.totals = dict.fromkeys(CATEGORIES, 0.0)

    @contextmanager
    def __call__(self, category: str):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.totals[category] += time.perf_counter() - t0


def bare_same_motions(seed: int = 0) -> dict:
    """The pick and place trees' motions as a plain script (their segments in order, at
    the heights and speeds :class:`SkillMotions` reads from them); returns wall-time
    split and sim time."""
    t_start = time.perf_counter()
    clock = Clock()
    m = SkillMotions.from_trees()
    scene = SceneSpec.from_dict(read_yaml(GRAPH, error=BenchError)["scene"])
    target = MuJoCoTarget("bare", scene, seed=seed)
    target.reset(seed=seed)
    model = target.model
    plan_checker = CollisionChecker(model, arm_joint_names=target.arm_joint_names, margin_m=0.01)
    time_checker = CollisionChecker(model, arm_joint_names=target.arm_joint_names, margin_m=0.0)
    vel, acc = target.velocity_limits(), np.asarray(DEFAULT_ACCELERATION_LIMITS)

    def held():
        return next((r["object"] for r in target.snapshot()["relations"] if r["relation"] == "holding"), None)

    def sync(checker):
        checker.set_world_state(target.data.qpos)
        checker.detach()
        obj = held()
        if obj:
            checker.attach(obj, np.linalg.inv(target.tcp_pose()) @ target.object_pose(obj))
        return checker

    def stream(traj):
        with clock("simulation"):
            t = 0.0
            while t < traj.duration - 1e-9:  # same 0.1 s slices the tree ticks in
                t_next = min(t + 0.1, traj.duration)
                res = target.track(traj, t_start=t, t_end=t_next, tracking_tol_rad=0.05)
                assert res.completed, res.reason
                t = t_next
            target.settle(traj.q[-1])

    def move_to(T=None, *, q_goal=None, scale: float = 1.0):
        if q_goal is None:
            with clock("ik"):
                q_goal = solve_ik(model, q_seed=target.arm_qpos(), target=T).q
        with clock("planning"):
            path = plan_path(sync(plan_checker), target.arm_qpos(), q_goal, planner="RRTConnect", timeout_s=2.0, seed=seed)
        with clock("timing"):
            traj = retime(path, vel_limits=vel * scale, acc_limits=acc * scale, dt=model.opt.timestep,
                          checker=sync(time_checker))
        stream(traj)

    def cartesian(T_goal, scale: float):
        with clock("ik"):
            path = cartesian_path(model, q_start=target.arm_qpos(), T_goal=T_goal)
        with clock("timing"):
            traj = retime(path, vel_limits=vel * scale, acc_limits=acc * scale, dt=model.opt.timestep)
        stream(traj)

    def offset(dz):
        T = target.tcp_pose().copy()
        T[2, 3] += dz
        return T

    def entity(snap, name):
        e = next(e for e in snap["entities"] if e["name"] == name)
        T = np.eye(4)
        T[:3, 3] = e["position"]
        import mujoco

        m = np.zeros(9)
        mujoco.mju_quat2Mat(m, np.asarray(e["quat_wxyz"], dtype=float))
        T[:3, :3] = m.reshape(3, 3)
        return T, np.asarray(e["size"], dtype=float)

    # pick (trees/pick.yaml)
    snap = target.snapshot()
    with clock("simulation"):
        target.set_gripper(opening_m=0.04)
    T_obj, half = entity(snap, "cube")
    grasp = top_down_grasp(T_obj, half, approach_height_m=m.pick_approach_height_m)
    move_to(grasp.pregrasp, scale=m.pick_transfer_velocity_scale)
    cartesian(grasp.pregrasp, m.approach_velocity_scale)  # AlignOverObject
    cartesian(grasp.grasp, m.approach_velocity_scale)
    with clock("simulation"):
        target.set_gripper(opening_m=0.0)
        assert target.held_objects() == ("cube",)
    cartesian(offset(m.lift_m), m.lift_velocity_scale)
    assert held() == "cube"
    # place (trees/place.yaml)
    snap = target.snapshot()
    T_region, _ = entity(snap, "goal")
    T_obj, half = entity(snap, "cube")
    T_place = place_pose(T_region[:3, 3], half, T_tcp_object=np.linalg.inv(target.tcp_pose()) @ T_obj)
    T_pre = T_place.copy()
    T_pre[2, 3] += m.place_approach_height_m
    move_to(T_pre, scale=m.place_transfer_velocity_scale)
    cartesian(T_place, m.lower_velocity_scale)
    with clock("simulation"):
        target.set_gripper(opening_m=0.04)
    cartesian(offset(m.retreat_offset_m), m.retreat_velocity_scale)
    move_to(q_goal=np.asarray(target.home_qpos, dtype=float))  # ClearTheView
    final = target.object_pose("cube")[:3, 3]
    assert scene.region("goal").contains_xy(final[:2]), f"cube ended at {final}"
    total = time.perf_counter() - t_start
    return {"total_s": total, **{f"{k}_s": v for k, v in clock.totals.items()},
            "other_s": total - sum(clock.totals.values()), "sim_time_s": target.sim_time}


def framework_run(seed: int = 0) -> dict:
    """``run_goal_graph`` on a fresh workspace; split from the sessions' recorded timings."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        report = run_goal_graph(GRAPH, Path(tmp) / "ws", seed=seed)
        total = time.perf_counter() - t0
        assert report.succeeded, report.to_dict()
        ws = Workspace.open(Path(tmp) / "ws")
        totals = dict.fromkeys(CATEGORIES, 0.0)
        sim = 0.0
        for row in report.sessions:
            attempt = ws.load_session(row.session_id).attempts[-1]
            for k in CATEGORIES:
                totals[k] += attempt.timings.get(k, 0.0)
            bundle = read_yaml(ws.root / attempt.evidence / "bundle.yaml", error=BenchError)
            sim = bundle["outcome"]["sim_time_s"]
    return {"total_s": total, **{f"{k}_s": v for k, v in totals.items()},
            "other_s": total - sum(totals.values()), "sim_time_s": sim}


def main(argv=None) -> int:
    parser = bench_parser(__doc__, "pick_and_place")
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args(argv)
    framework_run(0), bare_same_motions(0)  # warm-up: imports, mesh loading, OMPL/toppra first calls
    fw, bare = [], []
    for i in range(args.runs):
        fw.append(framework_run(seed=i))
        bare.append(bare_same_motions(seed=i))
        print(f"run {i + 1}/{args.runs}: framework {fw[-1]['total_s']:.3f} s, bare {bare[-1]['total_s']:.3f} s", file=sys.stderr)
    keys = ["total_s", "ik_s", "planning_s", "timing_s", "simulation_s", "other_s", "sim_time_s"]
    med = lambda rows, k: statistics.median(r[k] for r in rows)  # noqa: E731
    result = {
        "runs": args.runs,
        "framework_median": {k: med(fw, k) for k in keys},
        "bare_median": {k: med(bare, k) for k in keys},
        "framework_runs": fw,
        "bare_runs": bare,
    }
    result["ratio_framework_to_bare"] = result["framework_median"]["total_s"] / result["bare_median"]["total_s"]
    result["framework_overhead_fraction"] = result["framework_median"]["other_s"] / result["framework_median"]["total_s"]
    print(f"\npick and place, median of {args.runs} runs (seconds)")
    print(f"{'':22s}{'framework':>12s}{'bare':>12s}")
    labels = {"other_s": "overhead / glue"}
    for k in keys:
        print(f"{labels.get(k, k):22s}{result['framework_median'][k]:12.3f}{result['bare_median'][k]:12.3f}")
    print(f"\nframework / bare wall time: {result['ratio_framework_to_bare']:.2f}  (goal <= 1.20)")
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
