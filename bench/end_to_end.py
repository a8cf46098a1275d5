"""End to end: whole-process ``phyagentos run`` of the pick-and-place graph against the bare script.

    .venv/bin/python bench/end_to_end.py [--runs 5] [--holds 20] [--parts compare,holds,...] [--bytecode as-is]

Everything runs as real processes in one process tree (this script is a child
subreaper, so the runner and its forkserver are reaped here and their CPU counted):

1. **Comparison**, alternated so shared load hits both sides alike: ``phyagentos run
   phyagentos/data/goal_graphs/pick_and_place.yaml --workspace <new>`` against ``bench/bare_pick_and_place.py
   --once --perception`` (the same motions with the project's own motion library, no
   framework, and the same perception calls at the same points: before and after each
   skill and where the skill trees observe). Both sides must move alike: the simulated
   time each moved the arm is recorded with its ratio, and a difference above 5 % is
   warned of. ``compare_no_perception`` repeats it with the run's cameras removed (a
   workspace sensors.yaml without them) against the bare script without perception.
   Median wall and CPU time (user + system of the whole tree), their ratios, and the
   median ratio of the back-to-back pairs.
2. **Hand-off latency**: from one session's verdict (the transition's timestamp) to the
   next ready session's first actuation (``actuation_started_at`` in its evidence
   bundle, stamped by the SessionRunner just before the first tick).
3. **Hold chain**: one ``phyagentos run`` of a chain of ``--holds`` ``hold`` sessions
   (0 s); sessions per second, hand-offs, and the per-session framework cost split from
   the transitions' and bundle's timestamps: claim (ready -> claimed), preflight
   (claimed -> started, including the preflight round trip), runner start (started ->
   first tick), evidence (last tick -> awaiting_verification), verification
   (awaiting_verification -> verdict), plus the session-file writes counted.
   ``holds_no_cameras`` repeats it without cameras: with them, "runner start" holds the
   session's initial perception (two RGB-D renders and the perception pipeline) and
   "evidence" its terminal one, which every session does by design.
4. **Two-process mode**: ``phyagentos watch`` + ``phyagentos agent`` started first, then
   ``phyagentos submit`` of the hold chain and of pick-and-place; the same hand-off figures.
5. **Cold start**: from launching ``phyagentos run`` to the first session's first
   actuation, and import times (``python -X importtime``) of the CLI and of what
   ``run`` imports in the main process.

Bytecode: by default (``--bytecode cached``) the project's own modules (``phyagentos``,
``bench``) are compiled to ``__pycache__`` first, so every measured process, framework
and bare script alike, imports them from bytecode as an installed package or any second
run does. ``--bytecode as-is`` measures without that: under ``PYTHONDONTWRITEBYTECODE``
(set on some machines, this one included) every process then compiles the project's
modules from source on every run, which costs the framework more than the bare script
(it imports more of them); the JSON records which was measured.

Prints tables and writes ``bench/results/end_to_end.json``. Goals (issue 12): wall ratio
<= 1.2, CPU ratio <= 1.15, hand-off p50 <= 20 ms and p99 <= 100 ms.
"""

from __future__ import annotations

import ctypes
import json
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import yaml
from _harness import parser, percentile, write_json

from phyagentos.errors import BenchError
from phyagentos.yamlsource import read_yaml

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PHYAGENTOS = [str(BIN / "phyagentos")] if (BIN / "phyagentos").exists() else [sys.executable, "-m", "phyagentos.cli"]
BARE = [sys.executable, str(ROOT / "bench" / "bare_pick_and_place.py"), "--once"]
GRAPH = ROOT / "phyagentos" / "data" / "goal_graphs" / "pick_and_place.yaml"
_VERDICT_EVENTS = ("succeed", "fail", "replan")


