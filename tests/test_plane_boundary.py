"""The Agent and Runtime planes never import each other (import-linter contracts)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LINT = Path(sys.executable).parent / "lint-imports"


def run_lint(cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    return subprocess.run([str(LINT), "--config", str(cwd / ".importlinter")], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


def test_repository_keeps_the_planes_apart():
    result = run_lint(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    contracts = (ROOT / ".importlinter").read_text().count("[importlinter:contract:")
    assert contracts >= 9 and f"{contracts} kept, 0 broken" in result.stdout


def test_contract_catches_the_fleet_edge_importing_the_agent_plane(tmp_path):
    copy = tmp_path / "repo"
    shutil.copytree(ROOT / "phyagentos", copy / "phyagentos", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / ".importlinter", copy / ".importlinter")
    leak = copy / "phyagentos" / "fleet" / "edge.py"
    leak.write_text(leak.read_text(encoding="utf-8") + "\nfrom phyagentos.agent.verifier import SessionVerifier\n",
                    encoding="utf-8")
    result = run_lint(copy)
    assert result.returncode != 0
    assert "The fleet's edge never imports the Agent plane BROKEN" in result.stdout


def test_contract_catches_an_agent_module_importing_the_runtime(tmp_path):
    copy = tmp_path / "repo"
    shutil.copytree(ROOT / "phyagentos", copy / "phyagentos", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / ".importlinter", copy / ".importlinter")
    leak = copy / "phyagentos" / "agent" / "leak.py"
    leak.write_text("from phyagentos.runtime.supervisor import WatchdogSupervisor\n", encoding="utf-8")
    result = run_lint(copy)
    assert result.returncode != 0
    assert "Agent plane never imports the Runtime plane BROKEN" in result.stdout


def test_contract_catches_the_model_interface_importing_a_plane(tmp_path):
    copy = tmp_path / "repo"
    shutil.copytree(ROOT / "phyagentos", copy / "phyagentos", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / ".importlinter", copy / ".importlinter")
    (copy / "phyagentos" / "llm" / "leak.py").write_text("from phyagentos.agent.planner import GoalPlanner\n",
                                                         encoding="utf-8")
    result = run_lint(copy)
    assert result.returncode != 0
    assert "The model interface (phyagentos.llm) imports neither plane; both may use it BROKEN" in result.stdout
