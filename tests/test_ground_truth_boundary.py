"""The Agent plane never names the privileged channel: the CI check and proof that a leak breaks it."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "check_ground_truth_boundary.py"


def run_check(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), str(root)], capture_output=True, text=True, timeout=120)


@pytest.fixture
def copy(tmp_path):
    dst = tmp_path / "repo"
    shutil.copytree(ROOT / "phyagentos", dst / "phyagentos", ignore=shutil.ignore_patterns("__pycache__"))
    return dst


def test_repository_keeps_the_agent_plane_away_from_the_privileged_channel():
    result = run_check(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "boundary kept" in result.stdout


def test_the_make_test_target_runs_the_check_before_pytest():
    lines = (ROOT / "Makefile").read_text().split("test: setup\n", 1)[1].split("\n\n", 1)[0].splitlines()
    target = [ln.strip() for ln in lines]  # the recipe: its lines up to the next blank line
    commands = [re.sub(r"^([A-Z_]+=\S* )+", "", ln) for ln in target]  # without the environment settings
    pytest_line = next(i for i, ln in enumerate(commands) if ln.startswith(".venv/bin/pytest "))
    assert target.index(".venv/bin/python scripts/check_ground_truth_boundary.py") < pytest_line


@pytest.mark.parametrize("module,line,expect", [
    ("verifier.py", 'GT = "ground_truth.yaml"\n', "ground_truth"),
    ("diagnosis.py", "def _peek(ev):\n    return ev.terminal.get('truth')\n", "truth"),
    ("memory/conditions.py", "def _kinds(scene):\n    return scene.get('perturbations')\n", "perturbations"),
    ("recovery.py", "# compare against the perturbation record here\n", "perturbation"),
    ("memory/context_builder.py", "def f(*, ground_truth=None):\n    return ground_truth\n", "ground_truth"),
    ("coordinator.py", "from phyagentos.bench import report as _scores  # noqa\n", "imports phyagentos.bench"),
    # LIBERO's answer key and checker (docs/libero.md)
    ("verifier.py", "def _libero(target):\n    return target.check_success()\n", "check_success"),
    ("planner.py", "def _goal(task):\n    return open(task.bddl_path).read()\n", "bddl"),
    ("diagnosis.py", "KEY = 'obj_of_interest'\n", "obj_of_interest"),
    ("coordinator.py", "from phyagentos.targets.libero.catalog import resolve_task  # noqa\n",
     "imports phyagentos.targets.libero.catalog"),
])
def test_a_planted_leak_breaks_the_check(copy, module, line, expect):
    path = copy / "phyagentos" / "agent" / module
    path.write_text(path.read_text(encoding="utf-8") + "\n" + line, encoding="utf-8")
    result = run_check(copy)
    assert result.returncode == 1, result.stdout
    assert f"phyagentos/agent/{module}:" in result.stdout and expect in result.stdout
    assert "boundary BROKEN" in result.stdout


def test_importing_a_helper_that_reads_the_file_breaks_the_check_even_without_naming_it(copy):
    helper = copy / "phyagentos" / "scoring_helper.py"
    helper.write_text('"""Innocent prose."""\n\nPATH = "evidence/{sid}/ground_truth.yaml"\n\n'
                      "def load(sid):\n    return open(PATH.format(sid=sid)).read()\n", encoding="utf-8")
    agent = copy / "phyagentos" / "agent" / "verifier.py"
    agent.write_text(agent.read_text(encoding="utf-8") + "\nfrom phyagentos.scoring_helper import load as _load\n",
                     encoding="utf-8")
    result = run_check(copy)
    assert result.returncode == 1
    assert "imports phyagentos.scoring_helper" in result.stdout
    # and one step removed: a helper importing that helper
    (copy / "phyagentos" / "relay.py").write_text("from phyagentos.scoring_helper import load\n", encoding="utf-8")
    agent.write_text(agent.read_text(encoding="utf-8").replace("phyagentos.scoring_helper import load as _load",
                                                               "phyagentos.relay import load as _load"),
                     encoding="utf-8")
    result = run_check(copy)
    assert result.returncode == 1 and "via phyagentos.scoring_helper" in result.stdout


def test_prose_in_a_shared_module_is_not_a_leak_but_a_key_is(copy):
    errors = copy / "phyagentos" / "errors.py"
    errors.write_text(errors.read_text(encoding="utf-8") + '\n_MSG = "the source of truth is the session file"\n',
                      encoding="utf-8")
    assert run_check(copy).returncode == 0
    errors.write_text(errors.read_text(encoding="utf-8") + '\n_KEY = "ground_truth"\n', encoding="utf-8")
    result = run_check(copy)
    assert result.returncode == 1 and "imports phyagentos.errors" in result.stdout
