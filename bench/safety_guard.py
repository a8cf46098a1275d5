"""SafetyGuard cost per action for the 7-DOF Franka (+ gripper column).

    .venv/bin/python bench/safety_guard.py [--repeat 7] [--number 2000]

Times ``SafetyGuard.check`` on admissible commands (the path every command takes):
a single action, a 50-step chunk (a policy chunk at the model rate) and a 500-step
chunk (one second of control at 500 Hz), plus a 50-step chunk that violates a joint
limit (the diagnosis path that builds the events). Every check includes dtype/shape,
NaN/inf, rate, duration, joint limits, velocity, acceleration and the workspace box
through forward kinematics of the tcp. Reported: the best of ``--repeat`` timings of
``--number`` calls (timeit's convention; the minimum is the least disturbed by the
other processes on the machine), as us per call and us per action. Goal: under 20 us
per action. Writes bench/results/safety_guard.json.
"""

from __future__ import annotations

import logging
import timeit

import numpy as np
from _harness import parser, write_json

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.protocol.schemas import SafetyConfig
from phyagentos.runtime.safety_guard import EStopLatch, SafetyGuard
from phyagentos.targets import MuJoCoTarget, SceneSpec

GOAL_US_PER_ACTION = 20.0


def chunk(q0: np.ndarray, n: int, delta: float) -> np.ndarray:
    s = np.linspace(0, 1, n + 1)[1:]
    q = q0 + np.outer(delta * (3 * s**2 - 2 * s**3), np.ones(7))
    return np.hstack([q, np.full((n, 1), 0.04)])


def main() -> int:
    ap = parser(__doc__, "safety_guard")
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--number", type=int, default=2000)
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # the violating case logs every intervention
    target = MuJoCoTarget("bench", SceneSpec())
    guard = SafetyGuard.for_target(target, SafetyConfig(), events=[], estop=EStopLatch())
    q0 = target.home_qpos
    cases = {
        "single action": (np.hstack([q0 + 1e-4, [0.04]])[None, :], 0.01),
        "50-step chunk": (chunk(q0, 50, 0.02), 0.02),
        "500-step chunk": (chunk(q0, 500, 0.05), 0.002),
    }
    bad = chunk(q0, 50, 0.02)
    bad[25:, 6] = 3.0
    rows = []
    for name, (a, dt) in {**cases, "50-step chunk, violating": (bad, 0.02)}.items():
        outcome = guard.check(a, dt=dt).outcome
        guard.events.clear()
        assert outcome == ("halt" if "violating" in name else "pass"), (name, outcome)
        best = min(timeit.repeat(lambda: guard.check(a, dt=dt), number=args.number, repeat=args.repeat)) / args.number
        guard.events.clear()
        rows.append({"case": name, "actions": len(a), "us_per_call": round(best * 1e6, 2),
                     "us_per_action": round(best * 1e6 / len(a), 3), "outcome": outcome})
    print(f"{'case':28s} {'actions':>7s} {'us/call':>9s} {'us/action':>10s}")
    for r in rows:
        print(f"{r['case']:28s} {r['actions']:7d} {r['us_per_call']:9.1f} {r['us_per_action']:10.2f}")
    worst = max(r["us_per_action"] for r in rows if "violating" not in r["case"])
    ok = worst < GOAL_US_PER_ACTION
    print(f"goal < {GOAL_US_PER_ACTION} us per action on the admissible path: {'met' if ok else 'MISSED'} (worst {worst:.2f})")
    write_json(args.out, {"rows": rows, "goal_us_per_action": GOAL_US_PER_ACTION, "worst_us_per_action": worst,
                          "goal_met": ok, "repeat": args.repeat, "number": args.number})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
