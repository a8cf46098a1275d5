"""Bare pick-and-place on DEFAULT_SCENE using only phyagentos.targets and phyagentos.motion.

No framework, no behaviour trees: this is the floor the orchestrated version is compared
against. It makes the motions a ``phyagentos run`` of phyagentos/data/goal_graphs/pick_and_place.yaml
makes, in the order the shipped trees (trees/pick.yaml, trees/place.yaml) make them and
at their speeds (:class:`SkillMotions`, read from those files): open -> plan to the
pregrasp -> Cartesian align over the object and approach -> close -> Cartesian lift ->
plan the transfer over the wall with the cube attached -> Cartesian lower -> open ->
Cartesian retreat -> plan back to the ready configuration (out of the cameras' view).
The cube must end inside the goal region.

Usage::

    python bench/bare_pick_and_place.py [--runs 3] [--seed 0] [--plan-repeats 30] [--perception]

Prints a table and writes bench/results/bare_pick_and_place.json. The core is
``run_bare_pick_and_place(seed=0) -> dict`` (wall-time split in seconds: ik_s,
planning_s, timing_s, simulation_s, total_s; sim_time_s; per-call medians).
"""

from __future__ import annotations

import json
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from phyagentos.errors import BenchError, IKError  # noqa: E402
from phyagentos.motion import (  # noqa: E402
    DEFAULT_ACCELERATION_LIMITS,
    CollisionChecker,
    cartesian_path,
    hand_yaw,
    last_plan_stats,
    place_pose,
    plan_path,
    retime,
    solve_ik,
    top_down_grasp,
    top_down_grasp_candidates,
)
from phyagentos.targets import DEFAULT_SCENE, MuJoCoTarget, SceneSpec  # noqa: E402
from phyagentos.yamlsource import read_yaml

_ROOT = Path(__file__).resolve().parents[1]
TREES = _ROOT / "phyagentos" / "data" / "trees"

#: ``CartesianMove``'s velocity scale where a tree gives none (trees/place.yaml's Retreat);
#: phyagentos/primitives/execution.py, pinned equal by tests/test_mujoco_target.py.
CARTESIAN_DEFAULT_VELOCITY_SCALE = 0.3


@dataclass(frozen=True)
class SkillMotions:
    """The motion parameters of the shipped pick and place trees, so that the bare script
    moves as a run does (speeds are fractions (0, 1] of the joint velocity limits, and of
    the acceleration limits alike, as ``CartesianMove`` and ``move_to`` scale both)."""

    pick_approach_height_m: float
    approach_velocity_scale: float
    lift_m: float
    lift_velocity_scale: float
    pick_transfer_velocity_scale: float
    place_approach_height_m: float
    place_transfer_velocity_scale: float
    lower_velocity_scale: float
    retreat_offset_m: float
    retreat_velocity_scale: float

    @classmethod
    def from_trees(cls, trees: Path = TREES) -> "SkillMotions":
        """Read the parameter defaults of ``trees/pick.yaml`` and ``trees/place.yaml`` and
        the place tree's ``Retreat`` node. Raises BenchError for a file that does not
        read, KeyError if a tree lost one of them."""
        pick, place = (read_yaml(trees / name, error=BenchError) for name in ("pick.yaml", "place.yaml"))
        pd, qd = ({k: v["default"] for k, v in t["params"].items() if "default" in v} for t in (pick, place))
        retreat = next(c["params"] for c in place["root"]["sequence"]["children"] if c.get("name") == "Retreat")
        dx, dy, dz = retreat["offset"]
        assert dx == dy == 0.0, "trees/place.yaml's Retreat is no longer straight up"
        return cls(
            pick_approach_height_m=float(pd["approach_height_m"]),
            approach_velocity_scale=float(pd["approach_velocity_scale"]),
            lift_m=float(pd["lift_m"]),
            lift_velocity_scale=float(pd["lift_velocity_scale"]),
            pick_transfer_velocity_scale=float(pd["transfer_velocity_scale"]),
            place_approach_height_m=float(qd["approach_height_m"]),
            place_transfer_velocity_scale=float(qd["transfer_velocity_scale"]),
            lower_velocity_scale=float(qd["lower_velocity_scale"]),
            retreat_offset_m=float(dz),
            retreat_velocity_scale=float(retreat.get("velocity_scale", CARTESIAN_DEFAULT_VELOCITY_SCALE)),
        )