def _subreaper() -> None:
    """Become the reaper of orphaned descendants (Linux), so their CPU time is ours to count."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):
        pass


def _reap(timeout: float = 10.0) -> None:
    """Wait for every descendant re-parented to us (e.g. a forkserver outliving its parent)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            if time.monotonic() > deadline:
                return
            time.sleep(0.01)


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def timed(cmd: list[str], *, env: dict | None = None) -> dict:
    """Run ``cmd`` to completion; wall and CPU (the whole reaped tree) in s, start time, stdout."""
    cpu0 = _children_cpu()
    started_unix = time.time()
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env, timeout=900)
    wall = time.perf_counter() - t0
    _reap()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return {"wall_s": wall, "cpu_s": _children_cpu() - cpu0, "started_unix": started_unix, "stdout": proc.stdout}


def _ts(iso) -> float | None:
    """Unix seconds of an ISO timestamp (string, or a datetime as YAML or pydantic parse it)."""
    if not iso:
        return None
    if isinstance(iso, datetime):
        return (iso if iso.tzinfo else iso.replace(tzinfo=timezone.utc)).timestamp()
    return datetime.fromisoformat(str(iso).replace("Z", "+00:00")).timestamp()


def _ms(x: float | None) -> float | None:
    return None if x is None else round(x * 1e3, 2)


# -- reading a finished workspace ------------------------------------------------------------


def session_timeline(ws: Path) -> list[dict]:
    """Per session (creation order): timestamps (unix s) of its transitions and bundle."""
    from phyagentos.protocol import Workspace  # noqa: PLC0415

    workspace = Workspace.open(ws)
    rows = []
    for rec in workspace.list_sessions():
        t = {}
        for tr in rec.transitions:
            t.setdefault(tr.event.split(":", 1)[0], _ts(tr.at))
        attempt = rec.attempts[-1] if rec.attempts else None
        bundle = {}
        if attempt and attempt.evidence and (ws / attempt.evidence / "bundle.yaml").is_file():
            bundle = read_yaml(ws / attempt.evidence / "bundle.yaml", error=BenchError).get("outcome", {})
        verdict_at = next((t[e] for e in _VERDICT_EVENTS if e in t), None)
        rows.append({
            "session_id": rec.session_id, "node": rec.node, "state": rec.state,
            "depends_on": list(rec.depends_on), "created": _ts(rec.created_at),
            "claim": t.get("claim"), "start": t.get("start"), "submit": t.get("submit"),
            "verify": t.get("verify"), "verdict": verdict_at,
            "actuation_started": _ts(bundle.get("actuation_started_at")),
            "actuation_ended": _ts(bundle.get("actuation_ended_at")),
            "sim_time_s": bundle.get("sim_time_s"),  # the target's clock when the session ended
            "writes": len(rec.transitions),
        })
    return rows


def handoffs(rows: list[dict]) -> list[float]:
    """Verdict of a dependency -> first actuation of the session that waited for it (s)."""
    by_node = {}
    for r in rows:
        by_node.setdefault(r["node"], []).append(r)
    out = []
    for r in rows:
        if not r["depends_on"] or r["actuation_started"] is None:
            continue
        # the session became ready at the latest verdict among its dependencies
        ready = max((d["verdict"] for n in r["depends_on"] for d in by_node.get(n, []) if d["verdict"]), default=None)
        if ready is not None and r["actuation_started"] >= ready:
            out.append(r["actuation_started"] - ready)
    return out


def cost_split(rows: list[dict]) -> dict:
    """Median framework time per session phase (ms), from the timestamps."""
    phases = {"claim": [], "preflight": [], "runner_start": [], "actuation": [], "evidence": [],
              "verification": []}
    by_node = {r["node"]: r for r in rows}
    for r in rows:
        ready = max([by_node[n]["verdict"] for n in r["depends_on"] if n in by_node and by_node[n]["verdict"]]
                    or [r["created"]])
        pairs = {"claim": (ready, r["claim"]), "preflight": (r["claim"], r["start"]),
                 "runner_start": (r["start"], r["actuation_started"]),
                 "actuation": (r["actuation_started"], r["actuation_ended"]),
                 "evidence": (r["actuation_ended"], r["submit"]), "verification": (r["submit"], r["verdict"])}
        for k, (a, b) in pairs.items():
            if a is not None and b is not None:
                phases[k].append(b - a)
    out = {k: _ms(statistics.median(v)) if v else None for k, v in phases.items()}
    out["session_file_writes"] = statistics.median([r["writes"] for r in rows]) if rows else None
    return out


