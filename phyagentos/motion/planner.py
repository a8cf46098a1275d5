"""Collision-free joint-space paths with OMPL (official OMPL 2 nanobind bindings).

The state space is ``RealVectorStateSpace(7)`` bounded by the model's joint ranges; state
validity comes from a :class:`~phyagentos.motion.collision.CollisionChecker`, and motions
are checked by OMPL's discrete motion validator at ``resolution_rad`` (joint-space
Euclidean distance). Solutions are shortcut with OMPL's path simplifier (rope shortcutting) and then
subdivided so no segment is longer than ``max_segment_rad`` in any joint, which gives the
time parameterisation enough knots to stay close to the straight segments.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Sequence

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou

from phyagentos.errors import PlanningError, format_choices

from .collision import CollisionChecker

__all__ = ["plan_path", "PLANNERS", "last_plan_stats"]

log = logging.getLogger(__name__)

#: Planner names accepted by :func:`plan_path`.
PLANNERS: tuple[str, ...] = ("RRTConnect", "RRTstar", "PRM", "KPIECE1", "BITstar")
_OPTIMIZING = frozenset({"RRTstar", "PRM", "BITstar"})

_last_stats: dict = {}


def last_plan_stats() -> dict:
    """Statistics of the last :func:`plan_path` call: planner, solve_s, simplify_s,
    validity checks, states before/after simplification."""
    return dict(_last_stats)


def _always_valid(state) -> bool:
    return True


def _make_planner(name: str, si):
    return getattr(og, name)(si)


def plan_path(
    checker: CollisionChecker,
    q_start: Sequence[float],
    q_goal: Sequence[float],
    *,
    planner: str = "RRTConnect",
    timeout_s: float = 2.0,
    seed: int | None = None,
    simplify: bool = True,
    resolution_rad: float = 0.02,
    max_segment_rad: float = 0.25,
    max_simplify_passes: int = 3,
    optimize: bool = False,
) -> np.ndarray:
    """A collision-free piecewise-linear joint path from ``q_start`` to ``q_goal``.

    Args:
        checker: validity checker, already synchronised with the world
            (:meth:`CollisionChecker.set_world_state`, :meth:`~CollisionChecker.attach`).
        q_start, q_goal: ``(7,)`` rad.
        planner: one of :data:`PLANNERS`.
        timeout_s: planning time budget in seconds.
        seed: seeds OMPL's random generator (``ompl.util.RNG.setSeed``) so the same
            problem gives the same path; ``None`` leaves it random.
        simplify: shortcut the solution with OMPL's PathSimplifier (rope shortcutting).
        resolution_rad: motion checking resolution (joint-space distance, rad).
        max_segment_rad: after simplification segments are subdivided so no joint moves
            more than this between consecutive waypoints.
        max_simplify_passes: at most this many rope-shortcut passes (each stops the
            loop unless it shortened the path by more than 1 %).
        optimize: for the asymptotically optimal planners (RRTstar, PRM, BITstar) keep
            improving until ``timeout_s``; by default they stop at the first solution.

    Returns:
        ``(N, 7)`` waypoints in rad, ``N >= 2``, first row ``q_start``, last ``q_goal``.

    Raises:
        PlanningError: unknown planner (lists the valid ones), start or goal invalid
            (names the colliding pair or joint limit), or no exact solution in time.
    """
    if planner not in PLANNERS:
        raise PlanningError(f"unknown planner {planner!r}; valid planners: {format_choices(PLANNERS)}")
    n = len(checker.arm_joint_names)
    qs = np.asarray(q_start, dtype=float).reshape(-1)
    qg = np.asarray(q_goal, dtype=float).reshape(-1)
    for what, q in (("start", qs), ("goal", qg)):
        if q.shape != (n,) or not np.all(np.isfinite(q)):
            raise PlanningError(f"q_{what} must be a finite ({n},) vector, got shape {q.shape}")
    if timeout_s <= 0:
        raise PlanningError(f"timeout_s must be > 0, got {timeout_s}")
    for what, q in (("start", qs), ("goal", qg)):
        if not checker.is_valid(q):
            pairs = checker.colliding_pairs(q)
            desc = ", ".join(f"{a} <-> {b}" for a, b in pairs) or "unknown"
            raise PlanningError(f"{what} configuration is invalid: {desc} (q_{what}={np.round(q, 3).tolist()})")

    prev_level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        return _plan(checker, qs, qg, planner, timeout_s, seed, simplify, resolution_rad, max_segment_rad,
                     max_simplify_passes, optimize)
    finally:
        ou.setLogLevel(prev_level)


def _plan(checker, qs, qg, planner, timeout_s, seed, simplify, resolution_rad, max_segment_rad,
          max_simplify_passes, optimize) -> np.ndarray:
    n = len(qs)
    if seed is not None:
        # OMPL ignores a zero seed; map every int to a positive 32-bit seed.
        ou.RNG.setSeed(int(seed) % 2_147_483_646 + 1)
    space = ob.RealVectorStateSpace(n)
    bounds = ob.RealVectorBounds(n)
    lower, upper = checker.joint_limits
    for i in range(n):
        bounds.setLow(i, float(lower[i]))
        bounds.setHigh(i, float(upper[i]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    checks = [0]

    valid_in_bounds = checker.is_valid_within_limits

    def is_valid(state) -> bool:
        # OMPL only produces states inside the joint bounds of the state space.
        checks[0] += 1
        return valid_in_bounds(np.array(state[0:n]))

    si.setStateValidityChecker(is_valid)
    try:
        si.setStateValidityCheckingResolution(resolution_rad / space.getMaximumExtent())
        si.setup()
        ss = og.SimpleSetup(si)
        start = space.allocState()
        goal = space.allocState()
        for i in range(n):
            start[i] = float(qs[i])
            goal[i] = float(qg[i])
        ss.setStartAndGoalStates(start, goal)
        if planner in _OPTIMIZING:
            obj = ob.PathLengthOptimizationObjective(si)
            if not optimize:
                obj.setCostThreshold(ob.Cost(1e12))  # any solution is good enough
            ss.setOptimizationObjective(obj)
        ss.setPlanner(_make_planner(planner, si))
        ss.setup()
        t0 = time.perf_counter()
        status = ss.solve(float(timeout_s))
        solve_s = time.perf_counter() - t0
        if not ss.haveExactSolutionPath():
            raise PlanningError(
                f"{planner} found no collision-free path in {solve_s:.2f} s (budget {timeout_s} s, "
                f"status {status.asString()}); start {np.round(qs, 3).tolist()}, goal {np.round(qg, 3).tolist()}"
            )
        path = ss.getSolutionPath()
        n_raw = path.getStateCount()
        length_raw = path.length()
        t1 = time.perf_counter()
        if simplify:
            # Rope shortcutting (OMPL 2) gets most of simplifyMax's shortening at a
            # fraction of its validity checks; repeat while it still helps.
            ps = og.PathSimplifier(si)
            for _ in range(max_simplify_passes):
                before = path.length()
                ps.ropeShortcutPath(path)
                if path.length() > 0.99 * before:
                    break
        simplify_s = time.perf_counter() - t1
        P = np.array([[path.getState(k)[i] for i in range(n)] for k in range(path.getStateCount())])
        P[0], P[-1] = qs, qg
        P = _dedupe(P)
        P = _subdivide(P, max_segment_rad)
        _last_stats.clear()
        _last_stats.update(
            planner=planner,
            solve_s=solve_s,
            simplify_s=simplify_s,
            validity_checks=checks[0],
            states_raw=n_raw,
            length_raw_rad=length_raw,
            length_rad=float(np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1))),
            states_final=len(P),
        )
        return P
    finally:
        # Drop the C++ side's reference to the Python callback (and the checker).
        si.setStateValidityChecker(_always_valid)


def _dedupe(P: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    keep = [0]
    for k in range(1, len(P)):
        if np.max(np.abs(P[k] - P[keep[-1]])) > eps:
            keep.append(k)
    if len(keep) == 1:
        keep.append(len(P) - 1)
    return P[keep]


def _subdivide(P: np.ndarray, max_segment_rad: float) -> np.ndarray:
    if max_segment_rad <= 0:
        return P
    out = [P[0]]
    for a, b in zip(P[:-1], P[1:]):
        k = max(1, int(math.ceil(float(np.max(np.abs(b - a))) / max_segment_rad)))
        for j in range(1, k + 1):
            out.append(a + (b - a) * (j / k))
    return np.array(out)