class _Clock:
    """Accumulates wall time per category."""

    def __init__(self) -> None:
        self.s = {"ik": 0.0, "planning": 0.0, "timing": 0.0, "simulation": 0.0, "setup": 0.0, "perception": 0.0}

    def run(self, cat: str, fn, *args, **kwargs):
        t = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            self.s[cat] += time.perf_counter() - t


def run_bare_pick_and_place(
    seed: int = 0,
    *,
    scene: SceneSpec = DEFAULT_SCENE,
    object_name: str = "cube",
    region_name: str = "goal",
    planner: str = "RRTConnect",
    margin_m: float = 0.01,
    motions: SkillMotions | None = None,
    observer: Callable[[str, MuJoCoTarget], None] | None = None,
    perception: bool = False,
) -> dict:
    """Run one pick-and-place and return timings; raises AssertionError on failure.

    Returns a dict with wall-time split (``ik_s``, ``planning_s``, ``timing_s``,
    ``simulation_s``, ``setup_s``, ``total_s``), ``sim_time_s``, per-call medians
    (``ik_iterations_median``, ``ik_ms_median``, ``plan_ms_median``), counts, the final
    cube position and the tracking errors of each executed trajectory. ``motions``:
    heights and speeds (default: :meth:`SkillMotions.from_trees`, the shipped trees').
    ``observer(stage, target)``, if given, is called after the stages ``'grasped'``,
    ``'transferred'``, ``'released'`` and ``'retreated'`` (not timed separately).

    ``perception=True`` runs the same perception as a ``phyagentos run`` of
    phyagentos/data/goal_graphs/pick_and_place.yaml, at the same points and as often: the target's camera
    sensors (shipped ``sensors.yaml``, same resolution) captured and fused by a fresh
    :class:`~phyagentos.perception.Perceiver` per skill through
    :func:`phyagentos.primitives.observation.perceive_now` (frames saved as PNG like the
    SessionRunner saves them), before and after each skill (the SessionRunner's initial
    and terminal observation; the place starts from the pick's terminal view, as a run's
    does when nothing moved in between) and where the skill trees observe (pick: ObserveScene,
    ObserveAfterPick; place: ObserveScene, and ObserveAfterPlace after the arm cleared
    the cameras' view). Timed as ``perception_s`` (and in ``total_s``); the motions
    themselves still use the simulator's object pose, as without perception.
    """

    def notify(stage: str) -> None:
        if observer is not None:
            t = time.perf_counter()
            observer(stage, target)
            clock.s["observer"] = clock.s.get("observer", 0.0) + time.perf_counter() - t

    clock = _Clock()
    t_start = time.perf_counter()
    ik_iters: list[int] = []
    ik_ms: list[float] = []
    ik_pose_iters: list[int] = []  # stand-alone pose IK (pregrasp, preplace)
    ik_pose_ms: list[float] = []
    plan_ms: list[float] = []
    tracking: list[float] = []
    unexpected: list = []

    m = motions if motions is not None else SkillMotions.from_trees()
    target = clock.run("setup", MuJoCoTarget, "bare", scene, seed=seed)
    perceive = _Perception(target, clock) if perception else None
    if perceive:
        perceive.new_skill()
        perceive("initial")  # SessionRunner, before the pick
        perceive("01_ObserveScene")
    model = target.model
    checker = clock.run("planning", CollisionChecker, model, margin_m=margin_m)
    # Straight-line moves end in contact on purpose (fingers around the cube, cube on
    # the table), so they are checked without the planning margin.
    contact_checker = clock.run("planning", CollisionChecker, model, margin_m=0.0)
    vel = target.velocity_limits()
    acc = np.array(DEFAULT_ACCELERATION_LIMITS)
    obj = scene.object(object_name)
    region = scene.region(region_name)

    def ik(T, q_seed):
        t = time.perf_counter()
        sol = solve_ik(model, q_seed=q_seed, target=T, qpos_full=target.data.qpos)
        dt = time.perf_counter() - t
        clock.s["ik"] += dt
        ik_ms.append(dt * 1e3)
        ik_iters.append(sol.iterations)
        ik_pose_ms.append(dt * 1e3)
        ik_pose_iters.append(sol.iterations)
        return sol.q

    def plan(q_goal):
        checker.set_world_state(target.data.qpos)
        t = time.perf_counter()
        P = plan_path(checker, target.arm_qpos(), q_goal, planner=planner, seed=seed)
        dt = time.perf_counter() - t
        clock.s["planning"] += dt
        plan_ms.append(dt * 1e3)
        return P

    def cartesian(T_goal, q_start=None):
        stats: dict = {}
        t = time.perf_counter()
        q0 = target.arm_qpos() if q_start is None else q_start
        P = cartesian_path(model, q_start=q0, T_goal=T_goal, qpos_full=target.data.qpos, stats=stats)
        clock.s["ik"] += time.perf_counter() - t
        ik_iters.extend(stats["ik_iterations"])
        ik_ms.extend(stats["ik_solve_ms"])
        return P

    def check_straight(P, what: str, *, attached: np.ndarray | None = None, skip_first: bool = False) -> bool:
        t = time.perf_counter()
        contact_checker.set_world_state(target.data.qpos)
        if attached is not None:
            contact_checker.attach(object_name, attached)
        try:
            return contact_checker.check_path(P[1:] if skip_first else P)
        finally:
            contact_checker.detach()
            clock.s["planning"] += time.perf_counter() - t

    def execute(P, *, check: bool, attached: np.ndarray | None = None, scale: float = 1.0):
        # Planned paths hug the 1 cm planning margin after shortcutting, so the timed
        # trajectory (whose spline deviates slightly from the polyline) is verified
        # against real contact (margin 0) rather than against the margin again.
        if check:
            contact_checker.set_world_state(target.data.qpos)
            if attached is not None:
                contact_checker.attach(object_name, attached)
        try:
            traj = clock.run("timing", retime, P, vel_limits=vel * scale, acc_limits=acc * scale, dt=target.timestep,
                             checker=contact_checker if check else None)
        finally:
            contact_checker.detach()
        res = clock.run("simulation", target.execute_trajectory, traj, tracking_tol_rad=0.05)
        assert res.completed, f"execution stopped: {res.reason}"
        tracking.append(res.max_tracking_error_rad)
        unexpected.extend(res.contacts)
        return res

    # 1. open (pick: OpenGripper), choose a grasp whose approach is collision free, plan
    # home -> pregrasp
    clock.run("simulation", target.set_gripper, opening_m=0.04)
    T_obj = target.object_pose(object_name)
    q_home = target.arm_qpos()
    candidates = top_down_grasp_candidates(
        T_obj, obj.half_extents, approach_height_m=m.pick_approach_height_m,
        current_yaw_rad=hand_yaw(target.tcp_pose()), current_q7_rad=float(q_home[6]),
    )
    chosen = None
    for grasp in candidates:
        try:
            q_pre = ik(grasp.pregrasp, q_home)
            approach = cartesian(grasp.grasp, q_start=q_pre)
        except IKError:
            continue
        checker.set_world_state(target.data.qpos)
        if checker.is_valid(q_pre) and check_straight(approach, "approach"):
            chosen = grasp
            break
    assert chosen is not None, "no collision-free top-down grasp"
    grasp = chosen
    execute(plan(q_pre), check=True, scale=m.pick_transfer_velocity_scale)
    # 2. Cartesian align over the object and approach (AlignOverObject, Approach), close
    execute(cartesian(grasp.pregrasp), check=False, scale=m.approach_velocity_scale)
    execute(cartesian(grasp.grasp), check=False, scale=m.approach_velocity_scale)
    g = clock.run("simulation", target.set_gripper, opening_m=0.0)
    # the bare floor reads the simulator's contacts (ground truth), as it reads the true poses
    assert target.held_objects() == (object_name,), f"grasp failed: {g}"
    T_tcp_obj = np.linalg.inv(target.tcp_pose()) @ target.object_pose(object_name)
    notify("grasped")
    # 3. Cartesian lift
    lift = np.array(target.tcp_pose())
    lift[2, 3] += m.lift_m
    P = cartesian(lift)
    assert check_straight(P, "lift", attached=T_tcp_obj, skip_first=True), "lift collides"
    execute(P, check=False, scale=m.lift_velocity_scale)
    if perceive:
        perceive("02_ObserveAfterPick")
        perceive("terminal")  # SessionRunner, after the pick
        perceive.new_skill()
        # SessionRunner, before the place: nothing moved since the pick's terminal view, so
        # a run starts the place from that view (TargetPool.take_view); not perceived again.
        perceive("01_ObserveScene")
    # 4. transfer over the wall (planned, cube attached)
    T_place = place_pose(region.center, obj.half_extents, T_tcp_object=T_tcp_obj, yaw_rad=grasp.yaw_rad)
    T_preplace = T_place.copy()
    T_preplace[2, 3] += m.place_approach_height_m
    q_preplace = ik(T_preplace, target.arm_qpos())
    checker.attach(object_name, T_tcp_obj)
    execute(plan(q_preplace), check=True, attached=T_tcp_obj, scale=m.place_transfer_velocity_scale)
    checker.detach()
    notify("transferred")
    # 5. Cartesian lower, open, retreat
    P = cartesian(T_place)
    assert check_straight(P, "lower", attached=T_tcp_obj), "lowering collides"
    execute(P, check=False, scale=m.lower_velocity_scale)
    g = clock.run("simulation", target.set_gripper, opening_m=0.04)
    assert not target.held_objects(), f"object still held after opening: {g}"
    notify("released")
    retreat = np.array(target.tcp_pose())
    retreat[2, 3] += m.retreat_offset_m
    P = cartesian(retreat)
    assert check_straight(P, "retreat"), "retreat collides"
    execute(P, check=False, scale=m.retreat_velocity_scale)
    notify("retreated")
    # 6. back to the ready configuration (place: ClearTheView, with cameras or without)
    execute(plan(np.asarray(target.home_qpos, dtype=float)), check=True)
    if perceive:
        perceive("02_ObserveAfterPlace")
        perceive("terminal")  # SessionRunner, after the place

    # verify
    p = target.object_pose(object_name)[:3, 3]
    inside = region.contains_xy(p[:2])
    resting = abs(p[2] - obj.rest_z) < 0.005
    rel = target.snapshot()["relations"]
    assert inside and resting, f"cube not in region: position {p.round(4).tolist()}, region {region}"
    assert {"subject": object_name, "relation": "inside", "object": region_name} in rel, rel
    total = time.perf_counter() - t_start - clock.s.get("observer", 0.0)
    sim_time = target.sim_time
    target.close()
    if perceive:
        perceive.close()
    return {
        "seed": seed,
        "success": True,
        "ik_s": clock.s["ik"],
        "planning_s": clock.s["planning"],
        "timing_s": clock.s["timing"],
        "simulation_s": clock.s["simulation"],
        "setup_s": clock.s["setup"],
        "perception_s": clock.s.get("perception", 0.0),
        "perception_passes": perceive.passes if perceive else 0,
        "total_s": total,
        "sim_time_s": sim_time,
        "realtime_factor": sim_time / total,
        "ik_calls": len(ik_ms),
        "ik_iterations_median": float(statistics.median(ik_iters)),
        "ik_ms_median": float(statistics.median(ik_ms)),
        "ik_ms_per_iteration": float(sum(ik_ms) / max(1, sum(ik_iters))),
        "ik_pose_iterations_median": float(statistics.median(ik_pose_iters)),
        "ik_pose_ms_median": float(statistics.median(ik_pose_ms)),
        "plan_calls": len(plan_ms),
        "plan_ms_median": float(statistics.median(plan_ms)),
        "plan_ms": plan_ms,
        "max_tracking_error_rad": max(tracking),
        "unexpected_contacts": sorted({tuple(c) for c in unexpected}),
        "cube_final_position": [float(x) for x in p],
    }