def hold_chain(path: Path, n: int) -> Path:
    nodes = [{"id": f"h{i:02d}", "skill": "hold", "params": {"duration_s": 0.0},
              "accept": {"still": {"max_joint_motion_rad": 0.01}},
              "depends_on": [f"h{i - 1:02d}"] if i else []} for i in range(n)]
    path.write_text(yaml.safe_dump({"version": 1, "name": "hold_chain", "description": f"{n} chained 0 s holds",
                                    "defaults": {"target": "franka_tabletop"}, "nodes": nodes}))
    return path


# -- the parts -------------------------------------------------------------------------------


#: franka_tabletop's sensors without its cameras: a workspace with this sensors.yaml runs
#: every session without perception (the runner falls back to the target's own
#: observation), for the comparison against the bare script without perception.
NO_CAMERA_SENSORS = {"version": 1, "targets": {"franka_tabletop": [
    {"name": "joints", "kind": "joint_state", "frame_id": "panda0_link0", "rate_hz": 500},
    {"name": "gripper", "kind": "gripper", "frame_id": "tcp", "rate_hz": 500}]}}


def compare(runs: int, tmp: Path, *, perception: bool = True) -> dict:
    """Alternated whole-process runs of the framework and the bare script.

    ``perception=True``: the run with its cameras and perception on (every session
    perceives before and after its skill, and the skill trees observe), against
    ``bare_pick_and_place.py --perception`` (the same perception calls at the same
    points). ``perception=False``: the run in a workspace whose sensors.yaml has no
    cameras, against the bare script without perception.

    Both sides must make the same motions: the simulated time each moved its arm is
    recorded (``sim_time_s``) with their ratio, and ``motions_match`` says whether
    it is within 5 % (a warning is printed otherwise: the wall and CPU ratios then
    compare different motions, not the framework's cost).
    """
    fw, bare, cold, hand, fw_sim, bare_sim = [], [], [], [], [], []
    bare_cmd = [*BARE, "--perception"] if perception else BARE
    tag = "pp" if perception else "np"
    for i in range(runs):
        order = ("fw", "bare") if i % 2 == 0 else ("bare", "fw")
        for side in order:
            if side == "bare":
                r = timed(bare_cmd)
                result = json.loads(r["stdout"].strip().splitlines()[-1])
                assert result["success"], result
                bare.append(r)
                bare_sim.append(result["sim_time_s"])
            else:
                ws = tmp / f"{tag}{i}"
                if not perception:
                    ws.mkdir(parents=True)
                    (ws / "sensors.yaml").write_text(yaml.safe_dump(NO_CAMERA_SENSORS))
                r = timed([*PHYAGENTOS, "run", str(GRAPH), "--workspace", str(ws), "--json"])
                report = json.loads(r["stdout"])
                assert report["succeeded"], report
                rows = session_timeline(ws)
                first = min(x["actuation_started"] for x in rows if x["actuation_started"])
                cold.append(first - r["started_unix"])
                hand += handoffs(rows)
                # a run's target starts at 0: its clock at the last session's end is what it moved
                fw_sim.append(max(x["sim_time_s"] for x in rows if x["sim_time_s"] is not None))
                fw.append(r)
                shutil.rmtree(ws, ignore_errors=True)
            print(f"  run {i + 1}/{runs} {side:<4} wall {r['wall_s']:.2f} s  cpu {r['cpu_s']:.2f} s", flush=True)
    med = lambda xs, k: statistics.median(x[k] for x in xs)  # noqa: E731
    out = {
        "runs": runs,
        "perception": perception,
        "framework": {"wall_s": med(fw, "wall_s"), "cpu_s": med(fw, "cpu_s"),
                      "wall_all_s": [round(x["wall_s"], 3) for x in fw], "cpu_all_s": [round(x["cpu_s"], 3) for x in fw]},
        "bare": {"wall_s": med(bare, "wall_s"), "cpu_s": med(bare, "cpu_s"),
                 "wall_all_s": [round(x["wall_s"], 3) for x in bare], "cpu_all_s": [round(x["cpu_s"], 3) for x in bare]},
        "cold_start_to_first_actuation_s": {"median": statistics.median(cold), "all": [round(c, 3) for c in cold]},
        "handoff_ms": {"p50": _ms(percentile(hand, 50)), "p99": _ms(percentile(hand, 99)), "n": len(hand)},
        "sim_time_s": {"framework": statistics.median(fw_sim), "bare": statistics.median(bare_sim)},
    }
    sim = out["sim_time_s"]
    sim["ratio"] = sim["framework"] / sim["bare"]
    out["motions_match"] = abs(sim["ratio"] - 1.0) <= 0.05
    if not out["motions_match"]:
        print(f"  WARNING: the run moved its arm for {sim['framework']:.2f} s of simulated time, the bare script "
              f"for {sim['bare']:.2f} s: not the same motions", flush=True)
    # ratios of the medians, and the median of the per-pair ratios (each pair ran back to back)
    out["wall_ratio"] = out["framework"]["wall_s"] / out["bare"]["wall_s"]
    out["cpu_ratio"] = out["framework"]["cpu_s"] / out["bare"]["cpu_s"]
    out["wall_ratio_pairs_median"] = statistics.median(f["wall_s"] / b["wall_s"] for f, b in zip(fw, bare))
    out["cpu_ratio_pairs_median"] = statistics.median(f["cpu_s"] / b["cpu_s"] for f, b in zip(fw, bare))
    return out


