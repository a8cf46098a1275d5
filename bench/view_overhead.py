"""Cost of what ``phyagentos view`` asks of the runner: the live tree.json and ``--record``.

    .venv/bin/python bench/view_overhead.py [--runs 5] [--fps 10]

Runs the ``pick`` skill on the MuJoCo Franka (scene of phyagentos/data/goal_graphs/pick_and_place.yaml)
in-process through the BuiltinSkillRuntime, the way the SessionRunner does, three ways:

- ``bare``: no tree observer, no recorder;
- ``tree``: the TreeStatusPublisher (<= 10 Hz, atomic write without fsync) after every tick;
- ``tree+record``: plus a SessionRecorder at ``--fps`` frames per simulated second
  (320x240 overview camera, OSMesa, H.264 encoding on a background thread).

Reports medians over ``--runs`` runs after one warm-up: wall time per run, ticks, the
publisher's own cost per tick (it times itself: throttle check on every tick plus the
writes) and the recorder's render cost per frame; and the ratios to ``bare``. Writes
bench/results/view_overhead.json. The machine may be shared: compare ratios and medians.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from _harness import parser as bench_parser
from _harness import write_json

import phyagentos  # noqa: F401  (selects the headless GL backend before mujoco loads)
from phyagentos.errors import BenchError
from phyagentos.primitives.context import SkillContext
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir, skills_dir, trees_dir
from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
from phyagentos.runtime.recording import RecordingConfig, SessionRecorder
from phyagentos.runtime.safety_guard import SafetyGuard
from phyagentos.runtime.tree_status import TreeStatusPublisher
from phyagentos.targets import MuJoCoTarget, SceneSpec
from phyagentos.yamlsource import read_yaml

MODES = ("bare", "tree", "tree+record")


def one_run(mode: str, runtime: BuiltinSkillRuntime, scene: SceneSpec, safety, directory: Path, fps: float) -> dict:
    target = MuJoCoTarget("franka_tabletop", scene, seed=0)
    target.reset(seed=0)
    ctx = SkillContext(target=target, params={"object": "cube"}, seed=0)
    ctx.guard = SafetyGuard.for_target(target, safety, events=ctx.events, flow="builtin")
    publisher = recorder = None
    if mode != "bare":
        publisher = ctx.tree_observer = TreeStatusPublisher(directory / "tree.json", session_id="bench")
    if mode == "tree+record":
        recorder = SessionRecorder(target, directory, RecordingConfig(mode="all", fps=fps), seed=0)
    heartbeat = recorder.tick if recorder else None
    started = time.perf_counter()
    outcome = runtime.run("pick", ctx, deadline=time.monotonic() + 300, heartbeat=heartbeat)
    skill = time.perf_counter() - started
    files = recorder.close() if recorder else {}
    wall = time.perf_counter() - started
    target.close()
    assert outcome.status == "completed", outcome
    row = {"wall_s": wall, "skill_s": skill, "ticks": outcome.ticks}
    if publisher:
        row.update(publisher_us_per_tick=1e6 * publisher.cost_s / max(publisher.calls, 1), tree_writes=publisher.writes)
    if recorder:
        frames = len(recorder._t)
        row.update(frames=frames, render_ms_per_frame=1e3 * recorder.render_s / max(frames, 1),
                   record_hook_us_per_tick=1e6 * recorder.hook_s / max(recorder.ticks, 1), video="video" in files)
    return row


def main() -> None:
    parser = bench_parser(__doc__, "view_overhead")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--fps", type=float, default=10.0)
    args = parser.parse_args()
    graph = read_yaml(goal_graphs_dir() / "pick_and_place.yaml", error=BenchError)
    scene = SceneSpec.from_dict(graph["scene"])
    runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    with tempfile.TemporaryDirectory() as tmp:
        safety = Workspace.create(Path(tmp) / "ws").read_safety()
        rows: dict[str, list[dict]] = {m: [] for m in MODES}
        for i in range(args.runs + 1):
            for mode in MODES:  # interleaved, so load changes hit every mode alike
                d = Path(tmp) / f"{mode}-{i}"
                d.mkdir()
                row = one_run(mode, runtime, scene, safety, d, args.fps)
                if i:  # the first round warms up
                    rows[mode].append(row)
    med = {m: {k: statistics.median(r[k] for r in rows[m]) for k in rows[m][0] if isinstance(rows[m][0][k], (int, float))
               and not isinstance(rows[m][0][k], bool)} for m in MODES}
    bare = med["bare"]["wall_s"]
    print(f"pick skill on the MuJoCo Franka, medians of {args.runs} runs (shared 2-core machine)")
    nan = float("nan")
    print(f"{'mode':<12} {'skill s':>8} {'+close s':>8} {'ratio':>6} {'ticks':>6} {'tree µs/tick':>13} "
          f"{'rec µs/tick':>12} {'frames':>7} {'render ms/frame':>16}")
    for m in MODES:
        r = med[m]
        print(f"{m:<12} {r['skill_s']:8.3f} {r['wall_s']:8.3f} {r['wall_s'] / bare:6.2f} {r['ticks']:6.0f} "
              f"{r.get('publisher_us_per_tick', nan):13.1f} {r.get('record_hook_us_per_tick', nan):12.1f} "
              f"{r.get('frames', nan):7.0f} {r.get('render_ms_per_frame', nan):16.1f}")
    out = {"runs": args.runs, "fps": args.fps, "medians": med, "ratio_to_bare": {m: med[m]["wall_s"] / bare for m in MODES},
           "raw": rows}
    write_json(args.out, out)


if __name__ == "__main__":
    main()
