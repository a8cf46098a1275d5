"""scripts/suite_cpu.py: the suite's CPU charged to the test whose process tree spent it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "suite_cpu.py"

TESTS = '''\
import subprocess, sys, time

def test_burns_in_a_child():
    subprocess.run([sys.executable, "-c",
                    "import time\\nt = time.process_time()\\nwhile time.process_time() - t < 1.5: pass"], check=True)

def test_sleeps():
    time.sleep(1.0)

def test_fails():
    assert False
'''


def test_a_childs_cpu_is_charged_to_the_test_that_started_it_and_pytests_exit_code_is_kept(tmp_path):
    (tmp_path / "test_burn.py").write_text(TESTS, encoding="utf-8")
    out = tmp_path / "cpu.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--interval", "0.2", "--",
                           "-q", "-p", "no:cacheprovider", str(tmp_path / "test_burn.py")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1, proc.stdout + proc.stderr  # test_fails failed: pytest's code passes through
    table = json.loads(out.read_text())
    per_test = {node.split("::")[-1]: cpu for node, cpu in table["per_test"].items()}
    # the child burned 1.5 CPU-s; sampled every 0.2 s, at most the last interval is missed
    assert per_test["test_burns_in_a_child"] >= 1.2, table
    assert per_test.get("test_sleeps", 0.0) < 0.3, table
    (row,) = [row for name, row in table["per_file"].items() if name.endswith("test_burn.py")]
    assert row["python -c"] >= 1.2 and row["cpu_s"] >= row["python -c"], row
    assert 0 < table["charged_cpu_s"] <= table["machine_cpu_s"] and table["wall_s"] >= 1.0
    assert "test_burn.py  (python -c" in proc.stdout
