"""LIBERO-PRO next to LIBERO: each perturbation family beside its standard suite, by LIBERO's checker.

    .venv/bin/python bench/libero_pro.py [--suites libero_object,libero_object_swap,...] [--tasks 0-9]
        [--seeds 0] [--workers 1] [--heartbeat-timeout 180] [--workspace ws/libero_pro]
        [--out bench/results/libero_pro.json] [--merge]
    .venv/bin/python bench/libero_pro.py --check-builds [--suites ...]   # every family builds?

Every suite runs through the same command a user types, ``phyagentos bench <suite> --json``
(one subprocess per suite, one shared workspace so the looks of the categories are measured
once), and is judged by LIBERO's own checker (``env.check_success()`` in each session's
``ground_truth.yaml``). All suite names are checked before anything is built (exit 2 with the
valid names). Per suite:

- ``planned`` / ``refused``: chosen tasks whose instruction the Goal Planner's rules planned
  or refused (with the reason; a refused task's episodes count as failures, as LIBERO counts
  every task), written by the bench into ``<workspace>/libero/<suite>/planning.yaml``;
- ``first`` / ``final``: LIBERO's successes over all chosen episodes (tasks x init states):
  its signal at the end of a session before any recovery session / at the end of any session;
- ``drop_first_pts`` / ``drop_final_pts``: the standard suite's rate minus this suite's, in
  percentage points (positive: worse than standard), when the standard suite is in the run;
- ``not_runnable``: chosen tasks the suite ships no init state for (``libero_10_with_milk``'s
  tasks 3 and 4: LIBERO-PRO's files hold none), counted as failures above, as LIBERO counts
  every task; and ``on_tasks_run``: where there are some, the same drops over the tasks the
  suite can run only, each against the standard suite's same task (matched by LIBERO's task
  name less its scene prefix; absent when one does not match): ``tasks``, ``first_pct``,
  ``final_pct``, ``standard_first_pct``, ``standard_final_pct``, ``drop_first_pts``,
  ``drop_final_pts``;
- ``unsettled``: the episodes whose init state did not hold still ({episode: {object: m}}, the
  objects whose ground position moved more than 10 cm over LIBERO's settle steps,
  ``init_settle`` in each session's ``ground_truth.yaml``: some of LIBERO-PRO's init states
  put two objects in one place and the settle throws them apart, a bowl off the table), and
  ``at_rest``: ``episodes``, ``first`` and ``final`` over the rest; with the standard suite in
  the run, ``drop_first_pts`` / ``drop_final_pts`` of those against the standard's own at
  rest (a comparison beside the plain drop, which counts every episode as LIBERO does);
- ``false_successes`` / ``false_failures``: episodes whose final verdict (ours: every node's
  last session succeeded) says success where LIBERO's checker at the episode's end says no,
  and the reverse (an episode is comparable only at its end: a pick session's own success is
  not the task's);
- ``wall_s``: the suite's wall time.

``--check-builds`` instead builds one world per suite (task 0, init state 0: LIBERO's reset,
the init state, the settle steps) and reports whether the init states load and the world
builds, the seconds, and how far each object starts from where it starts in the standard
suite's same task (horizontal, m; tasks matched by name; an object moved more than 5 m was
parked out of the scene by LIBERO-PRO); a suite that cannot be run is a row with the reason;
writes
``bench/results/libero_pro_builds.json``.

Anchors (not run here; the numbers issue 29 quotes from LIBERO-PRO, arXiv 2510.03827): VLAs
score 0.0 under task perturbations; pi0.5 keeps 0.38 / 0.20 / 0.08 / 0.17 of its success under
object-position perturbations. Prints a table and writes the JSON.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import yaml
from _harness import parser, print_table, results_path, write_json

from phyagentos.bench import parse_seeds
from phyagentos.errors import TargetError, format_choices
from phyagentos.targets.libero.catalog import (
    SUITES,
    available_suites,
    perturbation_family,
    unavailable_suites,
)

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

#: What a default run measures: libero_object and one suite of each family it has.
DEFAULT_SUITES = ("libero_object", "libero_object_swap", "libero_object_object", "libero_object_with_mug",
                  "libero_object_lan", "libero_object_temp_x0.1")
#: Issue 29's anchors from LIBERO-PRO (arXiv 2510.03827), quoted, not measured here.
ANCHORS = {"vla_task_perturbation_success": 0.0,
           "pi05_position_perturbation_kept_fraction": [0.38, 0.20, 0.08, 0.17],
           "source": "LIBERO-PRO (Zhou et al. 2025, arXiv 2510.03827) as quoted by issue 29; not run here"}
EXIT_BAD_INPUT = 2


def _check_suites(names: list[str]) -> list[str]:
    try:
        ok = set(available_suites()) | set(SUITES)
        why = unavailable_suites()
    except TargetError as exc:
        return [str(exc)]
    problems = []
    for n in names:
        if n in why:
            problems.append(f"{n}: cannot be run: {why[n]}")
        elif n not in ok:
            problems.append(f"unknown LIBERO suite {n!r}; valid: {format_choices(ok)}")
    return problems


def task_stem(name: str) -> str:
    """A LIBERO task name less its scene prefix, "pick the" read as "pick up the": how a
    perturbed suite's task is matched to its standard suite's (``FLOOR_SCENE1_put_both_moka_pots_on_the_stove``
    and ``KITCHEN_SCENE8_put_both_moka_pots_on_the_stove``)."""
    return re.sub(r"^[A-Z_]+SCENE\d+_", "", name).replace("pick_the_", "pick_up_the_")


def _tasks_of(suite: str, tasks: list[int]) -> tuple[dict[str, str], list[int]]:
    """``({"t<i>": task stem}, [tasks with no init state])`` for the chosen tasks of ``suite``."""
    from phyagentos.targets.libero import load_init_states, resolve_task  # noqa: PLC0415

    stems, empty = {}, []
    for i in tasks:
        task = resolve_task(suite, i)
        stems[f"t{i}"] = task_stem(task.name)
        try:
            load_init_states(task)
        except TargetError:
            empty.append(i)
    return stems, empty


def at_rest(episodes: list[dict]) -> tuple[dict[str, dict[str, float]], dict[str, int]]:
    """``(unsettled, at_rest)`` of a bench run's episode rows (``report.json``): the episodes
    whose init state did not hold still ({episode id: {object: m moved}}, from each episode's
    ``init_settle``) and ``{"episodes", "first", "final"}`` counted over the others (an episode
    without a settle record counts as at rest)."""
    unsettled = {e["episode_id"]: dict((e.get("init_settle") or {}).get("moved_m") or {}) for e in episodes
                 if (e.get("init_settle") or {}).get("moved_m")}
    rest = [e for e in episodes if e["episode_id"] not in unsettled]
    return unsettled, {"episodes": len(rest), "first": sum(1 for e in rest if e.get("env_first_success")),
                       "final": sum(1 for e in rest if e.get("env_final_success"))}


def on_tasks_run(row: dict, standard: dict) -> dict | None:
    """The drops of perturbed suite ``row`` against ``standard`` (both :func:`run_suite` rows,
    percentages over ``seeds`` init states per task) over the tasks ``row`` can run only, each
    matched to the standard task of the same :func:`task_stem`; None when ``row`` can run
    every chosen task, or when one of its tasks has no match. A refused task counts as a
    failure here too: only a task with no init state to run is left out."""
    if not row.get("not_runnable"):
        return None
    by_stem = {v: k for k, v in standard.get("task_names", {}).items()}
    run = [k for k in row.get("task_names", {}) if int(k[1:]) not in row["not_runnable"]]
    pairs = [(k, by_stem.get(row["task_names"][k])) for k in run]
    if not pairs or any(ref is None for _, ref in pairs):
        return None
    n = len(pairs) * int(row["seeds"])

    def rate(r: dict, keys: list[str], what: str) -> float:
        return _pct(sum(r.get("per_task", {}).get(k, {}).get(what, 0) for k in keys), n)

    mine, ref = [k for k, _ in pairs], [k for _, k in pairs]
    out = {"tasks": len(pairs), "first_pct": rate(row, mine, "first"), "final_pct": rate(row, mine, "final"),
           "standard_first_pct": rate(standard, ref, "first"), "standard_final_pct": rate(standard, ref, "final")}
    out["drop_first_pts"] = round(out["standard_first_pct"] - out["first_pct"], 1)
    out["drop_final_pts"] = round(out["standard_final_pct"] - out["final_pct"], 1)
    return out


def _episode_rows(report_json: Path) -> list[dict]:
    return json.loads(report_json.read_text(encoding="utf-8"))["episodes"]


def _refusals(suite: str, tasks: list[int]) -> dict[int, str]:
    """``{task: reason}`` for the chosen tasks whose instruction the Goal Planner's rules refuse
    (the instruction and the declared objects only; nothing is built)."""
    from phyagentos.bench.libero import instruction_nodes  # noqa: PLC0415
    from phyagentos.errors import BenchError  # noqa: PLC0415
    from phyagentos.targets.libero import parse_bddl, resolve_task  # noqa: PLC0415

    out = {}
    for i in tasks:
        task = resolve_task(suite, i)
        problem = parse_bddl(task.bddl_path)
        try:
            instruction_nodes(task.instruction, problem.objects, problem.fixtures)
        except BenchError as exc:
            out[i] = f"task {i} ({task.instruction}): {exc}"
    return out


def run_suite(suite: str, workspace: Path, tasks: str, seeds: str, *, timeout_s: float, workers: int = 1,
              heartbeat_timeout_s: float = 180) -> dict:
    """One ``phyagentos bench <suite> --json`` run and its row (see the module docstring).

    ``workers`` episodes run at once (the bench's ``--workers``); ``heartbeat_timeout_s`` is the
    bench's ``--heartbeat-timeout`` in s (raise it on a loaded machine, where a runner's beat lags).
    """
    base, family, kind = perturbation_family(suite)
    n_tasks = len(tasks.split(","))
    n_seeds = len(parse_seeds(seeds))
    cmd = [sys.executable, "-m", "phyagentos.cli", "bench", suite, "--workspace", str(workspace), "--tasks", tasks,
           "--seeds", seeds, "--json", "--workers", str(workers), "--heartbeat-timeout", f"{heartbeat_timeout_s:g}",
           "--queue-timeout", "3000"]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=timeout_s)
    wall = round(time.monotonic() - t0, 1)
    row = {"suite": suite, "standard": base, "family": family, "kind": kind, "tasks": n_tasks, "seeds": n_seeds,
           "episodes": n_tasks * n_seeds, "exit_code": proc.returncode, "wall_s": wall, "command": " ".join(cmd[1:])}
    row["task_names"], row["not_runnable"] = _tasks_of(suite, [int(t) for t in tasks.split(",")])
    planning_file = workspace / "libero" / suite / "planning.yaml"
    if proc.returncode == EXIT_BAD_INPUT:  # refused before anything ran: nothing planned, or an error
        refused = _refusals(suite, [int(t) for t in tasks.split(",")])
        if len(refused) < n_tasks:
            row["error"] = proc.stderr[-3000:]
            return row
        row.update(planned=0, refused=n_tasks, refusals=list(refused.values()),
                   first=0, final=0, episodes_run=0, false_successes=0, false_failures=0)
        return row
    if proc.returncode not in (0, 1):
        row["error"] = proc.stderr[-3000:]
        return row
    rep = json.loads(proc.stdout)
    planning = yaml.safe_load(planning_file.read_text(encoding="utf-8")) if planning_file.is_file() else {}
    episodes = _episode_rows(Path(rep["report"]).with_name("report.json"))
    row.update(planned=len(planning.get("planned", [])), refused=len(planning.get("refused", {})),
               refusals=list((planning.get("refused") or {}).values()), episodes_run=len(episodes),
               first=sum(1 for e in episodes if e.get("env_first_success")),
               final=sum(1 for e in episodes if e.get("env_final_success")),
               false_successes=sum(1 for e in episodes if e["final_success"] and e.get("env_success") is False),
               false_failures=sum(1 for e in episodes if not e["final_success"] and e.get("env_success")),
               harness_errors=len(rep.get("harness_errors") or []), report=rep["report"],
               **dict(zip(("unsettled", "at_rest"), at_rest(episodes))),
               per_task={t: {"first": v["first_successes"], "final": v["final_successes"], "episodes": v["episodes"]}
                         for t, v in rep["ground_truth"]["per_task"].items()})
    return row


#: A horizontal move beyond this (m) is an object LIBERO-PRO parked out of the scene.
PARKED_M = 5.0
#: Every libero_object family the installed catalogue ships, for --check-builds.
BUILD_SUITES = ("libero_object_swap", "libero_object_object", "libero_object_lan", "libero_object_task",
                "libero_object_with_mug", "libero_object_with_red_box", "libero_object_with_yellow_book",
                "libero_object_with_blue_stick", "libero_object_with_red_stick", "libero_object_with_diffpos_stick",
                *(f"libero_object_temp_{a}0.{k}" for a in "xy" for k in range(1, 6)))


def check_builds(suites: list[str], out: Path) -> int:
    """Build task 0 / init 0 of each suite and of its standard suite; see the module docstring."""
    import numpy as np  # noqa: PLC0415

    from phyagentos.targets.libero import (  # noqa: PLC0415
        LiberoScene,
        LiberoTarget,
        load_init_states,
        resolve_task,
        suite_tasks,
    )

    def build(suite: str, task: int) -> tuple[dict, float]:
        t0 = time.monotonic()
        with LiberoTarget("libero", LiberoScene(suite=suite, task=task, init=0), seed=0) as target:
            objs = {k: np.asarray(v["position"]) for k, v in target.ground_truth()["objects"].items()}
        return objs, round(time.monotonic() - t0, 1)

    standard: dict[tuple[str, str], dict] = {}
    rows = []
    for suite in suites:
        base = perturbation_family(suite)[0]
        if suite in unavailable_suites():
            rows.append({"suite": suite, "built": False, "error": f"not runnable: {unavailable_suites()[suite]}"})
            print(f"| {suite} | - | False | - | - | - | - | {rows[-1]['error']} |", flush=True)
            continue
        task = resolve_task(suite, 0)
        row = {"suite": suite, "task": task.name, "instruction": task.instruction}
        try:
            row["init_states"] = list(load_init_states(task).shape)
            objs, row["build_s"] = build(suite, 0)
            row["built"] = True
            ref_index = next((t.index for t in suite_tasks(base) if task_stem(t.name) == task_stem(task.name)), None)
            if ref_index is not None and base != suite:
                key = (base, str(ref_index))
                if key not in standard:
                    standard[key] = build(base, ref_index)[0]
                common = [k for k in objs if k in standard[key]]
                d = {k: float(np.linalg.norm(objs[k][:2] - standard[key][k][:2])) for k in common}
                # LIBERO-PRO parks an object the shifted one would overlap ~10 m away (out of the scene)
                parked = sorted(k for k, v in d.items() if v > PARKED_M)
                near = {k: v for k, v in d.items() if v <= PARKED_M}
                row["objects_compared"] = len(common)
                row["moved"] = {k: round(v, 3) for k, v in near.items() if v > 0.02}
                row["parked_out_of_scene"] = parked
                row["displacement_max_m"] = round(max(near.values()), 3) if near else None
        except Exception as exc:  # noqa: BLE001 - a report of what fails, per suite
            row.update(built=False, error=f"{type(exc).__name__}: {exc}"[:500])
        rows.append(row)
        print(f"| {suite} | {row.get('init_states')} | {row['built']} | {row.get('build_s', '-')} | "
              f"{row.get('moved', '-')} | {', '.join(row.get('parked_out_of_scene', [])) or '-'} | "
              f"{row.get('displacement_max_m', '-')} | {row.get('error', '')} |", flush=True)
    write_json(out, rows, indent=1)
    return 0 if all(r["built"] for r in rows) else 1


def _pct(n: int, d: int) -> float:
    return round(100.0 * n / d, 1) if d else 0.0


def main(argv: list[str] | None = None) -> int:
    ap = parser(__doc__, "libero_pro")
    ap.add_argument("--suites", default=",".join(DEFAULT_SUITES), help="comma-separated LIBERO / LIBERO-PRO suites")
    ap.add_argument("--tasks", default="0-9", help="LIBERO task indices, e.g. 0-9 or 0,3")
    ap.add_argument("--seeds", default="0", help="LIBERO init-state indices, e.g. 0 or 0-2")
    ap.add_argument("--workspace", type=Path, default=ROOT / "ws" / "libero_pro")
    ap.add_argument("--timeout", type=float, default=7200, help="seconds per suite")
    ap.add_argument("--workers", type=int, default=1, help="episodes at once per suite (the bench's --workers)")
    ap.add_argument("--heartbeat-timeout", type=float, default=180,
                    help="s without a runner's beat before its session is failed (the bench's option)")
    ap.add_argument("--check-builds", action="store_true", help="build one world per suite instead of running it")
    ap.add_argument("--merge", action="store_true", help="keep the rows of --out's other suites (same tasks and "
                                                         "seeds) and replace those run now")
    args = ap.parse_args(argv)
    if args.check_builds and args.suites == ",".join(DEFAULT_SUITES):
        args.suites = ",".join(BUILD_SUITES)
    suites = [s.strip() for s in args.suites.split(",") if s.strip()]
    problems = _check_suites(suites)
    if args.check_builds:  # a registered suite that cannot be run is a row of the report, not an error
        problems = [p for p in problems if "cannot be run" not in p]
    if problems:
        for p in problems:
            print(p, file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.check_builds:
        print_table(("suite", "init states", "built", "build s", "moved > 2 cm (m)", "parked out of the scene",
                     "max move m", "error"), [])
        return check_builds(suites, results_path("libero_pro_builds"))
    tasks = ",".join(str(t) for t in parse_seeds(args.tasks))
    rows = []
    for suite in suites:
        print(f"{suite}: phyagentos bench {suite} --tasks {tasks} --seeds {args.seeds} ...", file=sys.stderr, flush=True)
        rows.append(run_suite(suite, args.workspace, tasks, args.seeds, timeout_s=args.timeout, workers=args.workers,
                              heartbeat_timeout_s=args.heartbeat_timeout))
    if args.merge and args.out.is_file():
        before = json.loads(args.out.read_text(encoding="utf-8"))
        if (before.get("tasks"), before.get("seeds")) == (tasks, args.seeds):
            now = {r["suite"] for r in rows}
            rows = [r for r in before["suites"] if r["suite"] not in now] + rows
    standard = {r["suite"]: r for r in rows if r["kind"] == "standard"}
    for r in rows:  # every row's rates first: a standard run now comes after the rows --merge kept
        r["first_pct"], r["final_pct"] = _pct(r.get("first", 0), r["episodes"]), _pct(r.get("final", 0), r["episodes"])
    for r in rows:
        ref = standard.get(r["standard"])
        if ref is not None and r is not ref:
            r["drop_first_pts"] = round(ref["first_pct"] - r["first_pct"], 1)
            r["drop_final_pts"] = round(ref["final_pct"] - r["final_pct"], 1)
            matched = on_tasks_run(r, ref)
            if matched is not None:
                r["on_tasks_run"] = matched
            mine, theirs = r.get("at_rest"), ref.get("at_rest")
            if mine and theirs and mine["episodes"] and theirs["episodes"]:
                for what in ("first", "final"):
                    mine[f"drop_{what}_pts"] = round(_pct(theirs[what], theirs["episodes"])
                                                     - _pct(mine[what], mine["episodes"]), 1)
    out = {"tasks": tasks, "seeds": args.seeds, "workspace": str(args.workspace), "suites": rows, "anchors": ANCHORS}
    write_json(args.out, out, indent=1, say=False)
    head = ("suite", "family", "planned/refused", "First", "Final", "drop First/Final (pts)",
            "on the tasks it can run", "on inits at rest", "false succ.", "false fail.", "wall s")
    table = []
    for r in rows:
        drop = (f"{r['drop_first_pts']:+.1f} / {r['drop_final_pts']:+.1f}" if "drop_first_pts" in r else "-")
        m = r.get("on_tasks_run")
        run = (f"{m['tasks']} tasks: {m['drop_first_pts']:+.1f} / {m['drop_final_pts']:+.1f}" if m
               else f"no init states: tasks {', '.join(map(str, r['not_runnable']))}" if r.get("not_runnable") else "-")
        a = r.get("at_rest") or {}
        rest = (f"{a['first']}/{a['final']} of {a['episodes']}"
                + (f": {a['drop_first_pts']:+.1f} / {a['drop_final_pts']:+.1f}" if "drop_first_pts" in a else "")
                if a else "-")
        table.append((r["suite"], f"{r['family']} ({r['kind']})", f"{r.get('planned', '?')}/{r.get('refused', '?')}",
                      f"{r.get('first', '?')}/{r['episodes']} ({r['first_pct']:.0f}%)",
                      f"{r.get('final', '?')}/{r['episodes']} ({r['final_pct']:.0f}%)", drop, run, rest,
                      r.get("false_successes", "?"), r.get("false_failures", "?"), f"{r['wall_s']:.0f}"))
    print_table(head, table)
    print(f"anchors ({ANCHORS['source']}): VLAs under task perturbations {ANCHORS['vla_task_perturbation_success']}; "
          f"pi0.5 keeps {ANCHORS['pi05_position_perturbation_kept_fraction']} under position perturbations")
    print(f"wrote {args.out}")
    return 1 if any("error" in r for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
