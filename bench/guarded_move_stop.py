"""How late ``guarded_move`` stops after its force limit, and what the per-step check costs.

    .venv/bin/python bench/guarded_move_stop.py [--repeat 3] [--limit-n 15] [--velocity-scale 0.3]

The closed Franka hand is moved above the default scene's cube, then a ``guarded_move``
presses down toward 1 cm below the cube's top face with ``max_contact_force_n``. Two
ways of checking the limit are compared on the same motion:

- ``per physics step``: the primitive as shipped (the force is measured after every
  physics step; it stops at the first step the limit is reached);
- ``per control period``: the same primitive streaming a whole control period
  (``control_period_s``, 0.1 s = 50 steps) between checks, as it did before.

Reported (medians over ``--repeat``): simulated time from the start of the press to the
stop, the contact force when it stopped (N), physics steps streamed after the first step
at or over the limit (recorded by wrapping ``track``), and wall time of the press. The
machine may be shared: compare the two rows, not absolute wall times. Writes
bench/results/guarded_move_stop.json.
"""

from __future__ import annotations

import statistics
import time

import py_trees
from _harness import parser as bench_parser
from _harness import write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.primitives import SkillContext
from phyagentos.primitives.contact import GuardedMove, _Slice, contact_force_n
from phyagentos.targets import MuJoCoTarget, SceneSpec


class PerPeriodGuardedMove(GuardedMove):
    """The baseline: one ``track`` call (a whole control period) between force checks."""

    def _stream(self, over_limit):
        ctx, target = self.ctx, self.ctx.target
        t_end = min(self._t + ctx.motion.control_period_s, self._traj.duration)
        result = target.track(self._traj, t_start=self._t, t_end=t_end, tracking_tol_rad=self.tracking_tol_rad)
        self._t = t_end
        force, touched = contact_force_n(target.model, target.data, ignore_bodies=self._ignore)
        stopped = over_limit(force)
        return _Slice(result.completed, result.max_tracking_error_rad, force, touched, stopped)


def _tick(leaf, ctx) -> None:
    py_trees.blackboard.Blackboard.clear()
    leaf.setup(context=ctx)
    for _ in range(5000):
        leaf.tick_once()
        if leaf.status != py_trees.common.Status.RUNNING:
            return
    raise RuntimeError("leaf never finished")


def press(cls, *, limit_n: float, velocity_scale: float) -> dict:
    target = MuJoCoTarget("bench", SceneSpec.default(), seed=0)
    try:
        ctx = SkillContext(target=target)
        target.set_gripper(opening_m=0.0)
        cube = target.object_pose("cube")[:3, 3]
        T = target.tcp_pose()
        _tick(GuardedMove("Over", offset=[cube[0] - T[0, 3], cube[1] - T[1, 3], 0.0], velocity_scale=0.5,
                          expect_contact=False), ctx)
        samples = []  # (steps, force after the call)
        track = target.track

        def recording(traj, **kw):
            result = track(traj, **kw)
            samples.append((result.steps, contact_force_n(target.model, target.data)[0]))
            return result

        target.track = recording
        t0, w0 = target.data.time, time.perf_counter()
        leaf = cls("Press", offset=[0.0, 0.0, cube[2] + 0.02 - 0.03 - T[2, 3]], velocity_scale=velocity_scale,
                   max_contact_force_n=limit_n, tracking_tol_rad=0.5)
        _tick(leaf, ctx)
        wall = time.perf_counter() - w0
        reader = py_trees.blackboard.Client(name="bench")
        reader.register_key(key="contact", access=py_trees.common.Access.READ)
        # steps streamed after the first step at or over the limit: within a call that
        # crossed it, the steps after the crossing are not observable here, so a
        # per-period call that crossed counts its own steps minus one (a lower bound)
        first = next((i for i, (_, f) in enumerate(samples) if f >= limit_n), None)
        late = 0 if first is None else sum(s for s, _ in samples[first + 1:]) + max(0, samples[first][0] - 1)
        return {"sim_s": target.data.time - t0, "force_n": float(reader.contact["force_n"]), "steps_after_limit": late,
                "wall_s": wall}
    finally:
        target.close()


def main() -> None:
    parser = bench_parser(__doc__, "guarded_move_stop")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--limit-n", type=float, default=15.0)
    parser.add_argument("--velocity-scale", type=float, default=0.3)
    args = parser.parse_args()
    rows = {}
    for name, cls in (("per physics step", GuardedMove), ("per control period", PerPeriodGuardedMove)):
        runs = [press(cls, limit_n=args.limit_n, velocity_scale=args.velocity_scale) for _ in range(args.repeat)]
        rows[name] = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    print(f"guarded_move pressing on the cube, limit {args.limit_n} N, velocity_scale {args.velocity_scale}, "
          f"median of {args.repeat}")
    print(f"{'check':<20} {'sim to stop s':>14} {'force at stop N':>16} {'steps after limit':>18} {'wall s':>8}")
    for name, r in rows.items():
        print(f"{name:<20} {r['sim_s']:>14.3f} {r['force_n']:>16.1f} {r['steps_after_limit']:>18.0f} {r['wall_s']:>8.3f}")
    write_json(args.out, {"limit_n": args.limit_n, "velocity_scale": args.velocity_scale,
                          "repeat": args.repeat, "rows": rows})


if __name__ == "__main__":
    main()
