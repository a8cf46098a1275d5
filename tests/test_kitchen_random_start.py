"""FrankaKitchen randomised robot start (KitchenScene.start_jitter_rad): seeds give
different, reproducible starts; the default keeps the environment's own keyframe."""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.bench import load_suite
from phyagentos.errors import TargetError
from phyagentos.targets.kitchen import FrankaKitchenTarget, KitchenScene


def test_start_jitter_outside_its_range_is_refused_and_round_trips_through_plain_data():
    with pytest.raises(TargetError, match="start_jitter_rad"):
        KitchenScene(start_jitter_rad=-0.1)
    with pytest.raises(TargetError, match="start_jitter_rad"):
        KitchenScene(start_jitter_rad=0.9)
    scene = KitchenScene(tasks=("kettle",), start_jitter_rad=0.1)
    assert KitchenScene.from_dict(scene.to_dict()) == scene
    assert KitchenScene().start_jitter_rad == 0.0


def test_the_random_start_suite_declares_the_jitter_in_both_tasks():
    suite = load_suite("kitchen_random_start")
    import yaml  # noqa: PLC0415

    for task in suite.tasks:
        scene = yaml.safe_load(task.goal_graph.read_text())["scene"]
        assert KitchenScene.from_dict(scene).start_jitter_rad == 0.1


@pytest.mark.sim
def test_seeds_give_different_reproducible_robot_starts_and_the_default_keeps_the_keyframe():
    def start(seed, jitter):
        with FrankaKitchenTarget("k", KitchenScene(tasks=("microwave",), start_jitter_rad=jitter), seed=seed) as k:
            lo, hi = k.model.jnt_range[k._jids, 0], k.model.jnt_range[k._jids, 1]  # noqa: SLF001
            q = k.arm_qpos()
            if jitter:  # clipped 1 mrad inside the range before the settling step
                assert np.all(q >= lo - 1e-3) and np.all(q <= hi + 1e-3), (q, lo, hi)
            return q

    keyframe_a, keyframe_b = start(0, 0.0), start(1, 0.0)
    np.testing.assert_allclose(keyframe_a, keyframe_b, atol=1e-6)  # no jitter: seeds only change obs noise
    a, b, a_again = start(0, 0.1), start(1, 0.1), start(0, 0.1)
    np.testing.assert_allclose(a, a_again, atol=1e-9)
    assert np.max(np.abs(a - b)) > 0.02
    # within the jitter (plus the one settling step) of the keyframe
    assert np.max(np.abs(a - keyframe_a)) < 0.1 + 0.01
