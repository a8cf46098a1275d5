"""FrankaKitchen through the target adapter: the environment's own success signal next to our verdict."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phyagentos.bench import run_bench
from phyagentos.targets.kitchen import FrankaKitchenTarget, KitchenScene

pytestmark = pytest.mark.sim


def test_kitchen_target_reports_the_environments_own_signal_and_carries_it_across_a_state_file(tmp_path):
    with FrankaKitchenTarget("kitchen", KitchenScene(tasks=("microwave",)), seed=0) as k:
        snap = k.snapshot()
        bench = k.ground_truth()["benchmark"]
        assert bench["tasks"] == {"microwave": False} and not bench["success"]
        door = next(e for e in snap["entities"] if e["name"] == "microwave")
        assert door["kind"] == "articulation" and abs(door["attributes"]["joint_position"]) < 0.01
        # the adapter drives the real environment: every motion is the env's own step()
        k.hold(duration_s=0.4)
        assert k.ground_truth()["benchmark"]["env_steps"] == 5
        k.save_state(tmp_path / "state.npz")
        q = k.arm_qpos()
    with FrankaKitchenTarget("kitchen", KitchenScene(tasks=("microwave",)), seed=1) as k2:
        k2.load_state(tmp_path / "state.npz")
        np.testing.assert_allclose(k2.arm_qpos(), q)
        assert k2.ground_truth()["benchmark"]["env_steps"] == 5


def test_kitchen_microwave_episode_is_judged_by_us_and_by_the_environment(tmp_path):
    result = run_bench("kitchen", tmp_path / "ws", tasks=("microwave",), seeds=(0,), workers=1)
    rep = json.loads((result.run_dir / "report.json").read_text())
    assert rep["harness_errors"] == []
    (ep,) = rep["episodes"]
    (gt,) = ep["ground_truth"]
    assert "FrankaKitchen-v1" in gt["source"]
    # the environment's own checker (door within 0.3 rad of -0.75) and our verdict agree here
    assert gt["env_success"] is True and gt["verdict"] == "success" and gt["agree"]
    assert rep["ground_truth"]["per_task"]["microwave"]["env_successes"] == 1
    md = (result.run_dir / "report.md").read_text()
    assert "Environment's own success signal" in md and "FrankaKitchen-v1" in md
