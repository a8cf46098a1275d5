"""The pre-motion checkpoint is not rewritten when the state file holds that world already (issue 12).

Every session persists its target's world before the first tick, so that a recovering
supervisor restores from there at worst. When the session's target was just restored
from this run's state file (the previous session's final checkpoint, durable since that
session's ``done``) and nothing changed it since (equal world digest), the file already
holds that world: ``TargetPool.checkpoint_before_motion`` rewrites only ``state.yaml``
(naming the new session) instead of the whole state. Any other world is written.
"""

from __future__ import annotations

import numpy as np
import pytest

import phyagentos  # noqa: F401  (headless GL before mujoco loads)
from phyagentos.protocol.atomic import batched_durability

from supervisor_util import make_workspace, submit


def _sessions(ws, *runs: str):
    recs = []
    for i, run in enumerate(runs):
        submit(ws, f"s{i}", skill="hold", parameters={"duration_s": 0.0}, run_id=run)
        recs.append(ws.load_session(f"s{i}"))
    return recs


def _files(ws, spec):
    d = ws.root / "targets" / spec.name
    return (d / "state.npz").read_bytes(), (d / "state.yaml").read_text()


@pytest.mark.sim
def test_an_unmoved_restored_world_keeps_its_state_file_and_names_the_new_session(tmp_path):
    from phyagentos.runtime.target_pool import TargetPool
    from phyagentos.targets import MuJoCoTarget

    ws = make_workspace(tmp_path / "ws")
    spec = ws.read("TARGETS").data.targets[0]
    a, b = _sessions(ws, "r1", "r1")
    pool = TargetPool(ws.root / "targets")
    try:
        target = pool.acquire(a, spec)  # a new run: reset, nothing on disk yet
        assert pool.checkpoint_before_motion(a, target) is True
        target.hold(duration_s=0.05)
        pool.release(a, target)
        npz, _ = _files(ws, spec)
        target = pool.acquire(b, spec)  # restored from the file a's release wrote
        with batched_durability():
            assert pool.checkpoint_before_motion(b, target) is False
        after_npz, record = _files(ws, spec)
        assert after_npz == npz and "session_id: s1" in record
        # a recovering supervisor restores exactly the world b starts from
        fresh = MuJoCoTarget(spec.name, seed=9)
        try:
            fresh.load_state(ws.root / "targets" / spec.name / "state.npz")
            assert fresh.world_digest() == target.world_digest()
            np.testing.assert_array_equal(fresh.arm_qpos(), target.arm_qpos())
        finally:
            fresh.close()
    finally:
        pool.close()


@pytest.mark.sim
@pytest.mark.parametrize("why", ["moved", "reset_for_another_run", "checked_once"])
def test_any_other_world_is_written_before_motion(tmp_path, why):
    from phyagentos.runtime.target_pool import TargetPool

    ws = make_workspace(tmp_path / "ws")
    spec = ws.read("TARGETS").data.targets[0]
    a, b = _sessions(ws, "r1", "r2" if why == "reset_for_another_run" else "r1")
    pool = TargetPool(ws.root / "targets")
    try:
        target = pool.acquire(a, spec)
        pool.checkpoint_before_motion(a, target)
        target.hold(duration_s=0.05)
        pool.release(a, target)
        target = pool.acquire(b, spec)
        if why == "moved":
            target.hold(duration_s=0.01)  # something moved it between acquire and the first tick
        if why == "checked_once":
            assert pool.checkpoint_before_motion(b, target) is False  # the restore is vouched for once
        assert pool.checkpoint_before_motion(b, target) is True
        _, record = _files(ws, spec)
        assert "session_id: s1" in record
    finally:
        pool.close()
