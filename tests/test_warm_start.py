"""A runner that builds a run's targets ahead of its first session (issue 12).

``phyagentos run`` asks its prestarted runner to build the graph's targets and open
their cameras while the whole-graph check runs (``TargetPool.warm``, the runner job
``warm``). Warming must be invisible to the session: the same world, the same camera
noise, and a runner that never answers the warm-up with an error a supervisor could
take for its own job's failure.
"""

from __future__ import annotations

import numpy as np
import pytest
from supervisor_util import make_workspace, submit

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.resources import skill_dirs, tree_dirs

SCENE = {"objects": [{"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.5, -0.2],
                      "rgba": [0.8, 0.1, 0.1, 1]}],
         "regions": [{"name": "goal", "center": [0.5, 0.25], "half_extents": [0.08, 0.08]}]}


def _session(ws, sid: str, *, run_id: str = "r-warm"):
    submit(ws, sid, skill="hold", parameters={"duration_s": 0.0}, run_id=run_id)

    def with_scene(r):
        r.scene = SCENE
        r.seed = 7

    return ws.update_session(sid, with_scene)


@pytest.mark.sim
def test_a_warmed_target_starts_its_session_in_the_same_world_as_a_cold_one(tmp_path):
    from phyagentos.runtime.target_pool import TargetPool

    warm_ws, cold_ws = make_workspace(tmp_path / "warm"), make_workspace(tmp_path / "cold")
    spec = warm_ws.read("TARGETS").data.targets[0]
    warm_pool, cold_pool = TargetPool(warm_ws.root / "targets"), TargetPool(cold_ws.root / "targets")
    try:
        assert warm_pool.warm(spec, SCENE) is True
        built = warm_pool._live[spec.name][1]
        assert warm_pool.warm(spec, SCENE) is False  # already built for this scene: nothing to do
        assert not (warm_ws.root / "targets" / spec.name / "state.npz").exists()  # warming writes nothing

        warm = warm_pool.acquire(_session(warm_ws, "s1"), spec)
        cold = cold_pool.acquire(_session(cold_ws, "s1"), spec)
        assert warm is built  # the session found the target built
        assert warm.sim_time == cold.sim_time
        np.testing.assert_array_equal(warm.arm_qpos(), cold.arm_qpos())
        np.testing.assert_array_equal(warm.object_pose("cube"), cold.object_pose("cube"))
        cam = warm.camera_names()[0]
        a, b = warm.capture(cam), cold.capture(cam)  # the same seeded camera noise: nothing drawn early
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth_m, b.depth_m)
    finally:
        warm_pool.close()
        cold_pool.close()


@pytest.mark.sim
def test_a_session_of_another_scene_rebuilds_the_warmed_target(tmp_path):
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    spec = ws.read("TARGETS").data.targets[0]
    pool = TargetPool(ws.root / "targets")
    try:
        pool.warm(spec, {"objects": [{"name": "block", "half_extents": [0.03, 0.03, 0.03], "position": [0.4, 0.1]}]})
        other = pool._live[spec.name][1]
        target = pool.acquire(_session(ws, "s1"), spec)
        assert target is not other and other.closed
        target.object_pose("cube")  # the session's scene, not the warmed one
    finally:
        pool.close()


@pytest.mark.sim
def test_warming_a_runner_answers_warmed_even_for_targets_it_cannot_build(tmp_path):
    from phyagentos.runtime.worker import RunnerProcess

    ws = make_workspace(tmp_path / "ws")
    runner = RunnerProcess(skills_dir=skill_dirs(), trees_dir=tree_dirs())
    try:
        kind, payload = runner.request("warm", timeout=120, expect=("warmed",), root=str(ws.root),
                                       targets=[{"name": "franka_tabletop", "scene": {"objects": "not a list"}},
                                                {"name": "no_such_target", "scene": None}])
        assert kind == "warmed"
        assert payload["built"] == [] and len(payload["errors"]) == 1
        assert "franka_tabletop" in payload["errors"][0]
        # the runner serves on: a good warm-up builds
        kind, payload = runner.request("warm", timeout=120, expect=("warmed",), root=str(ws.root),
                                       targets=[{"name": "franka_tabletop", "scene": SCENE}])
        assert (kind, payload["built"], payload["errors"]) == ("warmed", ["franka_tabletop"], [])
    finally:
        runner.close()
