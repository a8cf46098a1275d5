"""The built wheel is a working install: it carries the shipped skills, trees, protocol
templates and example goal graphs, and a fresh venv that has it (and no checkout on its
path) validates and runs the demo graph from an unrelated directory.

The fresh venv sees the shared venv's third-party packages through a ``.pth`` line (a plain
path entry: the shared venv's own ``.pth`` files, among them the editable install's finder
that maps ``phyagentos`` to the checkout, are not processed), so nothing is downloaded.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

import phyagentos

pytestmark = pytest.mark.wheel
REPO = Path(__file__).resolve().parents[1]
PACKAGE = Path(phyagentos.__file__).resolve().parent
#: Package files that are not Python and must ship (pyproject's [tool.setuptools.package-data]).
DATA_SUFFIXES = (".yaml", ".md", ".json", ".js", ".css")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of the source (the build writes ``build/`` and
    ``*.egg-info`` next to the sources; the checkout stays clean)."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    shutil.copytree(REPO / "phyagentos", src / "phyagentos", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                           "-w", str(out), str(src)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    [whl] = out.glob("phyagentos-*.whl")
    return whl


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    """A fresh venv with the wheel installed ``--no-deps``; returns its ``bin/``."""
    root = tmp_path_factory.mktemp("venv")
    venv.EnvBuilder(with_pip=False).create(root)
    python = root / "bin" / "python"
    proc = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps",
                           "--no-index", str(wheel)], capture_output=True, text=True, timeout=300, env=_clean_env())
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert list((root / "lib").glob("python*/site-packages/phyagentos/data/goal_graphs/pick_and_place.yaml")), \
        proc.stdout[-2000:]
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    (site / "shared-third-party.pth").write_text(sysconfig.get_paths()["purelib"] + "\n", encoding="utf-8")
    return root / "bin"


def _clean_env() -> dict[str, str]:
    """This process's environment without anything that points Python or PhyAgentOS at the checkout."""
    drop = ("PYTHONPATH", "PYTHONHOME", "PHYAGENTOS_HOME", "PHYAGENTOS_SKILLS_PATH", "VIRTUAL_ENV")
    return {k: v for k, v in os.environ.items() if k not in drop}


def test_the_wheel_carries_every_shipped_data_file_of_the_package(wheel):
    in_wheel = set(zipfile.ZipFile(wheel).namelist())
    shipped = {p.relative_to(PACKAGE.parent).as_posix() for p in PACKAGE.rglob("*")
               if p.is_file() and p.suffix in DATA_SUFFIXES and "__pycache__" not in p.parts}
    assert {"phyagentos/data/goal_graphs/pick_and_place.yaml", "phyagentos/data/protocol/SESSIONS.md",
            "phyagentos/data/skills/pick.yaml", "phyagentos/data/trees/pick.yaml",
            "phyagentos/data/protocol/schemas/session.schema.json"} <= shipped
    assert shipped - in_wheel == set()


def test_the_installed_wheel_validates_and_runs_the_demo_graph_from_an_unrelated_directory(installed, tmp_path):
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    env = _clean_env()
    where = subprocess.run([str(installed / "python"), "-c", "import phyagentos, phyagentos.resources as r; "
                            "print(phyagentos.__file__); print(r.goal_graphs_dir())"],
                           cwd=cwd, env=env, capture_output=True, text=True, timeout=60)
    assert where.returncode == 0, where.stderr
    module, graphs = (Path(line) for line in where.stdout.split())
    venv_root = installed.parent.resolve()
    assert module.resolve().is_relative_to(venv_root), module  # the installed copy, not the checkout
    assert graphs.resolve().is_relative_to(venv_root) and (graphs / "pick_and_place.yaml").is_file()

    listed = subprocess.run([str(installed / "phyagentos"), "examples", "--json"], cwd=cwd, env=env,
                            capture_output=True, text=True, timeout=60)
    assert listed.returncode == 0, listed.stderr
    assert Path(json.loads(listed.stdout)["pick_and_place"]).resolve().is_relative_to(venv_root)

    valid = subprocess.run([str(installed / "phyagentos"), "validate", "pick_and_place"], cwd=cwd, env=env,
                           capture_output=True, text=True, timeout=120)
    assert valid.returncode == 0, valid.stdout[-2000:] + valid.stderr[-2000:]
    assert "valid, 2 node(s)" in valid.stdout

    run = subprocess.run([str(installed / "phyagentos"), "run", "pick_and_place", "--workspace", "ws", "--json"],
                         cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["succeeded"] is True, report
    assert (cwd / "ws" / "SESSIONS.md").is_file()  # the workspace, from the packaged templates
