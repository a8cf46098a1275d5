"""Motion leaves: mink IK, OMPL planning and toppra retiming.

They compute and write to the blackboard; execution is a separate leaf so that
a tree can re-plan without re-executing, and so each stage is timed on its own
(``ik``, ``planning``, ``timing`` in the session's profile).
"""

from __future__ import annotations

import weakref

import numpy as np

from phyagentos.errors import IKError
from phyagentos.motion.collision import CollisionChecker
from phyagentos.motion.ik import solve_ik
from phyagentos.motion.planner import plan_path
from phyagentos.motion.retime import retime
from phyagentos.targets.contract import arm_dynamics_of

from . import planning_world
from .base import Primitive

__all__ = ["ReadyConfiguration", "SolveIK", "clear_ik", "SWIVEL_SEEDS_RAD",
           "PlanPath", "RetimePath", "session_checker", "held_object", "execution_limits", "ik_options",
           "PLANNING_MARGIN_M", "MAX_TRACED_WAYPOINTS", "traced_path", "start_contact_kind", "nearer_reachable_hand"]


def held_object(target) -> str | None:
    """Name of the object the gripper holds now, from the target's own state query."""
    for rel in target.snapshot().get("relations", []):
        if rel.get("relation") == "holding":
            return rel.get("object")
    return None


_CHECKERS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()

#: Clearance kept while planning, m. Shortcut paths run right along it, so the
#: timed trajectory is re-checked at zero margin (toppra may cut inside it).
PLANNING_MARGIN_M = 0.01


#: Most waypoints of a planned path kept in the trace (``plan`` ``path_rad``).
MAX_TRACED_WAYPOINTS = 64


def nearer_reachable_hand(ctx, closing: np.ndarray, pointing: np.ndarray,
                          points: list[np.ndarray]) -> tuple[float, np.ndarray] | None:
    """Of the two hands whose tool z axis is ``pointing`` (3,) world unit and whose fingers close
    along ``closing`` or its opposite (3,) world unit, at right angles to it, the one the arm
    reaches (IK, no collision check) at every point of ``points`` ((3,) world m, tool point),
    nearer the current wrist: ``(turn rad from the current hand, (3, 3) world rotation)``;
    ``None`` where the arm reaches neither.

    IK is seeded with the current joints; only when neither hand converges from there is each
    tried again from the target's ready configuration ``home_qpos`` (as :func:`clear_ik` seeds):
    the solver is local, and from a wrist wound far from the goal it stops short of poses the
    arm reaches (LIBERO-10 task 9, init 9: the push that shuts the microwave, 4-15 cm short from
    the joints the place left, reached from the ready configuration with either hand)."""
    target = ctx.target
    names, frame = tuple(target.arm_joint_names), target.tcp_site
    wrist = target.tcp_pose()[:3, :3]
    current, home = target.arm_qpos(), np.asarray(target.home_qpos, dtype=float)
    seeds = (current,) if np.allclose(current, home) else (current, home)  # at the ready pose already: once
    for seed in seeds:
        best = None
        for sign in (1.0, -1.0):
            y = sign * np.asarray(closing, dtype=float)
            R = np.column_stack([np.cross(y, pointing), y, np.asarray(pointing, dtype=float)])
            try:
                with ctx.profiler.section("ik"):
                    for p in points:
                        T = np.eye(4)
                        T[:3, :3], T[:3, 3] = R, p
                        solve_ik(target.model, q_seed=seed, target=T, arm_joint_names=names, frame=frame)
            except IKError:
                continue
            turn = float(np.arccos(np.clip((np.trace(wrist.T @ R) - 1.0) / 2.0, -1.0, 1.0)))
            if best is None or turn < best[0]:
                best = (turn, R)
        if best is not None:
            return best
    return None


