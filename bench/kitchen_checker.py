"""FrankaKitchen: per-task success by the environment's own checker next to our verdict, and
whether the seeds really differ.

    .venv/bin/python bench/kitchen_checker.py RUN_DIR [RUN_DIR ...] [--out bench/results/kitchen_checker.json]

RUN_DIR is a finished ``phyagentos bench kitchen`` run directory
(``<workspace>/bench/<bench_id>/``). For every episode this reads, from the last session's
``ground_truth.yaml`` (scoring only: the Agent plane never sees it), the environment's own
completion signal (gymnasium-robotics ``info['episode_task_completions']``), the step it
completed at, the environment steps used, and the initial and terminal microwave angle and
kettle position; next to it the SessionVerifier's verdict from the session file. The
spread of those values over seeds says whether the episodes are one trajectory or many.
Episodes ended by a heartbeat or queue timeout (machine load) are marked ``*`` and left out
of the per-task counts. Prints two tables and writes the JSON.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

from _harness import parser, write_json

from phyagentos.bench.report import load_report
from phyagentos.errors import BenchError
from phyagentos.yamlsource import read_yaml


def _gt(run_dir: Path, evidence: str | None) -> dict:
    if not evidence:
        return {}
    path = run_dir / evidence / "ground_truth.yaml"
    return (read_yaml(path, error=BenchError) or {}) if path.is_file() else {}


def episode_rows(run_dir: Path) -> list[dict]:
    """One row per episode of a kitchen bench run (see the module docstring)."""
    rep = load_report(run_dir)
    rows = []
    for ep in rep["episodes"]:
        last = max(ep["sessions"], key=lambda s: s["generation"]) if ep["sessions"] else None
        first = min(ep["sessions"], key=lambda s: s["generation"]) if ep["sessions"] else None
        gt_last = _gt(run_dir, last and last["evidence"])
        gt_first = _gt(run_dir, first and first["evidence"])
        init, term = gt_first.get("initial") or {}, gt_last.get("terminal") or {}
        bench = term.get("benchmark") or {}
        rows.append({
            "bench_id": rep["bench_id"], "episode_id": ep["episode_id"], "task": ep["task"], "seed": ep["seed"],
            "verdict": last and last["verdict"], "final_success": ep["final_success"],
            "first_success": ep["first_success"], "env_success": bench.get("success"),
            "completed_at_step": (bench.get("completed_at_step") or {}).get(ep["task"]),
            "env_steps": bench.get("env_steps"), "sessions": ep["n_sessions"],
            # ended by a heartbeat or queue timeout (machine load): not scored, counted apart
            "load_timeout": bool(ep.get("heartbeat_timeout_sessions")),
            "microwave_rad_initial": ((init.get("articulations") or {}).get("microwave") or {}).get("joint_position"),
            "microwave_rad_terminal": ((term.get("articulations") or {}).get("microwave") or {}).get("joint_position"),
            "kettle_xyz_initial": ((init.get("objects") or {}).get("kettle") or {}).get("position"),
            "kettle_xyz_terminal": ((term.get("objects") or {}).get("kettle") or {}).get("position"),
        })
    return rows


def _spread(values) -> dict:
    v = [float(x) for x in values if x is not None]
    if not v:
        return {"n": 0}
    return {"n": len(v), "distinct": len(set(v)), "min": min(v), "max": max(v),
            "stdev": statistics.pstdev(v) if len(v) > 1 else 0.0}


def summarise(rows: list[dict]) -> dict:
    """Per task: episodes, env successes, our Final, agreements, and the spread over seeds."""
    out = {}
    for task in sorted({r["task"] for r in rows}):
        lost = [r for r in rows if r["task"] == task and r["load_timeout"]]
        rs = [r for r in rows if r["task"] == task and not r["load_timeout"]]
        out[task] = {
            "episodes": len(rs), "seeds": sorted(r["seed"] for r in rs),
            "load_timeouts_not_scored": sorted(r["seed"] for r in lost),
            "verdict_success_env_success": sum(1 for r in rs if r["verdict"] == "success" and r["env_success"]),
            "verdict_success_env_failure": sum(1 for r in rs if r["verdict"] == "success" and not r["env_success"]),
            "verdict_other_env_success": sum(1 for r in rs if r["verdict"] != "success" and r["env_success"]),
            "verdict_other_env_failure": sum(1 for r in rs if r["verdict"] != "success" and not r["env_success"]),
            "env_successes": sum(1 for r in rs if r["env_success"]),
            "our_final_successes": sum(1 for r in rs if r["final_success"]),
            "our_first_successes": sum(1 for r in rs if r["first_success"]),
            "agreements": sum(1 for r in rs if bool(r["env_success"]) == (r["verdict"] == "success")),
            "env_steps": _spread(r["env_steps"] for r in rs),
            "completed_at_step": _spread(r["completed_at_step"] for r in rs),
            "microwave_rad_initial": _spread(r["microwave_rad_initial"] for r in rs),
            "microwave_rad_terminal": _spread(r["microwave_rad_terminal"] for r in rs),
            "kettle_x_initial": _spread((r["kettle_xyz_initial"] or [None])[0] for r in rs),
            "kettle_x_terminal": _spread((r["kettle_xyz_terminal"] or [None])[0] for r in rs),
        }
    return out


def main() -> int:
    ap = parser(__doc__, "kitchen_checker")
    ap.add_argument("runs", nargs="+", type=Path, help="kitchen bench run directories")
    args = ap.parse_args()
    rows = [r for run in args.runs for r in episode_rows(run)]
    summary = summarise(rows)
    print(f"{'task':<10}{'episodes':>9}{'env checker':>13}{'our Final':>11}{'our First':>11}{'agree':>7}"
          f"{'distinct env_steps':>20}{'distinct terminal':>19}{'load timeouts':>15}")
    for task, s in summary.items():
        key = "microwave_rad_terminal" if task == "microwave" else "kettle_x_terminal"
        print(f"{task:<10}{s['episodes']:>9}{s['env_successes']:>13}{s['our_final_successes']:>11}"
              f"{s['our_first_successes']:>11}{s['agreements']:>7}{s['env_steps'].get('distinct', 0):>20}"
              f"{s[key].get('distinct', 0):>19}{len(s['load_timeouts_not_scored']):>15}")
    print(f"\n{'episode':<18}{'verdict':>9}{'env':>7}{'done@':>7}{'steps':>7}{'microwave rad':>16}{'kettle x m':>14}")
    for r in sorted(rows, key=lambda r: (r["task"], r["seed"])):
        kx = (r["kettle_xyz_terminal"] or [None])[0]
        mw = r["microwave_rad_terminal"]
        print(f"{r['episode_id'] + (' *' if r['load_timeout'] else ''):<18}{str(r['verdict']):>9}"
              f"{str(r['env_success']):>7}{str(r['completed_at_step']):>7}"
              f"{str(r['env_steps']):>7}{'-' if mw is None else f'{mw:.9f}':>16}{'-' if kx is None else f'{kx:.6f}':>14}")
    write_json(args.out, {"benchmark": "kitchen_checker", "runs": [str(r) for r in args.runs],
                          "per_task": summary, "episodes": rows}, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
