"""The worked example of docs/targets.md ("Adding a robot"): a 2-DoF planar arm defined
outside the package (tests/planar_arm_plugin.py), registered without editing PhyAgentOS
(in-process with ``register_target``; across processes as an installed distribution's
entry point in the ``phyagentos.targets`` group), runs a ``hold`` session through the
normal ``phyagentos run`` path to success."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import yaml
from planar_arm_plugin import HOME_QPOS, PlanarArmTarget  # tests/ is on sys.path (rootdir conftest-less import)

from phyagentos.motion.retime import retime
from phyagentos.protocol import TargetSpec, Workspace
from phyagentos.resources import goal_graphs_dir
from phyagentos.targets.contract import Target, capabilities_of
from phyagentos.targets.registry import get_target_class, register_target, registered_targets, unregister_target

REPO = Path(__file__).resolve().parent.parent
TESTS = Path(__file__).resolve().parent

PLANAR_SPEC = dict(name="planar", kind="simulation", driver="planar_arm", capabilities=["arm", "joint_position_control"],
                   observations=["joint_positions"], action={"space": "joint_position", "dof": 2, "control_rate_hz": 500})


def test_the_planar_arm_keeps_the_contract_in_process(tmp_path):
    register_target("planar_arm", PlanarArmTarget)
    try:
        cls = get_target_class("planar_arm")
        assert cls is PlanarArmTarget and "planar_arm" in registered_targets()
        assert issubclass(cls, Target) and capabilities_of(cls).accepts("joint_trajectory")
        with cls("planar", seed=0) as arm:
            assert np.allclose(arm.arm_qpos(), HOME_QPOS)
            q_goal = np.array([0.8, -1.0])
            traj = retime(np.stack([arm.arm_qpos(), q_goal]), vel_limits=arm.velocity_limits(), acc_limits=[3.0, 3.0])
            result = arm.execute_trajectory(traj, tracking_tol_rad=0.05)
            assert result.completed and result.max_tracking_error_rad < 0.05
            assert np.allclose(arm.arm_qpos(), q_goal, atol=0.01)
            digest = arm.world_digest()
            arm.save_state(tmp_path / "state.npz")
            arm.reset(seed=1)
            arm.load_state(tmp_path / "state.npz")
            assert arm.world_digest() == digest
            assert arm.invoke_tool("hold", duration_s=0.2)["steps"] == 100
    finally:
        unregister_target("planar_arm")


def _install_plugin(site: Path) -> None:
    """What ``pip install`` of a package declaring the entry point leaves on sys.path."""
    dist = site / "planar_arm_plugin-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: planar-arm-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent("""\
        [phyagentos.targets]
        planar_arm = planar_arm_plugin:PlanarArmTarget
        """))


def test_a_hold_session_runs_on_the_plugin_arm_through_phyagentos_run(tmp_path):
    site = tmp_path / "site"
    _install_plugin(site)
    ws = tmp_path / "ws"
    Workspace.create(ws).update("TARGETS", lambda doc: doc.targets.append(TargetSpec(**PLANAR_SPEC)))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(TESTS), str(site)])}
    proc = subprocess.run([sys.executable, "-m", "phyagentos.cli", "run", str(goal_graphs_dir() / "hold.yaml"),
                           "--workspace", str(ws), "--target", "planar", "--json"],
                          capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads(proc.stdout)  # the run's JSON summary
    assert summary["succeeded"] is True and summary["nodes"] == {"hold_still": "succeeded"}
    assert [(x["target"], x["verdict"]) for x in summary["sessions"]] == [("planar", "success")]
    [rec] = Workspace.open(ws).list_sessions()
    assert rec.target == "planar" and rec.attempts[-1].outcome == "completed" and rec.state == "succeeded"
    [still] = rec.attempts[-1].verdict.criteria
    assert still.name == "still" and still.status == "satisfied"
    evidence = ws / rec.attempts[-1].evidence
    truth = yaml.safe_load((evidence / "ground_truth.yaml").read_text(encoding="utf-8"))
    before, after = truth["initial"]["arm_qpos"], truth["terminal"]["arm_qpos"]
    assert np.allclose(before, HOME_QPOS, atol=1e-6)
    assert max(abs(a - b) for a, b in zip(before, after)) < 0.01