def traced_path(path: np.ndarray) -> list[list[float]]:
    """A planned joint path as the trace keeps it: ``(M, n)`` rad, rounded to 1e-4 rad.

    Paths longer than :data:`MAX_TRACED_WAYPOINTS` are thinned evenly (first and last
    waypoint kept). The planner's path is piecewise linear in joint space, so the kept
    waypoints, joined by straight joint-space segments, are the plan (exactly, up to the
    thinning).
    """
    q = np.asarray(path, dtype=float)
    if len(q) > MAX_TRACED_WAYPOINTS:
        q = q[np.linspace(0, len(q) - 1, MAX_TRACED_WAYPOINTS).round().astype(int)]
    return q.round(4).tolist()


def ik_options(target, orientation_tol_rad: float = 1e-2) -> dict:
    """Keyword arguments of :func:`~phyagentos.motion.ik.solve_ik` / ``cartesian_path`` for
    ``target``, from what it declares: its ``arm_joint_names`` (any number of joints), its
    tool site ``tcp_site`` (default ``tcp``) and, for an arm that cannot reach every
    orientation, ``ik_orientation_tol_rad``: position-priority IK accepting orientations
    within that tolerance (the larger of it and ``orientation_tol_rad``)."""
    opts = {"arm_joint_names": tuple(target.arm_joint_names), "frame": target.tcp_site}
    relaxed = target.ik_orientation_tol_rad
    if relaxed is not None:
        opts["position_priority"] = True
        opts["orientation_tol_rad"] = max(float(relaxed), orientation_tol_rad)
    return opts


