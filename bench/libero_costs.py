"""LIBERO target costs: world build, reset, a control step with and without rendering, a camera capture, memory.

    .venv/bin/python bench/libero_costs.py [--suite libero_object] [--task 0] [--steps 200] [--out bench/results/libero_costs.json]

Measured on one LIBERO world (``LiberoTarget``, driver ``libero``):

- ``build_s``: constructing the target (LIBERO's ControlEnv, the XML recompile with the tool
  site and gravity-compensation attributes, the first reset);
- ``reset_s``: ``reset(seed=k)`` (``env.reset`` with ``hard_reset=False``, ``set_init_state``,
  LIBERO's 10 settle steps) over the init states 1..5;
- ``servo_control_step_ms``: one 20 Hz control period (25 physics steps of 2 ms) of the
  target's joint servos, as skills stream trajectories: nothing is rendered;
- ``liberos_osc_step_ms``: one ``env.step`` of LIBERO's own OSC_POSE controller (the
  do-nothing action), no cameras, for comparison (the settle steps use it);
- ``capture_ms``: ``capture(sensor)`` per camera (256x256 RGB-D, rendered on demand),
  the first (GL context and texture upload) and the median of the next five;
- ``rss_mb``: peak resident memory of the process.

Prints a table and writes the JSON.
"""

from __future__ import annotations

import resource
import statistics
import sys
import time

import numpy as np
from _harness import parser, write_json

from phyagentos.targets.libero import LiberoScene, LiberoTarget


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_costs")
    ap.add_argument("--suite", default="libero_object")
    ap.add_argument("--task", type=int, default=0)
    ap.add_argument("--steps", type=int, default=200, help="control periods timed per controller")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    target = LiberoTarget("libero", LiberoScene(suite=args.suite, task=args.task), seed=0)
    build_s = time.perf_counter() - t0
    resets = []
    for k in range(1, 6):
        t0 = time.perf_counter()
        target.reset(seed=k)
        resets.append(time.perf_counter() - t0)
    q = target.arm_qpos()
    t0 = time.perf_counter()
    for _ in range(args.steps):
        for _ in range(25):
            target.step(q)
    servo_ms = 1000.0 * (time.perf_counter() - t0) / args.steps
    # LIBERO's own controller: switch the arm back to its torque motors for the comparison
    target._servo(target.model, False)
    env = target.env
    noop = np.array([0.0] * 6 + [-1.0])
    t0 = time.perf_counter()
    for _ in range(args.steps):
        env.step(noop)
    osc_ms = 1000.0 * (time.perf_counter() - t0) / args.steps
    target._servo(target.model, True)
    target.reset(seed=0)
    captures = {}
    for sensor in target.camera_names():
        times = []
        for _ in range(6):
            t0 = time.perf_counter()
            target.capture(sensor)
            times.append(1000.0 * (time.perf_counter() - t0))
        captures[sensor] = {"first_ms": round(times[0], 1), "median_ms": round(statistics.median(times[1:]), 1)}
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    target.close()
    result = {"benchmark": "libero_costs", "suite": args.suite, "task": args.task, "build_s": round(build_s, 2),
              "reset_s": {"median": round(statistics.median(resets), 3), "max": round(max(resets), 3)},
              "servo_control_step_ms": round(servo_ms, 2), "liberos_osc_step_ms": round(osc_ms, 2),
              "capture_ms": captures, "rss_mb": round(rss_mb)}
    print(f"LIBERO {args.suite} task {args.task}: build {result['build_s']} s, reset median "
          f"{result['reset_s']['median']} s (max {result['reset_s']['max']} s)")
    print(f"control period (20 Hz): servo {servo_ms:.2f} ms, LIBERO's OSC env.step {osc_ms:.2f} ms (no rendering)")
    for sensor, c in captures.items():
        print(f"capture {sensor}: first {c['first_ms']} ms, then median {c['median_ms']} ms")
    print(f"peak RSS {result['rss_mb']} MB")
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