class _Perception:
    """The SessionRunner's perception without the framework: a fresh Perceiver per skill
    (``make_perceiver``, which continues the previous skill's tracks from
    ``target.runtime_notes`` like a run does) and ``perceive_now`` with the frames saved
    into a scratch evidence directory."""

    def __init__(self, target: MuJoCoTarget, clock: _Clock) -> None:
        import tempfile  # noqa: PLC0415

        from phyagentos.primitives.observation import has_cameras  # noqa: PLC0415

        assert has_cameras(target), "the bare target has no camera sensors (sensors.yaml)"
        self.target, self.clock, self.passes, self.skill = target, clock, 0, 0
        self.tmp = tempfile.TemporaryDirectory(prefix="bare-evidence-")
        self.perceiver = None

    def new_skill(self) -> None:
        from phyagentos.primitives.observation import make_perceiver  # noqa: PLC0415

        self.skill += 1
        self.perceiver = self.clock.run("perception", make_perceiver, self.target, None)

    def __call__(self, tag: str) -> dict:
        from phyagentos.primitives.observation import perceive_now  # noqa: PLC0415

        evidence = Path(self.tmp.name) / f"skill{self.skill}"
        snap = self.clock.run("perception", perceive_now, self.target, self.perceiver, evidence_dir=evidence,
                              evidence_rel=f"evidence/skill{self.skill}", tag=tag)
        assert snap is not None and snap.get("entities"), f"perception saw nothing at {tag}"
        self.passes += 1
        return snap

    def close(self) -> None:
        self.tmp.cleanup()


