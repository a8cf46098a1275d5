"""Sweep of the LIBERO bench's fixed skill defaults on LIBERO-90, LIBERO's training tasks.

    .venv/bin/python bench/libero_defaults_sweep.py [--settings trees,mid,fast] [--tasks planned] [--seeds 0]
        [--workspace ws/libero_sweep] [--workers 2] [--out bench/results/libero_defaults_sweep.json]

Every setting is a YAML file of ``bench/libero_skill_defaults/`` (``{skill: {parameter: value}}``,
the format of ``phyagentos bench --skill-defaults``): ``trees`` is the trees' own defaults (``{}``: the
approach, lift and lowering at 0.3 of the LIBERO target's joint limits), ``mid`` at 0.6, ``fast`` at
the full limits, as the transfers. Each runs
through the command a user types, ``phyagentos bench libero_90 --skill-defaults FILE --json``, on
the LIBERO-90 tasks the Goal Planner's rules plan (``--tasks planned``, the default, or LIBERO-90
task indices) and init states ``--seeds``, memory off, one workspace per setting (the category
looks measured once and copied). Never an evaluation suite (libero_spatial, _object, _goal, _10).

Per setting, by LIBERO's checker (``ground_truth.yaml`` of every session): ``first`` / ``final``
(successes within LIBERO-90's 400-step budget, before any recovery session / in any),
``within`` (first successes within each evaluation suite's budget: 220 / 280 / 300 / 520 steps),
``median_first_step`` (the control step at which the checker first held, over the successes),
``false_successes`` (sessions our verifier called a success where LIBERO's checker did not) and
the wall time. The best setting -- most ``first``, then most ``final``, then the lower median
step -- is written to ``bench/results/libero_defaults_best.yaml``; ``phyagentos.bench.libero.SKILL_DEFAULTS``
holds it. Prints a table and writes the JSON.
"""

from __future__ import annotations

import glob
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import yaml
from _harness import median, parser, print_table, results_path, write_json

SETTINGS_DIR = Path(__file__).resolve().parent / "libero_skill_defaults"
EVAL_BUDGETS = {"libero_spatial": 220, "libero_object": 280, "libero_goal": 300, "libero_10": 520}


def planned_tasks() -> list[int]:
    """LIBERO-90 task indices whose instruction the Goal Planner's rules plan."""
    from phyagentos.bench.libero import instruction_plan  # noqa: PLC0415
    from phyagentos.errors import BenchError  # noqa: PLC0415
    from phyagentos.targets.libero.catalog import parse_bddl, suite_tasks  # noqa: PLC0415

    out = []
    for i, task in enumerate(suite_tasks("libero_90")):
        problem = parse_bddl(task.bddl_path)
        try:
            instruction_plan(task.instruction, problem.objects, problem.fixtures)
            out.append(i)
        except BenchError:
            continue
    return out


def score(bench_dir: Path) -> dict:
    """LIBERO's verdicts of one bench run (its report's ground truth and every session's step)."""
    report = json.loads((bench_dir / "report.json").read_text())
    gt = report.get("ground_truth", {})
    per_task = dict(gt.get("per_task", []))
    firsts: dict[str, int] = {}
    for path in glob.glob(str(bench_dir / "episodes" / "*" / "evidence" / "*" / "ground_truth.yaml")):
        episode = path.split("/episodes/")[1].split("/")[0]
        bench = ((yaml.safe_load(Path(path).read_text()) or {}).get("terminal") or {}).get("benchmark") or {}
        step = bench.get("first_success_step")
        if step is not None and (episode not in firsts or step < firsts[episode]):
            firsts[episode] = int(step)
    steps = sorted(firsts.values())
    return {"episodes": len(glob.glob(str(bench_dir / "episodes" / "*" / "outcome.yaml"))),
            "first": sum(v["first_successes"] for v in per_task.values()),
            "final": sum(v["final_successes"] for v in per_task.values()),
            "within": {s: sum(1 for x in steps if x <= b) for s, b in EVAL_BUDGETS.items()},
            "median_first_step": median(steps),
            "false_successes": sum(1 for d in gt.get("disagreements", [])
                                   if d.get("verdict") == "success" and not d.get("env_success")
                                   and "place_" in d.get("session_id", "")),
            "wall_s": report.get("wall_time_s")}


def main() -> int:
    ap = parser(__doc__, "libero_defaults_sweep")
    ap.add_argument("--settings", default="trees,mid,fast", help="setting names (files of bench/libero_skill_defaults/)")
    ap.add_argument("--tasks", default="planned", help="LIBERO-90 task indices, or 'planned' (default)")
    ap.add_argument("--seeds", default="0", help="LIBERO-90 init states (default 0)")
    ap.add_argument("--workspace", type=Path, default=Path("ws/libero_sweep"))
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    names = [s.strip() for s in args.settings.split(",") if s.strip()]
    missing = [n for n in names if not (SETTINGS_DIR / f"{n}.yaml").is_file()]
    if missing:
        valid = sorted(p.stem for p in SETTINGS_DIR.glob("*.yaml"))
        print(f"unknown setting(s) {', '.join(missing)}; valid: {', '.join(valid)}", file=sys.stderr)
        return 2
    tasks = ",".join(map(str, planned_tasks())) if args.tasks == "planned" else args.tasks
    rows, results = [], {}
    looks = None
    for name in names:
        ws = args.workspace / name
        if looks is not None and not (ws / "libero").exists():  # the looks of the categories, measured once
            (ws / "libero").mkdir(parents=True)
            for f in looks.glob("*.yaml"):
                shutil.copy(f, ws / "libero" / f.name)
        t0 = time.time()
        cmd = [sys.executable, "-m", "phyagentos.cli", "bench", "libero_90", "--tasks", tasks, "--seeds", args.seeds,
               "--workers", str(args.workers), "--memory", "off", "--json", "--heartbeat-timeout", "300",
               "--queue-timeout", "6000", "--workspace", str(ws), "--skill-defaults", str(SETTINGS_DIR / f"{name}.yaml")]
        print(f"{name}: {' '.join(cmd[2:])}", file=sys.stderr, flush=True)
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            print(proc.stderr[-2000:], file=sys.stderr)
            return proc.returncode
        bench_dir = Path(json.loads(proc.stdout.strip().splitlines()[-1])["report"]).parent
        looks = ws / "libero"
        res = {"setting": yaml.safe_load((SETTINGS_DIR / f"{name}.yaml").read_text()) or {}, **score(bench_dir),
               "bench_dir": str(bench_dir), "elapsed_s": round(time.time() - t0, 1)}
        results[name] = res
        w = res["within"]
        rows.append([name, res["episodes"], res["first"], res["final"],
                     f"{w['libero_spatial']}/{w['libero_object']}/{w['libero_goal']}/{w['libero_10']}",
                     res["median_first_step"], res["false_successes"]])
    print_table(["setting", "episodes", "LIBERO first", "final", "first within 220/280/300/520", "median first step",
                 "false successes"], rows)
    best = max(results, key=lambda n: (results[n]["first"], results[n]["final"],
                                       -(results[n]["median_first_step"] or 1e9)))
    write_json(args.out or results_path("libero_defaults_sweep"),
               {"suite": "libero_90", "tasks": tasks, "seeds": args.seeds, "results": results, "best": best})
    best_path = results_path("libero_defaults_best", ".yaml")
    best_path.parent.mkdir(parents=True, exist_ok=True)
    best_path.write_text(f"# best setting of bench/libero_defaults_sweep.py on LIBERO-90 ({best})\n"
                         + yaml.safe_dump(results[best]["setting"], sort_keys=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
