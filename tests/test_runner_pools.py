"""A runner that serves one workspace after another keeps the target pools of at most two.

The runner process outlives workspaces: an idle runner is reused by the next ``run`` of
the same process (benchmark episodes, the tests), and ``watch`` serves whatever it is
given. Each pool holds live targets (models, data, camera renderers: hundreds of MB).
"""

from __future__ import annotations

import multiprocessing

import pytest

from phyagentos.protocol import Workspace
from phyagentos.resources import skill_dirs, tree_dirs
from phyagentos.runtime.heartbeat import Heartbeats
from phyagentos.runtime.worker import _Runner

pytestmark = pytest.mark.sim

TARGET = "franka_tabletop"


@pytest.fixture
def runner():
    near, far = multiprocessing.Pipe()
    r = _Runner(near, Heartbeats(), skill_dirs(), tree_dirs())
    yield r
    r.release_all()
    r.images.close()
    for pool in r.pools.values():
        pool.close()
    near.close()
    far.close()


def _serve(runner: _Runner, root: str, *, keep_reserved: bool = False):
    """Reserve the workspace's target, build it in the runner's pool, release it unless told
    otherwise; returns the live target."""
    ws = Workspace.open(root)
    spec = next(t for t in ws.read("TARGETS").data.targets if t.name == TARGET)
    runner.job_reserve(root, TARGET)
    assert runner.lock(root, TARGET).held
    pool = runner.pool(root)
    pool.warm(spec, None)
    target = pool._live[TARGET][1]
    if not keep_reserved:
        runner.job_unreserve(root, TARGET)
    return target


def test_a_runner_serving_workspace_after_workspace_closes_all_but_two_pools(runner, tmp_path):
    roots = [str(Workspace.create(tmp_path / f"ws{i}").root) for i in range(3)]
    targets = [_serve(runner, root) for root in roots]
    assert list(runner.pools) == roots[1:]
    assert targets[0].closed and not targets[1].closed and not targets[2].closed
    assert not any(root == roots[0] for root, _ in runner.locks)  # its released locks are forgotten


def test_a_workspace_whose_target_is_reserved_keeps_its_pool(runner, tmp_path):
    roots = [str(Workspace.create(tmp_path / f"ws{i}").root) for i in range(3)]
    held = _serve(runner, roots[0], keep_reserved=True)
    others = [_serve(runner, root) for root in roots[1:]]
    assert list(runner.pools) == [roots[0], roots[2]]
    assert not held.closed and runner.lock(roots[0], TARGET).held
    assert others[0].closed and not others[1].closed


def test_a_workspace_whose_target_is_too_big_to_keep_idle_is_closed_when_the_runner_moves_on(runner, tmp_path,
                                                                                               monkeypatch):
    # a LIBERO world (KEEP_WHEN_IDLE false) holds 1.5-2 GB: the next episode's world must not
    # be built beside the last one's; a reserved one stays
    roots = [str(Workspace.create(tmp_path / f"ws{i}").root) for i in range(4)]
    first = _serve(runner, roots[0])
    monkeypatch.setattr(type(first), "KEEP_WHEN_IDLE", False)
    second = _serve(runner, roots[1])
    assert list(runner.pools) == [roots[1]]
    assert first.closed and not second.closed
    held = _serve(runner, roots[2], keep_reserved=True)
    assert second.closed
    last = _serve(runner, roots[3])
    assert list(runner.pools) == [roots[2], roots[3]]
    assert not held.closed and not last.closed


def test_a_closed_workspaces_model_is_not_kept_alive_by_the_ik_and_kinematic_chain_caches(runner, tmp_path):
    # the IK contexts and the safety guard's chains hold their models (a LIBERO world's: about
    # 250 MB each, up to 4 + 8 of them): closing a target drops its model from both
    import gc
    import weakref

    from phyagentos.motion.ik import solve_ik
    from phyagentos.runtime.safety_guard import ChainFK

    roots = [str(Workspace.create(tmp_path / f"ws{i}").root) for i in range(3)]
    first = _serve(runner, roots[0])
    solve_ik(first.model, q_seed=first.arm_qpos(), target=first.tcp_pose(), arm_joint_names=first.arm_joint_names,
             frame=first.tcp_site)
    ChainFK.of(first.model, first.arm_joint_names, first.tcp_site)
    model = weakref.ref(first.model)
    del first
    for root in roots[1:]:
        _serve(runner, root)
    gc.collect()
    assert model() is None
