"""Where one hand-off goes: a traced ``phyagentos run`` of a hold chain, split by thread and function.

    .venv/bin/python bench/handoff_budget.py [--holds 20] [--cameras] [--show 9] [--graph G.yaml]

A diagnostic, not a goal measurement (the goals are ``bench/end_to_end.py``'s). It runs
``phyagentos run`` of a chain of ``--holds`` 0 s ``hold`` sessions (without cameras unless
``--cameras``) with this file as the program's main module. With the environment variable
``PHYAGENTOS_HANDOFF_TRACE`` set, importing this file wraps a fixed list of functions of
the agent, the supervisor, the protocol layer and the runner (``TRACED``) so that every
call appends ``thread, function, start, end`` (unix s) to ``<dir>/<pid>.log``; the
runner's forkserver children re-import the main module, so the runner process is traced
too. ``os.fsync`` and garbage collections (``gc.gen<N>``) are counted as well.
``--graph`` traces a run of that goal graph instead (e.g. ``phyagentos/data/goal_graphs/pick_and_place.yaml``
with ``--cameras``: its one hand-off, from pick to place).

Then, for every hand-off (a session's verdict to the next session's first actuation, as
``end_to_end.py`` measures it), the time each traced ``(process/thread, function)``
spent inside that window is summed, and the medians over the hand-offs are printed,
with the session's own transitions (verdict -> submitted -> claimed -> started -> first
tick). ``--show N`` prints hand-off N's timeline call by call. Nested functions are each
counted (a caller includes its callees), and the wrapping costs a few microseconds per
call: read the split, not the absolute times. Writes ``bench/results/handoff_budget.json``.
"""

from __future__ import annotations

import functools
import gc
import importlib
import os
import sys
import threading
import time

TRACE_ENV = "PHYAGENTOS_HANDOFF_TRACE"

#: (module, qualified name, which argument to log: an index into args, or None)
TRACED = [
    ("phyagentos.protocol.atomic", "atomic_write_bytes", 0),
    ("phyagentos.protocol.atomic", "_fsync_dir", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator.step", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator._verify", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator._consolidate", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator.sessions", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator._write_task", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator.write_task", None),
    ("phyagentos.agent.session_compiler", "SessionCompiler.compile_node", None),
    ("phyagentos.agent.verifier", "SessionVerifier.verify", None),
    ("phyagentos.protocol.workspace", "Workspace.append_log", None),
    ("phyagentos.protocol.workspace", "Workspace.save_session", None),
    ("phyagentos.protocol.workspace", "Workspace.submit_session", None),
    ("phyagentos.protocol.workspace", "Workspace.update_session", None),
    ("phyagentos.protocol.workspace", "Workspace.list_sessions", None),
    ("phyagentos.protocol.workspace", "Workspace.load_session", None),
    ("phyagentos.protocol.workspace", "Workspace.update", 1),
    ("phyagentos.protocol.workspace", "Workspace.read", 1),
    ("phyagentos.protocol.workspace", "Workspace.flush_index", None),
    ("phyagentos.protocol.archive", "SessionArchive.archive", None),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor._claim_next", None),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor._claim", None),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor._request", 1),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor._on_preflight", None),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor._poll_signals", None),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor._service_inflight", None),
    ("phyagentos.runtime.worker", "_Runner.reply", 1),
    ("phyagentos.runtime.worker", "_Runner._prepare", None),
    ("phyagentos.protocol.workspace", "Workspace.active_sessions", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator.node_states", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator.done", None),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor.step", None),
    ("phyagentos.runtime.supervisor", "WatchdogSupervisor._on_done", None),
    ("phyagentos.runtime.worker", "RunnerProcess.send", 1),
    ("phyagentos.app.orchestrator", "_agent_has_work", None),
    ("phyagentos.runtime.worker", "_Runner.job_preflight", None),
    ("phyagentos.runtime.worker", "_Runner.job_go", None),
    ("phyagentos.runtime.runner", "SessionRunner.run", None),
    ("phyagentos.runtime.target_pool", "TargetPool.acquire", None),
    ("phyagentos.runtime.target_pool", "TargetPool.checkpoint", None),
    ("phyagentos.runtime.safety_guard", "SafetyGuard.for_target", None),
    ("phyagentos.runtime.preflight", "run_preflight", None),
    ("phyagentos.runtime.preflight", "_tree_checks", None),
    ("phyagentos.runtime.trees", "TreeLibrary.spec", 1),
    ("phyagentos.runtime.trees", "TreeLibrary.build", 1),
    ("py_trees.trees", "BehaviourTree.setup", None),
    ("py_trees.trees", "BehaviourTree.tick", None),
    ("phyagentos.runtime.runner", "SessionRunner._initial_view", None),
    ("phyagentos.runtime.runner", "SessionRunner._image", None),
    ("phyagentos.runtime.runner", "_task_yaml", None),
    ("phyagentos.runtime.runner", "_truth", None),
    ("phyagentos.runtime.runner", "make_perceiver", None),
    ("phyagentos.runtime.runner", "dump_yaml", None),
    ("phyagentos.runtime.runner", "_perception_config", None),
    ("phyagentos.runtime.evidence_writer", "EvidenceImageWriter.scene", None),
    ("phyagentos.targets.mujoco_arm", "MuJoCoArmTarget.load_state", None),
    ("phyagentos.targets.mujoco_arm", "MuJoCoArmTarget.save_state", None),
    ("phyagentos.agent.coordinator", "AgentCoordinator.observed", None),
    ("phyagentos.agent.coordinator", "load_evidence", None),
    ("phyagentos.agent.verification", "load_evidence", None),
    ("phyagentos.agent.memory.context_builder", "ContextBuilder.build", None),
]