def holds_in_one_run(n: int, tmp: Path, *, cameras: bool = True) -> dict:
    """One run of a chain of ``n`` holds; ``cameras=False``: in a workspace whose
    sensors.yaml has no cameras (no perception before and after each hold)."""
    graph = hold_chain(tmp / "hold_chain.yaml", n)
    ws = tmp / ("holds" if cameras else "holds_no_cameras")
    if not cameras:
        ws.mkdir(parents=True)
        (ws / "sensors.yaml").write_text(yaml.safe_dump(NO_CAMERA_SENSORS))
    r = timed([*PHYAGENTOS, "run", str(graph), "--workspace", str(ws), "--json"])
    assert json.loads(r["stdout"])["succeeded"]
    rows = session_timeline(ws)
    hand = handoffs(rows)
    span = max(x["verdict"] for x in rows) - min(x["created"] for x in rows)
    shutil.rmtree(ws, ignore_errors=True)
    return {"sessions": n, "process_wall_s": r["wall_s"], "process_cpu_s": r["cpu_s"],
            "sessions_per_s": n / span, "first_submit_to_last_verdict_s": span,
            "handoff_ms": {"p50": _ms(percentile(hand, 50)), "p99": _ms(percentile(hand, 99)), "n": len(hand)},
            "per_session_ms": cost_split(rows)}


def two_process(n: int, tmp: Path) -> dict:
    ws = tmp / "two"
    subprocess.run([*PHYAGENTOS, "validate", str(GRAPH)], cwd=ROOT, capture_output=True)
    from phyagentos.protocol import Workspace  # noqa: PLC0415

    Workspace.create(ws)
    procs = [subprocess.Popen([*PHYAGENTOS, "watch", str(ws)], cwd=ROOT, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL),
             subprocess.Popen([*PHYAGENTOS, "agent", str(ws)], cwd=ROOT, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    out = {}
    try:
        deadline = time.monotonic() + 120
        while not list((ws / ".supervisors").glob("*.json")) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)  # let the watcher's runner finish importing: measure hand-offs, not start-up
        for name, graph in (("hold_chain", hold_chain(tmp / "hold_chain2.yaml", n)), ("pick_and_place", GRAPH)):
            t0 = time.perf_counter()
            sub = subprocess.run([*PHYAGENTOS, "submit", str(graph), "--workspace", str(ws)], cwd=ROOT,
                                 capture_output=True, text=True, timeout=120)
            assert sub.returncode == 0, sub.stderr
            run_id = sub.stdout.strip().splitlines()[-1]
            deadline = time.monotonic() + 600
            while (ws / "runs" / ".active" / run_id).exists() or any((ws / "runs" / ".active").glob(f"{run_id}*")):
                if time.monotonic() > deadline:
                    raise RuntimeError(f"run {run_id} did not finish in two-process mode")
                time.sleep(0.05)
            wall = time.perf_counter() - t0
            rows = [r for r in session_timeline(ws) if r["session_id"].startswith(run_id)]
            hand = handoffs(rows)
            out[name] = {"submit_to_finished_s": wall, "sessions": len(rows),
                         "handoff_ms": {"p50": _ms(percentile(hand, 50)), "p99": _ms(percentile(hand, 99)), "n": len(hand)},
                         "per_session_ms": cost_split(rows)}
    finally:
        for p in procs:
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=60)
            except subprocess.TimeoutExpired:
                p.kill()
        _reap()
        shutil.rmtree(ws, ignore_errors=True)
    return out


