"""Optional features are extras: the core runs without them, and a missing one says which
extra to install (phyagentos/extras.py, pyproject's optional dependencies)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from phyagentos.errors import MissingExtraError, PhyAgentOSError
from phyagentos.extras import EXTRAS, import_extra, missing_extra

REPO = Path(__file__).resolve().parents[1]
#: Extras that are not optional features of the package itself.
NOT_FEATURES = {"libero", "ray", "rerun", "test", "all"}


def _optional_dependencies() -> dict[str, list[str]]:
    import tomllib  # python >= 3.11 (the set-up's venv); the package itself needs 3.10

    return tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]


def test_every_feature_extra_of_pyproject_is_named_in_extras_and_all_installs_them():
    extras = _optional_dependencies()
    assert set(extras) - NOT_FEATURES == set(EXTRAS)
    assert extras["all"] == [f"phyagentos[{','.join(EXTRAS)}]"]
    assert "phyagentos[all,libero]" in extras["test"]  # make demo / make test install every extra


def test_a_missing_extra_module_is_an_error_that_names_the_extra_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "zenoh", None)  # import of zenoh halted: as if not installed
    with pytest.raises(MissingExtraError, match=r"pip install 'phyagentos\[fleet\]'") as info:
        import_extra("zenoh", extra="fleet")
    assert isinstance(info.value, PhyAgentOSError)
    assert (info.value.extra, info.value.module) == ("fleet", "zenoh")


def test_an_import_error_about_another_module_is_not_taken_for_a_missing_extra():
    broken = ModuleNotFoundError("No module named 'numpy.core._bad'", name="numpy.core._bad")
    with pytest.raises(ModuleNotFoundError, match="numpy.core._bad"):
        raise missing_extra(broken, extra="fleet")


def _blocked(tmp_path: Path) -> Path:
    """A folder of stand-ins for every extra's modules: importing one fails as a missing package does."""
    stubs = tmp_path / "no_extras"
    stubs.mkdir()
    for _, modules in EXTRAS.values():
        for name in modules:
            (stubs / f"{name}.py").write_text(
                f"raise ModuleNotFoundError(\"No module named '{name}'\", name={name!r})\n", encoding="utf-8")
    return stubs


@pytest.mark.sim
def test_the_core_runs_a_goal_graph_without_any_extra_and_a_feature_names_its_extra(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(_blocked(tmp_path)), str(REPO)])}
    cli = [sys.executable, "-m", "phyagentos.cli"]
    run = subprocess.run([*cli, "run", "hold", "--workspace", str(tmp_path / "ws"), "--json"], env=env,
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    assert json.loads(run.stdout.strip().splitlines()[-1])["succeeded"] is True
    view = subprocess.run([*cli, "view", str(tmp_path / "ws")], env=env, cwd=tmp_path, capture_output=True,
                          text=True, timeout=120)
    assert view.returncode == 2, view.stdout[-2000:] + view.stderr[-2000:]
    assert "pip install 'phyagentos[view]'" in view.stderr