def _install(out_dir: str) -> None:
    """Wrap :data:`TRACED` (those that exist in this tree) and ``os.fsync``; each process
    appends to ``<out_dir>/<pid>.log``."""
    handles: dict[int, object] = {}

    def emit(name: str, t0: float, t1: float, extra: str = "") -> None:
        pid = os.getpid()
        fh = handles.get(pid)
        if fh is None:
            fh = handles[pid] = open(f"{out_dir}/{pid}.log", "a", buffering=1, encoding="utf-8")  # noqa: SIM115
        fh.write(f"{threading.current_thread().name}\t{name}\t{t0:.6f}\t{t1:.6f}\t{extra}\n")

    for module, qual, arg in TRACED:
        try:
            owner = importlib.import_module(module)
            *path, attr = qual.split(".")
            for part in path:
                owner = getattr(owner, part)
            original = getattr(owner, attr)
        except (ImportError, AttributeError):
            continue  # not in this tree (e.g. an older checkout)

        def wrapper(*args, __original=original, __qual=qual, __arg=arg, **kwargs):
            t0 = time.time()
            try:
                return __original(*args, **kwargs)
            finally:
                extra = str(args[__arg])[-60:] if __arg is not None and len(args) > __arg else ""
                emit(__qual, t0, time.time(), extra)

        setattr(owner, attr, functools.wraps(original)(wrapper))
    real_fsync = os.fsync

    def fsync(fd):
        t0 = time.time()
        try:
            return real_fsync(fd)
        finally:
            emit("os.fsync", t0, time.time())

    os.fsync = fsync
    gc_started: list[float] = []

    def collected(phase: str, info: dict) -> None:  # garbage collections, as ``gc.gen<N>``
        if phase == "start":
            gc_started[:] = [time.time()]
        elif gc_started:
            emit(f"gc.gen{info['generation']}", gc_started[0], time.time(), str(info.get("collected", "")))

    gc.callbacks.append(collected)


if os.environ.get(TRACE_ENV):  # the traced run's processes (this file is their main module)
    os.makedirs(os.environ[TRACE_ENV], exist_ok=True)
    _install(os.environ[TRACE_ENV])


def _events(trace_dir) -> list[tuple]:
    events = []
    for log in sorted(trace_dir.glob("*.log")):
        for line in log.read_text(encoding="utf-8").splitlines():
            thread, name, t0, t1, extra = line.split("\t")
            events.append((float(t0), float(t1), f"{log.stem}:{thread}", name, extra))
    events.sort()
    return events


