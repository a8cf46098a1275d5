"""Benchmark suites through `phyagentos bench`: First vs Final, external ground truth, embodiments, throughput.

    .venv/bin/python bench/bench_suites.py [--only tabletop kitchen so101 throughput] [--workspace DIR]

Each measurement is one ``phyagentos.bench.run_bench`` call (the same path as the CLI
``phyagentos bench SUITE --workspace DIR ...``) and leaves its full report (Markdown,
JSON, plots, every episode's sessions and evidence) under ``DIR/bench/<bench_id>/``:

- ``tabletop``: 13 episodes x 4 tasks (52) on 2 workers, frozen memory, measurement
  seeds 0-12, 30 % of episodes perturbed: First, Final, gain in points, rescued.
- ``kitchen``: FrankaKitchen microwave and kettle, 10 episodes each: our Final next to
  the environment's own success signal, and their disagreements.
- ``so101``: the same pick-and-place graph on the SO-101 and on the Franka, 10 each.
- ``throughput``: the tabletop suite, 8 episodes x 4 tasks, with 1 and with 2 workers:
  episodes per minute (execution phase) and the 2-worker / 1-worker ratio.
- ``adaptation``: an adaptation pass (``--memory learn``, measurement seeds) followed by a
  frozen measurement on the held-out seeds with the memory it consolidated, next to the
  same held-out measurement from empty memory.

Prints a table and updates bench/results/bench_suites.json (numbers plus the report
paths they come from; measurements not run keep their previous entry).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

from _harness import parser, write_json
from rich.console import Console
from rich.table import Table

from phyagentos.bench import run_bench

MEASUREMENTS = ("tabletop", "kitchen", "so101", "throughput", "adaptation")


def _summary(result) -> dict:
    rep = result.report
    return {
        "report": str(result.run_dir / "report.md"),
        "bench_id": rep["bench_id"],
        "episodes_per_minute": rep["episodes_per_minute"],
        "execute_s": rep["execute_s"],
        "overall": {k: rep["overall"][k] for k in ("episodes", "first_rate_pct", "final_rate_pct", "gain_points",
                                                   "rescued", "rescued_episodes", "failed_episodes")},
        "per_task": {t: {k: s[k] for k in ("episodes", "first_rate_pct", "final_rate_pct", "gain_points", "rescued")}
                     for t, s in rep["per_task"].items()},
        "error_taxonomy": {c: t["count"] for c, t in rep["error_taxonomy"].items() if t["count"]},
        "ground_truth": {k: rep["ground_truth"][k] for k in ("sessions", "agreements", "per_task")},
        "disagreements": rep["ground_truth"]["disagreements"],
        "harness_errors": len(rep["harness_errors"]),
    }


def main() -> int:
    ap = parser(__doc__, "bench_suites")
    ap.add_argument("--only", nargs="*", choices=MEASUREMENTS, help="subset of the measurements")
    ap.add_argument("--workspace", type=Path, help="bench workspace (default: a temporary directory)")
    args = ap.parse_args()
    todo = args.only or list(MEASUREMENTS)
    root = args.workspace or Path(tempfile.mkdtemp(prefix="phyagentos-bench-"))
    out: dict = {"workspace": str(root)}
    console = Console()
    t0 = time.perf_counter()
    if "tabletop" in todo:
        out["tabletop"] = _summary(run_bench("tabletop", root / "tabletop", episodes=13, workers=2, memory="frozen"))
    if "kitchen" in todo:
        out["kitchen"] = _summary(run_bench("kitchen", root / "kitchen", episodes=10, workers=2, memory="frozen"))
    if "so101" in todo:
        out["so101"] = _summary(run_bench("so101", root / "so101", episodes=10, workers=2, memory="frozen"))
    if "throughput" in todo:
        one = run_bench("tabletop", root / "throughput", episodes=8, workers=1, memory="frozen")
        two = run_bench("tabletop", root / "throughput", episodes=8, workers=2, memory="frozen")
        out["throughput"] = {
            "episodes": one.report["overall"]["episodes"],
            "workers_1": {"episodes_per_minute": one.report["episodes_per_minute"], "execute_s": one.report["execute_s"],
                          "report": str(one.run_dir / "report.md")},
            "workers_2": {"episodes_per_minute": two.report["episodes_per_minute"], "execute_s": two.report["execute_s"],
                          "report": str(two.run_dir / "report.md")},
            "ratio_2_to_1": round(two.report["episodes_per_minute"] / one.report["episodes_per_minute"], 3),
        }
    if "adaptation" in todo:
        learn = run_bench("tabletop", root / "adaptation", episodes=13, workers=2, memory="learn")
        after = run_bench("tabletop", root / "adaptation", episodes=13, workers=2, memory="frozen", split="heldout")
        empty = run_bench("tabletop", root / "adaptation_empty", episodes=13, workers=2, memory="frozen", split="heldout")
        out["adaptation"] = {name: {"protocol": r.report["protocol"], "memory": r.report["memory"],
                                    "split": r.report["split"], "report": str(r.run_dir / "report.md"),
                                    **{k: r.report["overall"][k] for k in ("episodes", "first_rate_pct",
                                                                           "final_rate_pct", "rescued")}}
                             for name, r in (("learn_pass", learn), ("heldout_after_learning", after),
                                             ("heldout_empty_memory", empty))}
    out["wall_time_s"] = round(time.perf_counter() - t0, 1)

    table = Table(title="phyagentos bench: suites")
    for col in ("measurement", "episodes", "First", "Final", "gain", "rescued", "notes"):
        table.add_column(col, no_wrap=col == "measurement")
    for name in ("tabletop", "kitchen", "so101"):
        if name not in out:
            continue
        s = out[name]
        for task, pt in [*s["per_task"].items(), ("overall", s["overall"])]:
            note = ""
            gt = s["ground_truth"]["per_task"].get(task)
            if gt and gt["episodes"]:
                note = f"env success {gt['env_successes']}/{gt['episodes']}"
            table.add_row(f"{name}/{task}", str(pt["episodes"]), f"{pt['first_rate_pct']:.1f}%",
                          f"{pt['final_rate_pct']:.1f}%", f"{pt['gain_points']:+.1f}", str(pt["rescued"]), note)
    for name, a in out.get("adaptation", {}).items():
        table.add_row(f"adaptation/{name}", str(a["episodes"]), f"{a['first_rate_pct']:.1f}%",
                      f"{a['final_rate_pct']:.1f}%", "", str(a["rescued"]), f"{a['memory']} memory, {a['split']} seeds")
    if "throughput" in out:
        t = out["throughput"]
        table.add_row("throughput", str(t["episodes"]), "", "", "", "",
                      f"1 worker {t['workers_1']['episodes_per_minute']:.1f}/min, 2 workers "
                      f"{t['workers_2']['episodes_per_minute']:.1f}/min, ratio {t['ratio_2_to_1']:.2f}")
    console.print(table)
    path = args.out
    merged = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    merged.update(out)
    write_json(path, merged, indent=1)
    console.print(f"reports under {root}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