def import_times() -> dict:
    """Import time (s, median of 3) of ``phyagentos.cli`` and of the main process of ``run``."""
    out = {}
    for name, stmt in (("cli", "import phyagentos.cli"),
                       ("run_main_process", "import phyagentos.cli, phyagentos.app.orchestrator"),
                       ("interpreter_only", "pass")):
        walls = []
        for _ in range(3):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c", stmt], cwd=ROOT, check=True)
            walls.append(time.perf_counter() - t0)
        out[f"{name}_process_s"] = statistics.median(walls)
        if name != "interpreter_only":
            p = subprocess.run([sys.executable, "-X", "importtime", "-c", stmt], cwd=ROOT, capture_output=True,
                               text=True, check=True)
            total = 0
            for line in p.stderr.splitlines():
                parts = line.split("|")
                if len(parts) == 3 and parts[2].startswith(" ") and not parts[2].startswith("  "):
                    try:
                        total += int(parts[1])
                    except ValueError:
                        pass
            out[f"{name}_importtime_s"] = total / 1e6
    return out


def prepare_bytecode(mode: str) -> dict:
    """``cached``: compile the project's modules to ``__pycache__`` (what importing them
    does anyway unless bytecode writing is off); ``as-is``: leave them. Returns what the
    JSON records about it."""
    import compileall  # noqa: PLC0415

    if mode == "cached":
        for sub in ("phyagentos", "bench"):
            if not compileall.compile_dir(ROOT / sub, quiet=1):
                raise BenchError(f"compileall of {ROOT / sub} failed")
    return {"mode": mode, "dont_write_bytecode": bool(os.environ.get("PYTHONDONTWRITEBYTECODE"))}