def plan_over_wall_benchmark(repeats: int = 30, planner: str = "RRTConnect", margin_m: float = 0.01) -> dict:
    """Median/percentiles of plan_path over the wall (pregrasp above the cube to above
    the goal, cube attached), one seed per repeat."""
    target = MuJoCoTarget("plan-bench", DEFAULT_SCENE, seed=0)
    model = target.model
    checker = CollisionChecker(model, margin_m=margin_m)
    checker.set_world_state(target.data.qpos)
    T_obj = target.object_pose("cube")
    grasp = top_down_grasp(T_obj, (0.02, 0.02, 0.02))
    q_a = solve_ik(model, q_seed=target.home_qpos, target=grasp.pregrasp).q
    T_b = np.array(grasp.pregrasp)
    T_b[:2, 3] = DEFAULT_SCENE.region("goal").center
    q_b = solve_ik(model, q_seed=q_a, target=T_b).q
    T_tcp_obj = np.eye(4)
    checker.attach("cube", T_tcp_obj)
    times = []
    lengths = []
    for s in range(repeats):
        t = time.perf_counter()
        plan_path(checker, q_a, q_b, planner=planner, seed=s)
        times.append((time.perf_counter() - t) * 1e3)
        lengths.append(last_plan_stats()["length_rad"])
    target.close()
    times.sort()
    return {
        "planner": planner,
        "repeats": repeats,
        "median_ms": statistics.median(times),
        "p90_ms": times[int(0.9 * (len(times) - 1))],
        "max_ms": times[-1],
        "median_length_rad": statistics.median(lengths),
    }


