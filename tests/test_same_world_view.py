"""A session starts from the previous session's terminal view when nothing moved the target (issue 12).

The SessionRunner perceives before and after every skill. Between one session's
terminal perception and the next session's initial one on the same target nothing
actuates, so the runner hands the next session the kept view (``TargetPool.keep_view``
/ ``take_view``) instead of rendering and fusing the same world again, but only when
that is provable: same run, same live target, equal world digest after the state file
round trip, same perception configuration, no perturbations, and at most once.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import yaml
from supervisor_util import make_workspace, submit

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.protocol import Workspace

VIEW = {"snapshot": {"entities": [{"name": "cube", "position": [0.5, -0.2, 0.02]}]}, "evidence": "evidence/a"}


def _pair(ws, *, run_b: str = "r-view", scene: dict | None = None):
    recs = []
    for sid, run in (("a", "r-view"), ("b", run_b)):
        submit(ws, sid, skill="hold", parameters={"duration_s": 0.0}, run_id=run)

        def set_scene(r):
            r.scene = scene
            r.seed = 3

        recs.append(ws.update_session(sid, set_scene))
    return recs


def _hand_over(pool, spec, a, *, move=None, key=None):
    target = pool.acquire(a, spec)
    pool.keep_view(a, spec, target, VIEW, key=key)
    if move is not None:
        move(target)
    pool.release(a, target)


@pytest.mark.sim
def test_the_next_session_of_the_run_on_an_unmoved_target_gets_the_kept_view_once(tmp_path):
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    spec = ws.read("TARGETS").data.targets[0]
    a, b = _pair(ws)
    pool = TargetPool(ws.root / "targets")
    try:
        _hand_over(pool, spec, a)
        target = pool.acquire(b, spec)  # restored from the state file the release wrote
        assert pool.take_view(b, spec, target) == VIEW
        assert pool.take_view(b, spec, target) is None  # used once
    finally:
        pool.close()


@pytest.mark.sim
@pytest.mark.parametrize("why", ["moved", "other_run", "perturbed", "config_changed"])
def test_the_kept_view_is_refused_unless_the_world_is_provably_the_same(tmp_path, why):
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    spec = ws.read("TARGETS").data.targets[0]
    scene = {"objects": [{"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.5, -0.2]}]}
    if why == "perturbed":
        scene["perturbations"] = [{"kind": "perception_noise", "object": "cube"}]
    a, b = _pair(ws, run_b="r-other" if why == "other_run" else "r-view", scene=scene)
    pool = TargetPool(ws.root / "targets")
    try:
        move = (lambda t: t.hold(duration_s=0.02)) if why == "moved" else None
        _hand_over(pool, spec, a, move=move, key=("config", 1))
        target = pool.acquire(b, spec)
        key = ("config", 2) if why == "config_changed" else ("config", 1)
        assert pool.take_view(b, spec, target, key=key) is None
    finally:
        pool.close()


@pytest.mark.sim
def test_a_restored_world_has_the_digest_of_the_saved_one_and_a_moved_world_another(tmp_path):
    from phyagentos.targets import MuJoCoTarget

    target = MuJoCoTarget("franka_tabletop", seed=1)
    other = MuJoCoTarget("franka_tabletop", seed=2)
    try:
        target.hold(duration_s=0.05)
        target.runtime_notes["perception"] = {"tracks": {"cube": {"position": [0.5, -0.2, 0.02]}}}
        before = target.world_digest()
        path = target.save_state(tmp_path / "state.npz")
        other.load_state(path)
        assert other.world_digest() == before
        np.testing.assert_array_equal(other.arm_qpos(), target.arm_qpos())
        other.hold(duration_s=0.002)
        assert other.world_digest() != before
    finally:
        target.close()
        other.close()


@pytest.mark.sim
def test_a_run_starts_its_second_session_from_the_first_ones_terminal_view(tmp_path):
    from phyagentos.app.orchestrator import run_goal_graph

    graph = tmp_path / "two_holds.yaml"
    nodes = [{"id": f"h{i}", "skill": "hold", "params": {"duration_s": 0.0},
              "accept": {"still": {"max_joint_motion_rad": 0.01}}, "depends_on": [f"h{i - 1}"] if i else []}
             for i in range(3)]
    graph.write_text(yaml.safe_dump({"version": 1, "name": "two_holds", "defaults": {"target": "franka_tabletop"},
                                     "nodes": nodes}))
    report = run_goal_graph(graph, tmp_path / "ws", consolidate=False)
    assert report.succeeded
    ws = Workspace.open(tmp_path / "ws")
    evidence = {s.node: ws.root / s.attempts[-1].evidence for s in ws.list_sessions(run_id=report.run_id)}
    first = yaml.safe_load((evidence["h0"] / "initial.yaml").read_text())
    assert "same_world_as" not in first  # the first session perceives
    for prev, node in (("h0", "h1"), ("h1", "h2")):
        initial = yaml.safe_load((evidence[node] / "initial.yaml").read_text())
        terminal = yaml.safe_load((evidence[prev] / "terminal.yaml").read_text())
        assert initial.pop("same_world_as") == f"{evidence[prev].relative_to(ws.root).as_posix()}/terminal.yaml"
        assert initial["entities"] == [_relinked_entity(e, evidence[prev], evidence[node], ws.root)
                                       for e in terminal["entities"]]
        for png in (evidence[prev] / "frames").glob("terminal_*.png"):
            mine = evidence[node] / "frames" / png.name.replace("terminal_", "initial_")
            assert os.path.samefile(mine, png) or mine.read_bytes() == png.read_bytes()


def _relinked_entity(entity, prev, node, root):
    old = f"{prev.relative_to(root).as_posix()}/frames/terminal_"
    new = f"{node.relative_to(root).as_posix()}/frames/initial_"
    return yaml.safe_load(yaml.safe_dump(entity).replace(old, new))
