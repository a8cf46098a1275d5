"""Does a hand-off get slower the longer a run is? One long hold chain, split in quarters.

    .venv/bin/python bench/run_length.py [--holds 200] [--cameras]

Runs ``phyagentos run`` of a chain of ``--holds`` 0 s ``hold`` sessions (without cameras
unless ``--cameras``) as one process tree, then splits the chain into four quarters in
order and reports, per quarter, the hand-off (a session's verdict to the next session's
first actuation, as ``bench/end_to_end.py`` measures it) p50 and p99 in ms and the
sessions per second (first actuation of the quarter's first session to the verdict of
its last). A step lists the run's sessions and derives the DAG's node states, so every
per-session cost that grows with the run's length shows up as a last quarter slower than
the first; ``last_over_first`` is the ratio of their hand-off p50s (1.0: no growth).
Writes ``bench/results/run_length.json``.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _harness import parser, write_json
from end_to_end import NO_CAMERA_SENSORS, PHYAGENTOS, hold_chain, session_timeline

HERE = Path(__file__).resolve().parent


def quarters(rows: list[dict]) -> list[dict]:
    """Hand-off p50/p99 (ms) and sessions/s of each quarter of a chain's sessions."""
    by_node = {r["node"]: r for r in rows}
    chain = [r for r in rows if r["actuation_started"] is not None and r["verdict"] is not None]
    out = []
    k = len(chain) // 4
    for q in range(4):
        part = chain[q * k:(q + 1) * k] if q < 3 else chain[3 * k:]
        hand = [1000 * (r["actuation_started"] - by_node[r["depends_on"][0]]["verdict"]) for r in part
                if r["depends_on"] and by_node.get(r["depends_on"][0], {}).get("verdict") is not None]
        span = part[-1]["verdict"] - part[0]["actuation_started"]
        out.append({"sessions": len(part), "hand_off_p50_ms": round(statistics.median(hand), 2),
                    "hand_off_p99_ms": round(statistics.quantiles(hand, n=100)[98] if len(hand) > 1 else hand[0], 2),
                    "sessions_per_s": round(len(part) / span, 2) if span > 0 else None})
    return out


def main(argv=None) -> int:
    import yaml  # noqa: PLC0415

    ap = parser(__doc__, "run_length")
    ap.add_argument("--holds", type=int, default=200, help="length of the hold chain (default 200; at least 12)")
    ap.add_argument("--cameras", action="store_true", help="keep the target's cameras (perceive around each hold)")
    args = ap.parse_args(argv)
    if args.holds < 12:
        ap.error(f"--holds {args.holds}: a chain of at least 12 sessions is needed (three per quarter)")
    tmp = Path(tempfile.mkdtemp(prefix="phyagentos-run-length-"))
    try:
        ws = tmp / "ws"
        ws.mkdir()
        if not args.cameras:
            (ws / "sensors.yaml").write_text(yaml.safe_dump(NO_CAMERA_SENSORS))
        graph = hold_chain(tmp / "hold_chain.yaml", args.holds)
        print(f"running a chain of {args.holds} holds ...", flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run([*PHYAGENTOS, "run", str(graph), "--workspace", str(ws), "--json"], capture_output=True,
                              text=True, cwd=HERE.parent)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            print(proc.stderr[-3000:], file=sys.stderr)
            return proc.returncode
        parts = quarters(session_timeline(ws))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    result = {"holds": args.holds, "cameras": args.cameras, "wall_s": round(wall, 2), "cpu_count": os.cpu_count(),
              "quarters": parts,
              "last_over_first": round(parts[3]["hand_off_p50_ms"] / parts[0]["hand_off_p50_ms"], 3)}
    print(f"\n{'quarter':>8} {'sessions':>9} {'hand-off p50 ms':>16} {'p99 ms':>8} {'sessions/s':>11}")
    for i, p in enumerate(parts):
        print(f"{i + 1:>8} {p['sessions']:>9} {p['hand_off_p50_ms']:>16.1f} {p['hand_off_p99_ms']:>8.1f} "
              f"{p['sessions_per_s'] or float('nan'):>11.2f}")
    print(f"last quarter over first (hand-off p50): {result['last_over_first']:.2f}; whole run {wall:.1f} s")
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
