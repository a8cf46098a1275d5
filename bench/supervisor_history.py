"""Does the cost of a session transition grow with history? 100 vs 10,000 finished sessions.

    .venv/bin/python bench/supervisor_history.py [--small 100] [--large 10000] [--reps 40]

Two workspaces get ``--small`` and ``--large`` sessions of history: each a real
session submitted and ended (``cancel`` -> ``cancelled``), hence archived, spread over
runs of 50 sessions. Then, in each, a fresh run measures (medians over ``--reps``):

- ``submit``: ``Workspace.submit_session`` of a new pending session;
- ``transition``: one fenced ``update_session`` firing a lifecycle event (session file,
  state hint and SESSIONS.md, fsynced);
- ``claimable``: listing the pending sessions (what a supervisor does on every wake-up);
- ``run sessions``: ``list_sessions(run_id=...)`` of the new run (the Agent's query);
- ``load archived``: loading a finished session by id (verifier lineage);
- ``full lifecycle``: claim, preflight, start, finish, submit, verify, succeed.

Goal: large/small ratio <= 1.5 for every operation. History is built with the normal
API, but with the SESSIONS.md view and fsyncs of the history itself switched off to
keep set-up short; measurements use the normal, durable path.
Writes bench/results/supervisor_history.json.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

from _harness import parser, write_json
from _supervisor_common import submit

from phyagentos.protocol import Workspace, new_lease
from phyagentos.protocol.lifecycle import SessionLifecycle

LIFECYCLE = ("claim", "preflight", "start", "finish", "submit", "verify", "succeed")


def build_history(ws: Workspace, n: int) -> None:
    ws._index_upsert = lambda record: None  # the view is bounded anyway; skipping it only speeds set-up
    import phyagentos.protocol.workspace.sessions as wsmod  # where session files are written

    write = wsmod.write_document
    wsmod.write_document = lambda doc, path=None, durable=True, **kw: write(doc, path, durable=False, **kw)
    try:
        for i in range(n):
            sid = f"h{i:05d}"
            submit(ws, sid, run_id=f"hist-{i // 50:04d}")
            ws.update_session(sid, lambda r: (SessionLifecycle(r).fire("cancel"), SessionLifecycle(r).fire("cancelled")) and None)
    finally:
        wsmod.write_document = write
        del ws._index_upsert
    ws.rebuild_index()


class Probe:
    """The measured operations on one workspace (each call is one sample)."""

    def __init__(self, ws: Workspace) -> None:
        self.ws = ws
        self.counter = iter(range(10**6))
        self.archived = iter(f"h{i:05d}" for i in range(10**6))
        self.lease = new_lease("bench", ttl_s=3600)
        self.to_claim: list[str] = []

    def submit(self):
        sid = f"m{next(self.counter):06d}"
        submit(self.ws, sid, run_id="now")
        self.to_claim.append(sid)

    def transition(self):
        def fn(r):
            r.lease = self.lease
            SessionLifecycle(r).fire("claim")

        self.ws.update_session(self.to_claim.pop(0), fn)

    def claimable(self):
        self.ws.active_sessions("pending")

    def run_sessions(self):
        self.ws.list_sessions(run_id="now")

    def load_archived(self):
        self.ws.load_session(next(self.archived))

    def full_lifecycle(self):
        sid = f"L{next(self.counter):06d}"
        submit(self.ws, sid, run_id="now-l")
        for event in LIFECYCLE:
            self.ws.update_session(sid, lambda r, e=event: SessionLifecycle(r).fire(e))


OPS = ("submit", "transition", "claimable", "run_sessions", "load_archived", "full_lifecycle")


def measure(probes: dict[str, Probe], reps: int) -> dict[str, dict[str, float]]:
    """Median ms per operation; samples alternate between the workspaces, so load from
    anything else on the machine hits both alike."""
    samples = {label: {op: [] for op in OPS} for label in probes}
    for op in OPS:
        n = max(5, reps // 4) if op == "full_lifecycle" else reps
        for _ in range(n):
            for label, probe in probes.items():
                t0 = time.perf_counter()
                getattr(probe, op)()
                samples[label][op].append(1e3 * (time.perf_counter() - t0))
    return {label: {op: statistics.median(v) for op, v in ops.items()} for label, ops in samples.items()}


def main() -> int:
    ap = parser(__doc__, "supervisor_history")
    ap.add_argument("--small", type=int, default=100)
    ap.add_argument("--large", type=int, default=10_000)
    ap.add_argument("--reps", type=int, default=40)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        probes, sizes = {}, {}
        for label, n in (("small", args.small), ("large", args.large)):
            ws = Workspace.create(Path(tmp) / label)
            t0 = time.perf_counter()
            build_history(ws, n)
            print(f"history of {n} sessions built in {time.perf_counter() - t0:.1f} s", flush=True)
            probes[label], sizes[label] = Probe(ws), n
        medians = measure(probes, args.reps)
    results = {label: {"history": sizes[label], **medians[label]} for label in medians}
    ops = [k for k in results["small"] if k != "history"]
    ratios = {op: results["large"][op] / results["small"][op] for op in ops}
    print(f"{'operation':16s} {args.small:>10d} {args.large:>10d} {'ratio':>7s}   (median ms)")
    for op in ops:
        print(f"{op:16s} {results['small'][op]:10.2f} {results['large'][op]:10.2f} {ratios[op]:7.2f}")
    ok = all(r <= 1.5 for r in ratios.values())
    print(f"goal (ratio <= 1.5 for every operation): {'met' if ok else 'MISSED'}")
    write_json(args.out, {"results": results, "ratios": ratios, "goal_met": ok})
    return 0


if __name__ == "__main__":
    sys.exit(main())