def main(argv=None) -> int:
    ap = parser(__doc__, "end_to_end")
    ap.add_argument("--runs", type=int, default=5, help="alternated runs of each side (default 5)")
    ap.add_argument("--holds", type=int, default=20, help="length of the hold chain (default 20)")
    ap.add_argument("--parts", default="imports,compare,compare_no_perception,holds,holds_no_cameras,two_process",
                    help="comma-separated subset of imports,compare,compare_no_perception,holds,holds_no_cameras,"
                         "two_process (default all)")
    ap.add_argument("--bytecode", choices=("cached", "as-is"), default="cached",
                    help="cached: compile the project's modules first (default); as-is: measure without that")
    args = ap.parse_args(argv)
    _subreaper()
    bytecode = prepare_bytecode(args.bytecode)
    load = os.getloadavg()
    print(f"load average at start {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores; "
          f"bytecode {bytecode['mode']} (PYTHONDONTWRITEBYTECODE {'set' if bytecode['dont_write_bytecode'] else 'unset'})",
          flush=True)
    tmp = Path(tempfile.mkdtemp(prefix="phyagentos-e2e-"))
    try:
        parts = set(args.parts.split(","))
        result = {"load_at_start": load, "bytecode": bytecode}
        if "imports" in parts:
            result["imports"] = import_times()
        if "compare" in parts:
            print("comparison (alternated):", flush=True)
            result["compare"] = compare(args.runs, tmp)
        if "compare_no_perception" in parts:
            print("comparison without perception (alternated):", flush=True)
            result["compare_no_perception"] = compare(args.runs, tmp, perception=False)
        if "holds" in parts:
            print("hold chain in one run:", flush=True)
            result["holds"] = holds_in_one_run(args.holds, tmp)
        if "holds_no_cameras" in parts:
            print("hold chain in one run, no cameras:", flush=True)
            result["holds_no_cameras"] = holds_in_one_run(args.holds, tmp, cameras=False)
        if "two_process" in parts:
            print("two-process mode:", flush=True)
            result["two_process"] = two_process(args.holds, tmp)
        result["load_at_end"] = os.getloadavg()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    c = result.get("compare")
    for key, title in (("compare", "with perception"), ("compare_no_perception", "without perception")):
        cc = result.get(key)
        if not cc:
            continue
        print(f"\n{title:34}{'framework':>12}{'bare':>10}{'ratio':>8}{'pairs':>8}{'goal':>8}")
        print(f"{'wall, median (s)':34}{cc['framework']['wall_s']:>12.3f}{cc['bare']['wall_s']:>10.3f}"
              f"{cc['wall_ratio']:>8.2f}{cc['wall_ratio_pairs_median']:>8.2f}{'<=1.20':>8}")
        print(f"{'CPU, median (s)':34}{cc['framework']['cpu_s']:>12.3f}{cc['bare']['cpu_s']:>10.3f}"
              f"{cc['cpu_ratio']:>8.2f}{cc['cpu_ratio_pairs_median']:>8.2f}{'<=1.15':>8}")
        print(f"{'simulated time moved, median (s)':34}{cc['sim_time_s']['framework']:>12.3f}"
              f"{cc['sim_time_s']['bare']:>10.3f}{cc['sim_time_s']['ratio']:>8.2f}{'':>8}{'same':>8}")
        print(f"{'cold start to first actuation (s)':34}{cc['cold_start_to_first_actuation_s']['median']:>12.3f}")
    rows = [("pick_and_place run", c["handoff_ms"])] if c else []
    if result.get("compare_no_perception"):
        rows.append(("pick_and_place run, no cameras", result["compare_no_perception"]["handoff_ms"]))
    if "holds" in result:
        rows.append((f"{args.holds} holds, one run", result["holds"]["handoff_ms"]))
    if "holds_no_cameras" in result:
        rows.append((f"{args.holds} holds, one run, no cameras", result["holds_no_cameras"]["handoff_ms"]))
    for name, part in result.get("two_process", {}).items():
        rows.append((f"two-process {name}", part["handoff_ms"]))
    print(f"\n{'hand-off verdict -> next actuation':40}{'p50 ms':>10}{'p99 ms':>10}{'n':>5}")
    for name, h in rows:
        print(f"{name:40}{h['p50'] if h['p50'] is not None else '-':>10}{h['p99'] if h['p99'] is not None else '-':>10}"
              f"{h['n']:>5}")
    for key in ("holds", "holds_no_cameras"):
        if key in result:
            h = result[key]
            print(f"\n{key.replace('_', ' ')}: {h['sessions_per_s']:.2f} sessions/s; per session (median ms): "
                  + ", ".join(f"{k} {v}" for k, v in h["per_session_ms"].items()))
    for name, part in result.get("two_process", {}).items():
        print(f"two-process {name}: submit to finished {part['submit_to_finished_s']:.2f} s; per session (median ms): "
              + ", ".join(f"{k} {v}" for k, v in part["per_session_ms"].items()))
    if "imports" in result:
        im = result["imports"]
        print(f"imports: cli {im['cli_importtime_s']:.3f} s, run's main process {im['run_main_process_importtime_s']:.3f} s "
              f"(-X importtime); interpreter alone {im['interpreter_only_process_s']:.3f} s")
    print(f"load average at end {result['load_at_end'][0]:.2f}")
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
