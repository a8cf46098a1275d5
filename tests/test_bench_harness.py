"""The benchmark harness runs episodes through the ordinary session path and reports from session files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from phyagentos.bench import load_suite, parse_seeds, run_bench
from phyagentos.bench.compiler import plan_episodes
from phyagentos.errors import BenchError
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

CLI = [sys.executable, "-m", "phyagentos.cli"]


def write_suite(path: Path, *, rate: float = 0.0, kinds=(), tasks=None) -> Path:
    tasks = tasks or [
        {"id": "pick_and_place", "goal_graph": str(goal_graphs_dir() / "pick_and_place.yaml"),
         "randomize": [{"names": ["cube"], "xy": [0.05, 0.05], "yaw": 0.5}]},
        {"id": "put_in_bin", "goal_graph": str(goal_graphs_dir() / "put_in_bin.yaml"),
         "randomize": [{"names": ["cube"], "xy": [0.04, 0.04]}]},
    ]
    suite = {"version": 1, "name": "mini", "episodes": 2, "perturbations": {"rate": rate, "kinds": list(kinds)},
             "tasks": tasks}
    path.write_text(yaml.safe_dump(suite), encoding="utf-8")
    return path


def session_files(root: Path) -> list[Path]:
    return sorted(root.rglob("sessions/*.md"))


def test_gate_rejects_a_disabled_target_with_a_diagnostic_and_compiles_no_episode(tmp_path):
    ws = Workspace.create(tmp_path / "ws")

    def disable(doc):
        for t in doc.targets:
            t.enabled = False

    ws.update("TARGETS", disable)
    suite = write_suite(tmp_path / "mini.yaml")
    with pytest.raises(BenchError) as err:
        run_bench(suite, ws.root, episodes=2, workers=1)
    problems = err.value.problems
    assert any("franka_tabletop" in p and "disabled" in p for p in problems), problems
    assert any(p.startswith("[preflight]") and "preflight.target_disabled" in p for p in problems), problems
    (run_dir,) = (ws.root / "bench").iterdir()
    gate = yaml.safe_load((run_dir / "gate.yaml").read_text())
    assert gate["ok"] is False
    assert not (run_dir / "episodes").exists()
    assert session_files(ws.root) == []


def test_gate_failure_is_exit_code_2_on_the_command_line(tmp_path):
    suite = write_suite(tmp_path / "mini.yaml", tasks=[
        {"id": "pick_and_place", "goal_graph": str(goal_graphs_dir() / "pick_and_place.yaml"), "target": "ur5_cell"}])
    proc = subprocess.run([*CLI, "bench", str(suite), "--workspace", str(tmp_path / "ws"), "--episodes", "1"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "availability gate failed" in proc.stderr
    assert "ur5_cell" in proc.stderr and "TARGETS.md" in proc.stderr
    assert session_files(tmp_path / "ws") == []


def test_episode_plan_is_a_pure_function_of_suite_task_and_seed(tmp_path):
    suite = load_suite(write_suite(tmp_path / "mini.yaml", rate=0.5, kinds=("adjacent_box", "heavy_object")))
    a = plan_episodes(suite, bench_id="b1", seeds=(0, 1, 2, 3), split="measurement", memory="frozen",
                      protocol="measurement")
    b = plan_episodes(suite, bench_id="b2", seeds=(0, 1, 2, 3), split="measurement", memory="frozen",
                      protocol="measurement")
    assert [e.scene for e in a] == [e.scene for e in b]
    assert [e.evaluation["perturbation"] for e in a] == [e.evaluation["perturbation"] for e in b]
    cubes = [next(o["position"] for o in e.scene["objects"] if o["name"] == "cube") for e in a]
    assert len({tuple(c) for c in cubes}) == len(cubes)  # every seed draws its own initial state


def test_parse_seeds_accepts_ranges_and_lists_and_rejects_garbage():
    assert parse_seeds("0-3,7") == (0, 1, 2, 3, 7)
    for bad in ("a", "3-1", "1,1", ""):
        with pytest.raises(BenchError):
            parse_seeds(bad)


def test_suite_with_an_unknown_perturbation_is_rejected_with_the_valid_choices(tmp_path):
    with pytest.raises(BenchError, match="unknown perturbation 'gremlins'.*adjacent_box"):
        load_suite(write_suite(tmp_path / "bad.yaml", rate=0.5, kinds=("gremlins",)))


@pytest.mark.sim
def test_small_suite_report_traces_every_number_to_the_session_files(tmp_path):
    # 2 tasks x 2 seeds on 2 workers; every episode gets a box next to the cube, so
    # genuine failures (and verifier-triggered child sessions) appear in the evidence.
    suite = write_suite(tmp_path / "mini.yaml", rate=1.0, kinds=("adjacent_box",), tasks=[
        {"id": "pick_and_place", "goal_graph": str(goal_graphs_dir() / "pick_and_place.yaml"),
         "randomize": [{"names": ["cube"], "xy": [0.05, 0.05], "yaw": 0.5}]},
        {"id": "put_in_bin", "goal_graph": str(goal_graphs_dir() / "put_in_bin.yaml")},
    ])
    # A runner starved of CPU for the default heartbeat timeout (a loaded CI machine) ends
    # its session as a heartbeat timeout, which the report rightly keeps out of the episodes
    # (not a robot outcome); this test is about the report, so it gives the runners time.
    result = run_bench(suite, tmp_path / "ws", seeds=(0, 1), workers=2, memory="frozen", heartbeat_timeout_s=120.0)
    rep = json.loads((result.run_dir / "report.json").read_text())
    assert rep["heartbeat_timeouts"]["episodes"] == []
    assert rep["overall"]["episodes"] == 4 and rep["harness_errors"] == []
    assert (result.run_dir / "report.md").is_file() and (result.run_dir / "first_vs_final.png").stat().st_size > 1000

    first = final = 0
    all_ids = set()
    for ep in rep["episodes"]:
        ws = Workspace.open(result.run_dir / ep["directory"])
        records = {s.session_id: s for s in ws.list_sessions()}
        assert {s["session_id"] for s in ep["sessions"]} == set(records)
        all_ids |= set(records)
        for s in ep["sessions"]:
            rec = records[s["session_id"]]
            assert (result.run_dir / s["file"]).is_file()
            assert s["state"] == rec.state and rec.evaluation["episode"] == ep["episode_id"]
            assert rec.evaluation["seed"] == ep["seed"]
            assert rec.seed == ep["seed"] + [n.id for n in ws.read("TASK").data.nodes].index(rec.node)
        # First / Final recomputed from the session files themselves
        nodes = [n.id for n in ws.read("TASK").data.nodes]
        roots_ok = all(any(r.node == n and r.parent_session_id is None and r.state == "succeeded" for r in records.values())
                       for n in nodes)
        latest_ok = all(max((r for r in records.values() if r.node == n), key=lambda r: int(r.session_id.rsplit("-", 1)[1])).state
                        == "succeeded" for n in nodes if any(r.node == n for r in records.values())) and \
            all(any(r.node == n for r in records.values()) for n in nodes)
        assert ep["first_success"] == roots_ok and ep["final_success"] == latest_ok
        first += roots_ok
        final += latest_ok
    assert rep["overall"]["first_successes"] == first and rep["overall"]["final_successes"] == final
    assert rep["overall"]["first_rate_pct"] == pytest.approx(100.0 * first / 4)
    failed = [sid for t in rep["error_taxonomy"].values() for sid in t["sessions"]]
    assert failed, "the perturbed episodes should leave at least one unsuccessful session"
    for category, t in rep["error_taxonomy"].items():
        assert t["count"] == len(t["sessions"])
        assert set(t["sessions"]) <= all_ids
    states = {s["session_id"]: s["state"] for ep in rep["episodes"] for s in ep["sessions"]}
    assert all(states[sid] != "succeeded" for sid in failed)
    md = (result.run_dir / "report.md").read_text()
    for ep in rep["episodes"]:
        for s in ep["sessions"]:
            assert s["file"] in md
