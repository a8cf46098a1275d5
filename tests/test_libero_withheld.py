"""A LIBERO session decides the same with its ground truth withheld: LIBERO's checker, the BDDL
answer key and the true poses reach ground_truth.yaml and nothing the Agent plane reads."""

from __future__ import annotations

import pytest
import yaml
from test_ground_truth_withheld import _differences, run_withheld

from phyagentos.bench.libero import _ensure_target, instruction_nodes
from phyagentos.targets.libero import parse_bddl, resolve_task

pytestmark = pytest.mark.sim


def test_a_libero_episode_decides_identically_with_ground_truth_withheld(tmp_path):
    task = resolve_task("libero_object", 0)
    problem = parse_bddl(task.bddl_path)
    graph = tmp_path / "libero_t0.yaml"
    # declared as a user would without looks: names and categories only (the pick cannot tell
    # the soup from the rest and is diagnosed, which exercises the Agent's decisions); a LIBERO
    # render holds the runner for seconds, beyond the default 10 s heartbeat on a loaded machine
    # (as `phyagentos bench --heartbeat-timeout` says): what is tested here is the decisions
    nodes = instruction_nodes(task.language, problem.objects, problem.fixtures)
    for node in nodes:
        node.setdefault("limits", {})["heartbeat_timeout_s"] = 120.0
    graph.write_text(yaml.safe_dump({
        "version": 1, "name": "libero_t0", "description": task.language, "defaults": {"target": "libero"},
        "scene": {"suite": "libero_object", "task": 0, "init": 0, **problem.declared()},
        "nodes": nodes}))
    _ensure_target(tmp_path / "ws")
    mp = pytest.MonkeyPatch()
    try:
        report, log = run_withheld(mp, tmp_path, graph, tmp_path / "ws")
    finally:
        mp.undo()
    assert log, f"no verifying step ran: {report.to_dict()}"
    for step in log:
        assert step["withheld"] == step["shadow"], _differences(step["withheld"], step["shadow"])
        assert step["memory"] == step["shadow_memory"]
    verdicts = [s["verdict"] for step in log for sid in step["verified"] for s in [step["withheld"][sid]] if s["verdict"]]
    # not vacuous: the failed pick was diagnosed from perceived evidence alone
    causes = {v["diagnosis"]["cause"] for v in verdicts if v.get("diagnosis")}
    assert causes & {"object_not_seen", "perception_unknown"}, verdicts
    # what was withheld: LIBERO's verdict and answer key, in the shadow's copies only
    shadow = next(tmp_path.glob("shadow-*/withheld/*/ground_truth.yaml"))
    record = yaml.safe_load(shadow.read_text())
    assert "check_success" in record["benchmark"]["source"]
    assert record["terminal"]["bddl"]["goal"] == ["And", ["In", "alphabet_soup_1", "basket_1_contain_region"]]
    assert not report.succeeded
