"""`phyagentos bench --heartbeat-timeout`: every session's runner heartbeat limit, and
heartbeat timeouts counted on their own row, never as robot successes or failures."""

from __future__ import annotations

import json

import pytest
import yaml

from phyagentos.bench import load_suite, run_bench
from phyagentos.bench.compiler import plan_episodes
from phyagentos.bench.episode import episode_graph_text
from phyagentos.cli import build_parser
from phyagentos.errors import BenchError
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir


def write_suite(path):
    suite = {"version": 1, "name": "mini", "episodes": 1, "tasks": [
        {"id": "pick_and_place", "goal_graph": str(goal_graphs_dir() / "pick_and_place.yaml")}]}
    path.write_text(yaml.safe_dump(suite), encoding="utf-8")
    return path


def test_heartbeat_timeout_flag_defaults_to_the_graphs_own_limit(tmp_path):
    parser = build_parser()
    assert parser.parse_args(["bench", "tabletop", "--workspace", str(tmp_path)]).heartbeat_timeout is None
    args = parser.parse_args(["bench", "tabletop", "--workspace", str(tmp_path), "--heartbeat-timeout", "45",
                              "--queue-timeout", "7200"])
    assert args.heartbeat_timeout == 45.0 and args.queue_timeout == 7200.0
    assert parser.parse_args(["bench", "tabletop", "--workspace", str(tmp_path)]).queue_timeout is None


def test_episode_limits_reach_every_node_of_the_episode_graph_and_nothing_else_changes(tmp_path):
    suite = load_suite(write_suite(tmp_path / "mini.yaml"))
    plain, = plan_episodes(suite, bench_id="b1", seeds=(3,), split="heldout", memory="off", protocol="measurement")
    raised, = plan_episodes(suite, bench_id="b1", seeds=(3,), split="heldout", memory="off", protocol="measurement",
                            limits={"heartbeat_timeout_s": 45.0})
    assert plain.limits == {} and raised.limits == {"heartbeat_timeout_s": 45.0}
    g0 = yaml.safe_load(episode_graph_text(plain))
    g1 = yaml.safe_load(episode_graph_text(raised))
    assert len(g1["nodes"]) == 2
    for n0, n1 in zip(g0["nodes"], g1["nodes"]):
        assert n1["limits"]["heartbeat_timeout_s"] == 45.0
        assert "heartbeat_timeout_s" not in (n0.get("limits") or {})
        assert {k: v for k, v in n1["limits"].items() if k != "heartbeat_timeout_s"} == (n0.get("limits") or {})
    assert g0["scene"] == g1["scene"]


def test_a_non_positive_heartbeat_timeout_is_refused_before_any_episode_is_compiled(tmp_path):
    with pytest.raises(BenchError, match="heartbeat_timeout_s must be > 0"):
        run_bench(write_suite(tmp_path / "mini.yaml"), tmp_path / "ws", seeds=(0,), heartbeat_timeout_s=0.0)
    with pytest.raises(BenchError, match="queue_timeout_s must be > 0"):
        run_bench(write_suite(tmp_path / "mini.yaml"), tmp_path / "ws", seeds=(0,), queue_timeout_s=-1.0)
    assert not list((tmp_path / "ws").rglob("episodes"))


@pytest.mark.sim
def test_sessions_ended_by_a_heartbeat_timeout_are_counted_apart_not_as_robot_failures(tmp_path):
    # A 1 ms heartbeat limit: the real supervisor ends the real runner's session on
    # heartbeat.runner long before the robot could succeed or fail.
    result = run_bench(write_suite(tmp_path / "mini.yaml"), tmp_path / "ws", seeds=(0,), workers=1,
                       memory="off", heartbeat_timeout_s=0.001)
    rep = json.loads((result.run_dir / "report.json").read_text())
    assert rep["session_limits"] == {"heartbeat_timeout_s": 0.001}
    ws = Workspace.open(result.run_dir / "episodes" / "pick_and_place-s0")
    records = ws.list_sessions()
    assert records and all(r.limits.heartbeat_timeout_s == 0.001 for r in records)
    ended = [r.session_id for r in records
             if r.attempts and r.attempts[-1].error is not None and r.attempts[-1].error.code.startswith("heartbeat.")]
    assert ended, [(r.session_id, r.state) for r in records]
    hb = rep["heartbeat_timeouts"]
    assert hb["episodes"] == ["pick_and_place-s0"] and set(ended) <= set(hb["sessions"])
    assert hb["per_task"] == {"pick_and_place": 1}
    # neither a success nor a failure of the robot
    assert rep["overall"]["episodes"] == 0 and rep["overall"]["failed_episodes"] == []
    assert all(not t["count"] for t in rep["error_taxonomy"].values()), rep["error_taxonomy"]
    md = (result.run_dir / "report.md").read_text()
    assert "heartbeat or queue timeout (machine load; not scored above) | 1 |" in md
    assert set(hb["codes"]) <= {"heartbeat.runner", "heartbeat.target", "heartbeat.policy"}


def test_sessions_that_timed_out_in_the_queue_are_counted_apart_with_their_code(tmp_path):
    # A 1 ms queue limit: the real supervisor times the pending session out before any
    # runner starts; no robot moved, so the episode is neither a success nor a failure.
    result = run_bench(write_suite(tmp_path / "mini.yaml"), tmp_path / "ws", seeds=(0,), workers=1,
                       memory="off", queue_timeout_s=0.001)
    rep = json.loads((result.run_dir / "report.json").read_text())
    assert rep["session_limits"] == {"queue_timeout_s": 0.001}
    (ep,) = rep["episodes"]
    assert ep["sessions"] and all(s["state"] == "timed_out" and s["error_code"] == "timeout.queue"
                                  for s in ep["sessions"])
    assert rep["heartbeat_timeouts"]["episodes"] == ["pick_and_place-s0"]
    assert rep["heartbeat_timeouts"]["codes"] == {"timeout.queue": len(ep["sessions"])}
    assert rep["overall"]["episodes"] == 0
    assert all(not t["count"] for t in rep["error_taxonomy"].values()), rep["error_taxonomy"]
