"""A hand-off split into its stages, from the sessions' own transitions, pooled over runs.

    .venv/bin/python bench/handoff_stages.py [--runs 2] [--holds 20] [--cameras] [--graph G.yaml]

Runs ``phyagentos run`` ``--runs`` times (a chain of ``--holds`` 0 s ``hold`` sessions,
or ``--graph``; without cameras unless ``--cameras``) and splits every hand-off (a
session's verdict to the next session's first actuation, as ``bench/end_to_end.py``
measures it) at the timestamps the protocol already records, untraced:

- ``agent``: the dependency's verdict -> the next session's ``created_at`` (verification
  write and archive, memory consolidation, context, compile),
- ``submit_to_claim``: ``created_at`` -> its ``claim`` transition (the submit write, the
  supervisor's wake-up, the target reservation),
- ``claim_to_start``: ``claim`` -> ``start`` (the runner's preflight),
- ``start_to_first_tick``: ``start`` -> ``actuation_started_at`` (``go``, its writes, the
  tree's build and setup),
- ``total``.

Prints the median of each over the pooled hand-offs of all runs and writes
``bench/results/handoff_stages.json``. Where ``bench/handoff_budget.py`` traces one run
function by function, this one measures without any wrapping; compare versions by
alternating them (docs/PERFORMANCE.md round 14).
"""

from __future__ import annotations

import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from _harness import parser, write_json
from end_to_end import NO_CAMERA_SENSORS, PHYAGENTOS, hold_chain, session_timeline

HERE = Path(__file__).resolve().parent

STAGES = ("agent", "submit_to_claim", "claim_to_start", "start_to_first_tick", "total")


def stages(rows: list[dict]) -> list[dict[str, float]]:
    """Each hand-off of one run's timeline (:func:`session_timeline`) split into
    :data:`STAGES` (ms); a session waiting on several dependencies is timed from the last
    verdict among them."""
    by_node: dict[str, list[dict]] = {}
    for r in rows:
        by_node.setdefault(r["node"], []).append(r)
    out = []
    for r in rows:
        verdicts = [d["verdict"] for n in r["depends_on"] for d in by_node.get(n, []) if d["verdict"]]
        marks = (max(verdicts, default=None), r["created"], r["claim"], r["start"], r["actuation_started"])
        if any(m is None for m in marks) or marks[-1] < marks[0]:
            continue
        spans = [1e3 * (b - a) for a, b in zip(marks, marks[1:])]
        out.append(dict(zip(STAGES, [*spans, 1e3 * (marks[-1] - marks[0])])))
    return out


def main(argv=None) -> int:
    import yaml  # noqa: PLC0415

    ap = parser(__doc__, "handoff_stages")
    ap.add_argument("--runs", type=int, default=2, help="runs whose hand-offs are pooled (default 2)")
    ap.add_argument("--holds", type=int, default=20, help="length of the hold chain (default 20)")
    ap.add_argument("--graph", type=Path, help="a goal graph to run instead of the hold chain")
    ap.add_argument("--cameras", action="store_true", help="keep the target's cameras")
    args = ap.parse_args(argv)
    pooled: list[dict[str, float]] = []
    for i in range(args.runs):
        tmp = Path(tempfile.mkdtemp(prefix="phyagentos-handoff-stages-"))
        try:
            ws = tmp / "ws"
            ws.mkdir()
            if not args.cameras:
                (ws / "sensors.yaml").write_text(yaml.safe_dump(NO_CAMERA_SENSORS))
            graph = args.graph.resolve() if args.graph else hold_chain(tmp / "hold_chain.yaml", args.holds)
            proc = subprocess.run([*PHYAGENTOS, "run", str(graph), "--workspace", str(ws), "--json"],
                                  capture_output=True, text=True, cwd=HERE.parent)
            if proc.returncode != 0:
                print(proc.stderr[-3000:], file=sys.stderr)
                return proc.returncode
            found = stages(session_timeline(ws))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        print(f"run {i + 1}/{args.runs}: {len(found)} hand-offs", flush=True)
        pooled += found
    if not pooled:
        print("no hand-off: the graph has no session that waited for another", file=sys.stderr)
        return 1
    medians = {s: round(statistics.median(h[s] for h in pooled), 2) for s in STAGES}
    print(f"\n{'stage':<22}{'p50 ms':>9}")
    for s in STAGES:
        print(f"{s:<22}{medians[s]:>9.1f}")
    print(f"({len(pooled)} hand-offs)")
    result = {"graph": str(args.graph) if args.graph else f"{args.holds} holds", "cameras": args.cameras,
              "runs": args.runs, "hand_offs": len(pooled), "p50_ms": medians}
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
