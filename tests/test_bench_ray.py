"""`--executor ray`: the same episodes, run as tasks on a local Ray instance."""

from __future__ import annotations

import json

import pytest
import yaml

from phyagentos.bench import run_bench
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

pytestmark = pytest.mark.sim


def test_ray_executor_runs_the_episodes_through_the_same_session_path(tmp_path):
    suite = tmp_path / "mini.yaml"
    suite.write_text(yaml.safe_dump({"version": 1, "name": "mini", "episodes": 2, "tasks": [
        {"id": "put_in_bin", "goal_graph": str(goal_graphs_dir() / "put_in_bin.yaml")}]}))
    # Ray's own processes share the two cores with the suite's workers: beside four CPU hogs
    # a runner went silent longer than the default heartbeat timeout (10 s) and both episodes
    # ended `heartbeat.runner`, which the report rightly counts apart. As in
    # test_bench_harness, the sessions get a heartbeat timeout sized for a loaded machine.
    result = run_bench(suite, tmp_path / "ws", workers=2, executor="ray", heartbeat_timeout_s=120.0)
    rep = json.loads((result.run_dir / "report.json").read_text())
    assert rep["executor"] == "ray" and rep["harness_errors"] == []
    assert rep["overall"]["episodes"] == 2
    for ep in rep["episodes"]:
        assert ep["worker"] and ep["sessions"]
        ws = Workspace.open(result.run_dir / ep["directory"])
        states = {s.session_id: s.state for s in ws.list_sessions()}
        assert {s["session_id"]: s["state"] for s in ep["sessions"]} == states
        assert all(state in ("succeeded", "failed", "replanned") for state in states.values()), states


def test_ray_workers_run_at_normal_priority_and_keep_the_gl_backend(monkeypatch):
    # Ray starts task workers at nice 15; an episode's supervisor and runner then starve beside
    # ordinary load (tests/test_bench_ray.py above: 308 s beside two busy loops, 57 s at nice 0).
    from phyagentos.bench.executor import _ray_env

    monkeypatch.setenv("MUJOCO_GL", "osmesa")
    env = _ray_env()
    assert env["RAY_worker_niceness"] == "0" and env["MUJOCO_GL"] == "osmesa"
