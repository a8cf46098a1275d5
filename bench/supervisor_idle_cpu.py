"""CPU used by an idle supervisor: a ``phyagentos watch`` process with nothing to do.

    .venv/bin/python bench/supervisor_idle_cpu.py [--seconds 60]

Starts ``phyagentos watch`` on an empty workspace, waits until it is up (its runner
process and forkserver started), then reads utime + stime of the supervisor and all
its descendants from /proc at the start and the end of ``--seconds`` seconds, in both
wake-up modes (inotify with the 1 s polling fallback, and pure 1 s polling). Idle
work is a maintenance pass per second (expired leases, queue timeouts: an empty
directory scan) and the inotify thread, which sleeps in ``read``.

Goal: under 1 % of one core. Writes bench/results/supervisor_idle_cpu.json.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from _harness import parser, write_json
from _supervisor_common import cpu_seconds, descendants, make_workspace, start_watch, stop

MODES = {"inotify": (), "polling 1 s": ("--no-inotify",)}


def idle_cpu(mode_args: tuple[str, ...], seconds: float) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        ws = make_workspace(Path(tmp) / "ws")
        sup = start_watch(ws, *mode_args)
        try:
            time.sleep(5.0)  # runner and forkserver finish starting
            pids = [sup.pid, *descendants(sup.pid)]
            before = sum(cpu_seconds(p) for p in pids)
            t0 = time.monotonic()
            time.sleep(seconds)
            used = sum(cpu_seconds(p) for p in pids) - before
            wall = time.monotonic() - t0
        finally:
            stop(sup)
    return {"processes": len(pids), "cpu_s": used, "wall_s": wall, "percent_of_core": 100.0 * used / wall}


def main() -> int:
    ap = parser(__doc__, "supervisor_idle_cpu")
    ap.add_argument("--seconds", type=float, default=60.0)
    args = ap.parse_args()
    rows = {}
    print(f"{'mode':12s} {'processes':>9s} {'cpu s':>7s} {'wall s':>7s} {'% core':>7s}")
    for name, mode_args in MODES.items():
        r = rows[name] = idle_cpu(mode_args, args.seconds)
        print(f"{name:12s} {r['processes']:9d} {r['cpu_s']:7.3f} {r['wall_s']:7.1f} {r['percent_of_core']:7.3f}")
    ok = all(r["percent_of_core"] < 1.0 for r in rows.values())
    print(f"goal (< 1 % of a core): {'met' if ok else 'MISSED'}")
    write_json(args.out, {"modes": rows, "goal_met": ok, "seconds": args.seconds})
    return 0


if __name__ == "__main__":
    sys.exit(main())
