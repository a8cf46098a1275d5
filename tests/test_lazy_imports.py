"""What processes of ``phyagentos run`` do not import (issue 12, round 3).

Each check runs in a fresh interpreter, so what this test process has loaded does not
count: a runner starts with the forkserver's preload and never loads the policy client
(websockets, asyncio, ssl), the LLM client or the statechart (transitions) for builtin
skills; the CLI module, which every forkserver child re-imports as its main module,
loads no rich; the ``run`` process loads no numpy.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _loaded(code: str, modules: tuple[str, ...]) -> list[str]:
    probe = code + f"\nimport sys\nprint('LOADED', [m for m in {modules!r} if m in sys.modules])\n"
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("LOADED ")][-1]
    return eval(line.removeprefix("LOADED "))  # noqa: S307 - our own repr of a list of str


def test_a_runner_of_builtin_skills_starts_without_the_policy_llm_or_statechart_modules():
    code = ("import importlib\nfrom phyagentos.runtime import worker\n"
            "for name in worker._PRELOAD:\n    importlib.import_module(name)\n")
    assert _loaded(code, ("websockets", "asyncio", "ssl", "phyagentos.policy.client", "phyagentos.llm",
                          "phyagentos.runtime.policy_runtime", "phyagentos.runtime.agent_runtime",
                          "transitions", "rich", "networkx")) == []


def test_the_other_skill_runtimes_load_when_a_session_asks_for_them():
    from phyagentos.runtime.agent_runtime import AgentSkillRuntime
    from phyagentos.runtime.policy_runtime import PolicySkillRuntime
    from phyagentos.runtime.runner import SKILL_RUNTIMES

    assert SKILL_RUNTIMES["policy"] is PolicySkillRuntime and SKILL_RUNTIMES["agent"] is AgentSkillRuntime
    assert dict(SKILL_RUNTIMES) == {"policy": PolicySkillRuntime, "agent": AgentSkillRuntime}
    assert "builtin" not in SKILL_RUNTIMES


def test_the_cli_module_that_forkserver_children_re_import_loads_no_rich():
    assert _loaded("import phyagentos.cli", ("rich", "rich.console", "rich.table")) == []


def test_the_run_process_imports_no_numpy_before_a_pose_is_computed():
    assert _loaded("import phyagentos.cli, phyagentos.app.orchestrator", ("numpy",)) == []


def test_the_held_object_model_still_computes_poses():
    from phyagentos.agent.held_object import _pose

    T = _pose([0.1, 0.2, 0.3], [1.0, 0.0, 0.0, 0.0])
    assert T.shape == (4, 4) and list(T[:3, 3]) == [0.1, 0.2, 0.3] and T[0, 0] == 1.0
    assert _pose(None, [1.0, 0.0, 0.0, 0.0]) is None


def test_a_quiet_run_process_never_imports_rich_and_a_log_record_still_renders_through_it(tmp_path):
    import yaml

    graph = tmp_path / "hold.yaml"
    graph.write_text(yaml.safe_dump({"version": 1, "name": "one_hold", "description": "a 0 s hold",
                                     "nodes": [{"id": "h", "skill": "hold", "target": "franka_tabletop",
                                                "params": {"duration_s": 0.0},
                                                "accept": {"still": {"max_joint_motion_rad": 0.01}}}]}))
    ws = tmp_path / "ws"
    ws.mkdir()
    (ws / "sensors.yaml").write_text(yaml.safe_dump({"version": 1, "targets": {"franka_tabletop": [
        {"name": "joints", "kind": "joint_state", "frame_id": "panda0_link0", "rate_hz": 500}]}}))
    code = ("import logging, sys\nfrom phyagentos.cli import main\n"
            f"code = main(['run', {str(graph)!r}, '--workspace', {str(ws)!r}, '--json'])\n"
            "assert code == 0, code\n"
            "print('AFTER_RUN', [m for m in sys.modules if m == 'rich' or m.startswith('rich.')])\n"
            "logging.getLogger('phyagentos.test').warning('a warning after the run')\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert [ln for ln in out.stdout.splitlines() if ln.startswith("AFTER_RUN ")] == ["AFTER_RUN []"]
    assert "a warning after the run" in out.stderr and "WARNING" in out.stderr  # rich's level column


def test_the_runner_preload_defers_pyplot_that_toppra_imports_for_plots_it_never_draws():
    code = ("import importlib\nfrom phyagentos.runtime import worker\n"
            "for name in worker._PRELOAD:\n    importlib.import_module(name)\n"
            "import toppra.parametrizer\n")
    assert _loaded(code, ("matplotlib.figure", "matplotlib.axes")) == []


def test_a_deferred_pyplot_is_the_real_pyplot_from_its_first_use():
    code = ("import os, sys\nos.environ['MPLBACKEND'] = 'Agg'\nimport phyagentos.motion.retime\n"
            "import toppra.algorithm.algorithm as tal\nplaceholder = tal.plt\n"
            "assert 'matplotlib.figure' not in sys.modules\n"
            "fig = placeholder.figure()\nassert type(fig).__module__ == 'matplotlib.figure', type(fig)\n"
            "real = sys.modules['matplotlib.pyplot']\nassert real is not placeholder and real.gcf() is fig\n"
            "import matplotlib.pyplot as again\nassert again is real and placeholder.gcf() is fig\n")
    assert _loaded(code, ("matplotlib.figure",)) == ["matplotlib.figure"]