def main(argv=None) -> int:
    from _harness import parser, write_json  # noqa: PLC0415  (here: tests/test_end_to_end.py loads this file as a module)

    ap = parser(__doc__, "bare_pick_and_place")
    ap.add_argument("--runs", type=int, default=3, help="measured runs after one warm-up run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plan-repeats", type=int, default=30)
    ap.add_argument("--perception", action="store_true",
                    help="perceive where a phyagentos run of pick_and_place.yaml perceives (see run_bare_pick_and_place)")
    ap.add_argument("--once", action="store_true",
                    help="one cold run, print its result as JSON, write nothing (bench/end_to_end.py)")
    args = ap.parse_args(argv)
    if args.once:
        print(json.dumps(run_bare_pick_and_place(seed=args.seed, perception=args.perception)))
        return 0

    cold = run_bare_pick_and_place(seed=args.seed, perception=args.perception)
    runs = [run_bare_pick_and_place(seed=args.seed + i, perception=args.perception) for i in range(args.runs)]
    runs_sorted = sorted(runs, key=lambda r: r["total_s"])
    med = runs_sorted[len(runs_sorted) // 2]
    wall = plan_over_wall_benchmark(args.plan_repeats) if args.plan_repeats > 0 else None

    keys = ["ik_s", "planning_s", "timing_s", "simulation_s", "setup_s", "perception_s", "total_s", "sim_time_s"]
    print(f"{'metric':<28}{'cold':>10}{'median run':>12}")
    for k in keys:
        print(f"{k:<28}{cold[k]:>10.3f}{med[k]:>12.3f}")
    for k in ["ik_calls", "ik_iterations_median", "ik_ms_median", "ik_ms_per_iteration",
              "ik_pose_iterations_median", "ik_pose_ms_median", "plan_ms_median",
              "max_tracking_error_rad", "realtime_factor"]:
        print(f"{k:<28}{cold[k]:>10.3f}{med[k]:>12.3f}")
    if wall:
        print(f"RRTConnect over the wall ({wall['repeats']} seeds): median {wall['median_ms']:.1f} ms, "
              f"p90 {wall['p90_ms']:.1f} ms, max {wall['max_ms']:.1f} ms")
    print(f"cube final position {med['cube_final_position']}, unexpected contacts {med['unexpected_contacts']}")

    out = {"cold": cold, "median_run": med, "runs": runs, "plan_over_wall": wall}
    write_json(args.out, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