def budget(ws, trace_dir, *, show: int | None = None) -> dict:
    """Median ms per (process:thread, function) inside the hand-offs of the run in ``ws``."""
    import statistics  # noqa: PLC0415

    from end_to_end import session_timeline  # noqa: PLC0415  (bench/ is sys.path[0] of the script)

    rows = session_timeline(ws)
    by_node = {r["node"]: r for r in rows}
    events = _events(trace_dir)
    # name processes by role: the run process, and the runner (whoever ran job_go)
    roles = {}
    for _, _, who, name, _ in events:
        pid = who.split(":")[0]
        if name == "AgentCoordinator.step":
            roles[pid] = "run"
        elif name == "_Runner.job_go":
            roles[pid] = "runner"
    spans: dict[tuple[str, str], list[float]] = {}
    marks: dict[str, list[float]] = {k: [] for k in ("hand-off", "verdict -> submitted", "submitted -> claimed",
                                                     "claimed -> started", "started -> first tick")}
    hands = [(by_node[r["depends_on"][0]], r) for r in rows if r["depends_on"] and r["actuation_started"]]
    for i, (dep, r) in enumerate(hands):
        a, b = dep["verdict"], r["actuation_started"]
        marks["hand-off"].append(b - a)
        marks["verdict -> submitted"].append(r["created"] - a)
        marks["submitted -> claimed"].append(r["claim"] - r["created"])
        marks["claimed -> started"].append(r["start"] - r["claim"])
        marks["started -> first tick"].append(b - r["start"])
        inside = [e for e in events if e[1] > a and e[0] < b]
        totals: dict[tuple[str, str], float] = {}
        for t0, t1, who, name, _ in inside:
            pid, thread = who.split(":", 1)
            key = (f"{roles.get(pid, pid)}:{thread}", name)
            totals[key] = totals.get(key, 0.0) + min(t1, b) - max(t0, a)
        for key, v in totals.items():
            spans.setdefault(key, []).append(v)
        if show == i:
            print(f"hand-off {i} ({dep['node']} -> {r['node']}), ms from the verdict:")
            for t0, t1, who, name, extra in inside:
                pid, thread = who.split(":", 1)
                print(f"  {1000 * (t0 - a):7.1f} {1000 * (t1 - a):7.1f} {1000 * (t1 - t0):6.1f}  "
                      f"{roles.get(pid, pid) + ':' + thread:28} {name} {extra}")
    n = len(hands)
    ms = lambda xs: round(1000 * statistics.median(xs + [0.0] * (n - len(xs))), 2)  # noqa: E731
    return {"hand_offs": n,
            "segments_ms": {k: ms(v) for k, v in marks.items()},
            "functions_ms": sorted(({"where": w, "function": f, "median_ms": ms(v)} for (w, f), v in spans.items()),
                                   key=lambda d: -d["median_ms"])}


def main(argv=None) -> int:
    import shutil  # noqa: PLC0415
    import subprocess  # noqa: PLC0415
    import tempfile  # noqa: PLC0415
    from pathlib import Path  # noqa: PLC0415

    import yaml  # noqa: PLC0415
    from _harness import parser, write_json  # noqa: PLC0415
    from end_to_end import NO_CAMERA_SENSORS, hold_chain  # noqa: PLC0415

    ap = parser(__doc__, "handoff_budget")
    ap.add_argument("--holds", type=int, default=20, help="length of the hold chain (default 20)")
    ap.add_argument("--cameras", action="store_true", help="keep the target's cameras (perceive around each hold)")
    ap.add_argument("--graph", type=Path, default=None, help="trace a run of this goal graph instead of a hold chain")
    ap.add_argument("--show", type=int, default=None, help="print this hand-off's timeline call by call")
    args = ap.parse_args(argv)
    load = os.getloadavg()
    tmp = Path(tempfile.mkdtemp(prefix="phyagentos-handoff-"))
    try:
        ws = tmp / "ws"
        ws.mkdir()
        if not args.cameras:
            (ws / "sensors.yaml").write_text(yaml.safe_dump(NO_CAMERA_SENSORS))
        graph = args.graph.resolve() if args.graph is not None else hold_chain(tmp / "hold_chain.yaml", args.holds)
        env = {**os.environ, TRACE_ENV: str(tmp / "trace")}
        proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", "run", str(graph),
                               "--workspace", str(ws), "--json"], env=env, capture_output=True, text=True)
        if proc.returncode != 0:
            print(proc.stderr[-3000:], file=sys.stderr)
            return proc.returncode
        result = {"load_at_start": load, "holds": args.holds, "cameras": args.cameras,
                  **budget(ws, tmp / "trace", show=args.show), "load_at_end": os.getloadavg()}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"\n{result['hand_offs']} hand-offs, load {load[0]:.2f} -> {result['load_at_end'][0]:.2f}; median ms:")
    for k, v in result["segments_ms"].items():
        print(f"  {v:7.1f}  {k}")
    print("  time inside the hand-off per process:thread and function (callers include callees):")
    for row in result["functions_ms"]:
        if row["median_ms"] >= 0.3:
            print(f"  {row['median_ms']:7.1f}  {row['where']:28} {row['function']}")
    write_json(args.out, result)
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:  # the traced run itself: the CLI with this file as main module
        from phyagentos.cli import main as cli_main

        sys.exit(cli_main(sys.argv[2:]))
    raise SystemExit(main())
