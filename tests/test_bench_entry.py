"""`python -m bench` is the one entry point of the benchmarks in bench/."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_list_names_every_benchmark_script_and_no_helper():
    out = bench("list")
    assert out.returncode == 0
    names = {line.split()[0] for line in out.stdout.splitlines() if line.strip()}
    scripts = {p.stem for p in (ROOT / "bench").glob("*.py") if not p.stem.startswith("_")}
    assert names == scripts and "end_to_end" in names and "_supervisor_common" not in names


def test_an_unknown_benchmark_exits_2_listing_the_valid_names():
    out = bench("no_such_bench")
    assert out.returncode == 2
    assert "no_such_bench" in out.stderr and "end_to_end" in out.stderr and "list" in out.stderr


def test_arguments_after_the_name_reach_the_benchmark():
    out = bench("safety_guard", "--help")
    assert out.returncode == 0 and "usage:" in out.stdout
