"""Claim latency: a session submitted to an idle supervisor, until its claim is on disk.

    .venv/bin/python bench/supervisor_claim_latency.py [--sessions 150] [--seed 0]

A real ``phyagentos watch`` process watches a fresh workspace. The benchmark submits
one ``noop`` session at a time (through ``Workspace.submit_session``, after a random
pause so submissions do not line up with a polling period), starts the clock when
``submit_session`` returns, and stops it at the inotify wake-up (in the benchmark
process) after which the session file shows the session claimed: the claim is
durable then (the file is fsynced before it is renamed into place). It
waits for the session to finish before the next one, so the supervisor is idle at
every submit. Modes, side by side:

- ``inotify``: event-driven wake-up (the default), 1 s polling fallback;
- ``poll 50 ms`` and ``poll 500 ms``: ``--no-inotify`` with that polling period.

Goal: event-driven p50 <= 5 ms and p99 <= 50 ms. Writes bench/results/supervisor_claim_latency.json.
"""

from __future__ import annotations

import random
import sys
import tempfile
import time
from pathlib import Path

from _harness import parser, percentile, write_json
from _supervisor_common import make_workspace, start_watch, stop, submit

from phyagentos.protocol import WorkspaceWatcher
from phyagentos.protocol.codec import read_document
from phyagentos.protocol.schemas import SessionRecord

MODES = {"inotify": (), "poll 50 ms": ("--no-inotify", "--poll-s", "0.05"),
         "poll 500 ms": ("--no-inotify", "--poll-s", "0.5")}


def state_of(path: Path) -> str | None:
    try:
        return read_document(path, SessionRecord).data.state
    except (FileNotFoundError, ValueError):
        return None


def measure(mode_args: tuple[str, ...], sessions: int, rng: random.Random) -> list[float]:
    with tempfile.TemporaryDirectory() as tmp:
        ws = make_workspace(Path(tmp) / "ws")
        watcher = WorkspaceWatcher(ws.root, dirs=("sessions",))
        sup = start_watch(ws, "--lease-s", "30", *mode_args)
        latencies = []
        try:
            for i in range(-3, sessions):  # three warm-up sessions (runner start-up, first scene)
                time.sleep(rng.uniform(0.01, 0.1))
                sid = f"s{i + 3:04d}"
                path = ws.session_path(sid)
                watcher.clear()
                submit(ws, sid)
                t0 = time.perf_counter()
                while True:
                    watcher.wait(0.2)
                    woke = time.perf_counter()  # the claim was visible by now (checked next)
                    watcher.clear()
                    state = state_of(path)
                    if state not in (None, "pending"):
                        break
                if i >= 0:
                    latencies.append(woke - t0)
                deadline = time.monotonic() + 60
                while ws.load_session(sid).state != "awaiting_verification":
                    if time.monotonic() > deadline:
                        raise RuntimeError(f"session {sid} did not finish")
                    watcher.wait(0.05)
                    watcher.clear()
        finally:
            stop(sup)
            watcher.close()
    return latencies


def main() -> int:
    ap = parser(__doc__, "supervisor_claim_latency")
    ap.add_argument("--sessions", type=int, default=150)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = random.Random(args.seed)
    rows = {}
    print(f"{'mode':12s} {'sessions':>8s} {'p50 ms':>8s} {'p90 ms':>8s} {'p99 ms':>8s} {'max ms':>8s}")
    for name, mode_args in MODES.items():
        lat = measure(mode_args, args.sessions, rng)
        ms = [1e3 * x for x in lat]
        rows[name] = {"sessions": len(ms), "p50_ms": percentile(ms, 50), "p90_ms": percentile(ms, 90),
                      "p99_ms": percentile(ms, 99), "max_ms": max(ms)}
        r = rows[name]
        print(f"{name:12s} {r['sessions']:8d} {r['p50_ms']:8.2f} {r['p90_ms']:8.2f} {r['p99_ms']:8.2f} {r['max_ms']:8.2f}")
    ok = rows["inotify"]["p50_ms"] <= 5.0 and rows["inotify"]["p99_ms"] <= 50.0
    print(f"goal (inotify p50 <= 5 ms, p99 <= 50 ms): {'met' if ok else 'MISSED'}")
    write_json(args.out, {"modes": rows, "goal_met": ok, "sessions": args.sessions, "seed": args.seed})
    return 0


if __name__ == "__main__":
    sys.exit(main())