def execution_limits(ctx, velocity_scale: float, acceleration_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """``(velocity (n,) rad/s, acceleration (n,) rad/s^2)`` limits for timing a motion.

    Velocity comes from the target (what its actuators sustain: the simulated
    Panda's damping and force limits allow far less than the datasheet), times
    ``velocity_scale``; acceleration from :data:`DEFAULT_ACCELERATION_LIMITS`.
    """
    vel = np.asarray(ctx.target.velocity_limits(), dtype=float) * velocity_scale
    # A target that is not the Franka declares its own (n,) acceleration limits.
    acc = np.asarray(ctx.target.acceleration_limits(), dtype=float) * acceleration_scale
    return vel, acc


def session_checker(ctx, *, margin_m: float = 0.0, opening_m: float | None = None) -> CollisionChecker:
    """A collision checker synced to the world the target plans in: for a
    :class:`~phyagentos.targets.contract.PlansInPerceivedWorld` target (LIBERO, the tabletop
    scenes) the world its
    robot perceived (:mod:`phyagentos.primitives.planning_world`), else the simulator's state;
    with ``opening_m`` (m per finger) its fingers stand that far open instead of as they are
    (:meth:`~phyagentos.motion.collision.CollisionChecker.set_gripper_opening`: a hand
    pre-shaped before it approaches).

    Whatever the gripper holds is attached at its offset in the hand (perceived, or the
    simulator's for a world that plans in its state) so transfers are checked with the
    object in hand. Checkers are cached per target and margin:
    building one copies the model (~15 ms), and a target outlives its sessions. The
    checkers of one target share one copy (a LIBERO world's is about 250 MB, most of it
    textures: one copy, not one per margin).
    """
    target = ctx.target
    cache = _CHECKERS.setdefault(target, {})
    checker = cache.get(margin_m)
    if checker is None:
        # A target may name its tool site, robot body pairs its model lets touch (e.g.
        # adjacent links a third-party model does not exclude) and its gripper's bodies.
        checker = CollisionChecker(target.model, arm_joint_names=target.arm_joint_names, margin_m=margin_m,
                                   tcp_site=target.tcp_site, allowed_pairs=target.allowed_collision_pairs,
                                   gripper_bodies=target.gripper_body_names,
                                   share_model_of=next((c for c in cache.values()
                                                        if c.model_source is target.model), None))
        cache[margin_m] = checker
    perceived = planning_world.plans_in_perceived_world(target)
    if perceived:  # what the robot perceived, never where the simulator has put things
        planning_world.apply(target, checker)
    else:  # a target without the capability (FrankaKitchen): the simulator's state
        checker.set_world_state(target.data.qpos)
    if opening_m is not None:
        checker.set_gripper_opening(opening_m)
    checker.detach()
    # What to attach. In the perceived world: what its last look saw in the hand, else the
    # object the robot believes it closed on (proprioception); both by perception's names, as
    # the world places everything. In the simulator's: what the hand's contacts say it holds
    # (one of two identical moka pots, named by perception as the other, is the one in the
    # hand), else the belief. The collision model is the runtime's, never the Agent's.
    from .grasp_sense import belief  # noqa: PLC0415

    if perceived:
        obj = planning_world.held(target) or belief(target).object
        T = planning_world.in_hand(target, obj) if obj is not None else None
    else:
        obj = held_object(target) or belief(target).object
        T = np.linalg.inv(target.tcp_pose()) @ target.object_pose(obj) if obj is not None else None
    if obj is not None and T is not None:
        checker.attach(target.object_body(obj), T)
    return checker


def start_contact_kind(checker: CollisionChecker, pairs) -> str:
    """What an invalid start configuration touches, from the checker's colliding name
    pairs: ``self`` (only the arm's own links), ``held_object`` (the carried object
    against the arm), ``joint_limit``, else ``environment`` (table, obstacles, objects)."""
    if any(a == "joint_limit" for a, _ in pairs):
        return "joint_limit"
    robot = {checker.model.body(b).name for b in checker.robot_bodies}
    if pairs and all(a in robot and b in robot for a, b in pairs):
        return "self"
    held = checker.attached
    if held is not None and pairs and all(held in (a, b) and (a in robot or b in robot) for a, b in pairs):
        return "held_object"
    return "environment"


class ReadyConfiguration(Primitive):
    """Write the target's ready (home) joint configuration (n,) rad to blackboard ``out``,
    e.g. to take the arm out of the cameras' view before a final observation."""

    def __init__(self, name: str, *, out: str = "q_goal"):
        super().__init__(name)
        self.out = out
        self.writes(out)

    def step(self):
        self.set(self.out, np.asarray(self.ctx.target.home_qpos, dtype=float))


#: Offsets (rad) added to joints 1, 3 and 5 of a 7-joint arm's ready configuration to seed
#: IK when the solution from the current joints collides: the elbow swung to either side
#: (the 7-dof arm's redundancy), so the forearm clears a neighbouring bottle.
SWIVEL_SEEDS_RAD: tuple[tuple[float, float, float], ...] = (
    (0.0, 0.6, 0.0), (0.0, -0.6, 0.0), (0.4, 0.8, -0.4), (-0.4, -0.8, 0.4))


def clear_ik(ctx, pose: np.ndarray, *, q_seed=None, position_tol_m: float = 1e-3, orientation_tol_rad: float = 1e-2,
             allow: str | None = None, margin_m: float = PLANNING_MARGIN_M, opening_m: float | None = None):
    """IK for the (4, 4) world tcp ``pose`` whose configuration is clear of the scene.

    Seeds, in order: ``q_seed`` (default the current joints), the target's ready
    configuration ``home_qpos``, then (7 joints) that configuration with the elbow swung
    (:data:`SWIVEL_SEEDS_RAD`). The first converged solution clear of collisions (the
    session's checker with clearance ``margin_m``, default the planner's, the held object
    attached; pairs naming body ``allow`` ignored; the fingers ``opening_m`` m open each when
    given, else as they are) is returned; when none is clear, the first converged one. Returns ``(solution,
    colliding pairs of it, seed)``, seed ``"current"`` (or ``"given"``), ``"home_qpos"`` or
    ``"swivel <k>"``.

    Raises:
        IKError: no seed converged (the error of the first).
    """
    target = ctx.target
    opts = ik_options(target, orientation_tol_rad)
    opts.setdefault("orientation_tol_rad", orientation_tol_rad)
    try:
        checker = session_checker(ctx, margin_m=margin_m, opening_m=opening_m)
    except Exception:  # noqa: BLE001 - a target without a collision model: IK only
        checker = None
    home = np.asarray(target.home_qpos, dtype=float)
    seeds = [("current" if q_seed is None else "given",
              np.asarray(target.arm_qpos() if q_seed is None else q_seed, dtype=float)), ("home_qpos", home)]
    if home.shape == (7,):
        for k, (d1, d3, d5) in enumerate(SWIVEL_SEEDS_RAD):
            seeds.append((f"swivel {k}", home + np.array([d1, 0.0, d3, 0.0, d5, 0.0, 0.0])))
    first, error = None, None
    for i, (label, seed) in enumerate(seeds):
        if i >= 2 and first is None:
            break  # the swivel seeds only look for a clear one among converging solutions
        try:
            sol = solve_ik(target.model, q_seed=seed, target=pose, position_tol_m=position_tol_m, **opts)
        except IKError as exc:
            error = error or exc
            continue
        pairs = () if checker is None else tuple(p for p in checker.colliding_pairs(sol.q) if allow not in p)
        if not pairs:
            return sol, (), label
        if first is None:
            first = (sol, pairs, label)
        if checker is None:
            break
    if first is not None:
        return first
    raise error  # type: ignore[misc]


class SolveIK(Primitive):
    """Joint configuration (n,) rad reaching the (4, 4) tcp pose at blackboard key ``pose``
    (joints, tool site and orientation tolerance as the target declares, :func:`ik_options`).

    The solver starts from the current arm configuration; when that stalls (a wrapped-up
    arm far from the goal, e.g. after a grasp at a large yaw), it starts once more from the
    target's ready configuration ``home_qpos`` before failing with the first error; when the
    solution collides with the scene, other seeds look for one that does not
    (:func:`clear_ik`; the planner would refuse the colliding goal).

    Args:
        pose: blackboard key of the target tcp pose (world frame).
        out: blackboard key written with the joint solution.
        position_tol_m, orientation_tol_rad: convergence tolerances.
    """

    def __init__(self, name: str, *, pose: str, out: str = "q_goal", position_tol_m: float = 1e-3,
                 orientation_tol_rad: float = 1e-2):
        super().__init__(name)
        self.pose_key, self.out = pose, out
        self.position_tol_m, self.orientation_tol_rad = float(position_tol_m), float(orientation_tol_rad)
        self.reads(pose)
        self.writes(out)

    def step(self):
        with self.ctx.profiler.section("ik"):
            sol, pairs, seed = clear_ik(self.ctx, self.get(self.pose_key), position_tol_m=self.position_tol_m,
                                        orientation_tol_rad=self.orientation_tol_rad)
        if seed != "current":
            self.ctx.trace.record("ik_reseeded", pose=self.pose_key, seed=seed, collides=[list(p) for p in pairs[:3]])
        self.set(self.out, sol.q)
        self.ctx.trace.record("ik", pose=self.pose_key, iterations=sol.iterations, position_error_m=float(sol.position_error_m))


class PlanPath(Primitive):
    """Collision-free joint path from the current configuration to blackboard ``goal``.

    Uses OMPL with MuJoCo collision checking; the held object (if any) is attached
    to the gripper so the transfer is checked with it.

    Args:
        goal: blackboard key of the goal configuration (7,) rad.
        out: blackboard key written with the (N, 7) path.
        planner: OMPL planner name (default from the session's motion settings).
        timeout_s: planning budget, s.

    The trace records ``plan`` {planner, waypoints, collision_at_goal, path_rad}; a start
    configuration that is itself invalid adds an entry with ``collision_at_start``, its
    ``colliding_pairs`` and ``start_contact`` (:func:`start_contact_kind`) before the
    planner refuses it:
    ``path_rad`` is the planned joint path, ``(M, 7)`` rad in the arm's joint order, at
    most :data:`MAX_TRACED_WAYPOINTS` waypoints (:func:`traced_path`), so the view can
    draw the plan next to what was executed.
    """

    def __init__(self, name: str, *, goal: str = "q_goal", out: str = "path", planner: str | None = None,
                 timeout_s: float | None = None):
        super().__init__(name)
        self.goal_key, self.out, self.planner, self.timeout_s = goal, out, planner, timeout_s
        self.reads(goal)
        self.writes(out)

    def step(self):
        ctx = self.ctx
        q0 = ctx.target.arm_qpos()
        with ctx.profiler.section("planning"):
            checker = session_checker(ctx, margin_m=PLANNING_MARGIN_M)
            # A start a hair outside the model's joint range (a third-party initial state)
            # is planned from its projection; the tracker accepts the gap (< 0.02 rad).
            clipped = np.clip(q0, *checker.joint_limits)
            q0 = np.where(np.abs(clipped - q0) < 0.02, clipped, q0)
            q_goal = np.asarray(self.get(self.goal_key), dtype=float)
            if not checker.is_valid(q0):
                pairs = checker.colliding_pairs(q0)
                ctx.trace.record("plan", planner=self.planner or ctx.motion.planner, waypoints=0,
                                 collision_at_goal=False, collision_at_start=True,
                                 start_contact=start_contact_kind(checker, pairs),
                                 colliding_pairs=[list(p) for p in pairs])
            if q_goal.shape == q0.shape and np.all(np.isfinite(q_goal)) and not checker.is_valid(q_goal):
                pairs = [list(p) for p in checker.colliding_pairs(q_goal)]
                ctx.trace.record("plan", planner=self.planner or ctx.motion.planner, waypoints=0,
                                 collision_at_goal=True, colliding_pairs=pairs)
            path = plan_path(checker, q0, self.get(self.goal_key), planner=self.planner or ctx.motion.planner,
                             timeout_s=self.timeout_s or ctx.motion.planning_timeout_s, seed=ctx.seed)
        self.set(self.out, path)
        ctx.trace.record("plan", planner=self.planner or ctx.motion.planner, waypoints=int(len(path)),
                         collision_at_goal=False, path_rad=traced_path(path))


class RetimePath(Primitive):
    """Time-optimal trajectory along blackboard ``path`` under velocity/acceleration limits and,
    where the target declares its arm's dynamics, within the actuators' torques (toppra).

    The timed trajectory is re-checked for collisions (toppra's spline can cut
    corners), with the held object attached.

    Args:
        path: blackboard key of the (N, 7) path.
        out: blackboard key written with the Trajectory.
        velocity_scale, acceleration_scale: fractions (0, 1] of the robot's limits.
    """

    def __init__(self, name: str, *, path: str = "path", out: str = "trajectory", velocity_scale: float | None = None,
                 acceleration_scale: float | None = None):
        super().__init__(name)
        for label, v in (("velocity_scale", velocity_scale), ("acceleration_scale", acceleration_scale)):
            if v is not None and not 0 < v <= 1:
                raise ValueError(f"{label} must be in (0, 1], got {v}")
        self.path_key, self.out = path, out
        self.velocity_scale, self.acceleration_scale = velocity_scale, acceleration_scale
        self.reads(path)
        self.writes(out)

    def step(self):
        ctx = self.ctx
        vel, acc = execution_limits(ctx, self.velocity_scale or ctx.motion.velocity_scale,
                                    self.acceleration_scale or ctx.motion.acceleration_scale)
        with ctx.profiler.section("timing"):
            checker = session_checker(ctx)
            traj = retime(np.asarray(self.get(self.path_key)), vel_limits=vel, acc_limits=acc,
                          dt=ctx.target.model.opt.timestep, checker=checker, dynamics=arm_dynamics_of(ctx.target))
        self.set(self.out, traj)
        ctx.trace.record("retime", duration_s=float(traj.duration), samples=int(len(traj.t)))
