"""CPU of the ``phyagentos view`` server with its index page open in a real browser.

    .venv/bin/python bench/view_load.py [--runs 1 1000] [--seconds 10] [--json]

For each run count: a fresh workspace with that many registered runs (RunRegistry, the
way ``phyagentos run`` registers them), a real ``phyagentos view`` server, and headless
Chromium (Selenium) showing the index page. Then two phases of ``--seconds`` each:

- ``idle``: nothing changes;
- ``churn``: what a live run does to the watched directories: a session file rewritten
  (temporary file + rename) 20 times a second, a session index hint renamed 2 times a
  second (a state transition) and one new run registered every second.

Reported: the view server's CPU (user + system time from ``/proc/<pid>/stat``) as a
percentage of one core over each phase, the time until the index shows its run table,
the page's fragment requests in each phase (the browser's ``performance`` entries), and the
update latency: the median time from a pause or resume written to RUNTIME_SIGNAL.md until the
open page shows it (after the churn phase).
To measure another checkout (e.g. before a change), run this file with that checkout on
PYTHONPATH: the server is started as ``python -m phyagentos.cli`` from ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from phyagentos.protocol import Workspace
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.protocol.schemas import RunRecord, utc_now_iso

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--window-size=1280,1000")
GRAPH = "version: 1\nname: bench\nnodes: []\n"


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (s), from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def register_runs(ws: Workspace, n: int, start: int = 0) -> None:
    for i in range(start, start + n):
        ws.runs.register(RunRecord(run_id=f"r{i:05d}", goal_graph="bench.yaml", graph_file="", submitted_at=utc_now_iso()),
                         GRAPH)


def start_view(workspace: Path) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([sys.executable, "-m", "phyagentos.cli", "view", str(workspace), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "COLUMNS": "200"}, cwd=workspace.parent)  # PYTHONPATH picks the code
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if m := re.search(r"(http://\S+/)", line):
            return proc, m.group(1).rstrip("/")
        if not line:
            break
    proc.kill()
    raise RuntimeError("phyagentos view did not announce its URL")


def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tempfile.mkdtemp(prefix='phyagentos-bench-chromium-')}")
    return webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"), options=options)


class Churn:
    """Writes what a live run writes to the watched directories (see the module docstring)."""

    def __init__(self, ws: Workspace, first_run: int) -> None:
        self.ws = ws
        self.next_run = first_run
        self.sessions = ws.root / "sessions"
        self.index = ws.root / "sessions" / ".index"
        self.index.mkdir(parents=True, exist_ok=True)
        self.hint = self.index / "bench-churn-1~running"
        self.hint.write_text("{}")
        self.i = 0

    def step(self) -> None:
        """One 50 ms step."""
        self.i += 1
        atomic_write_text(self.sessions / "bench-churn-1.md", f"heartbeat {self.i}\n")
        if self.i % 10 == 0:
            dest = self.index / ("bench-churn-1~" + ("claimed" if self.hint.name.endswith("running") else "running"))
            os.rename(self.hint, dest)
            self.hint = dest
        if self.i % 20 == 0:
            register_runs(self.ws, 1, self.next_run)
            self.next_run += 1


def fragment_requests(driver) -> int:
    return driver.execute_script(
        "return performance.getEntriesByType('resource').filter(e => e.name.includes('/fragment/')).length")


def update_latency_ms(ws: Workspace, driver, rounds: int = 6) -> float:
    """Median time (ms) from a signal written to RUNTIME_SIGNAL.md (pause, then resume) until
    the open index page shows it, polled every 5 ms in the browser."""
    samples = []
    for i in range(rounds):
        kind, flag = ("pause", "paused") if i % 2 == 0 else ("resume", "none")
        t0 = time.monotonic()
        ws.send_signal(kind, reason="bench", issued_by="bench")
        deadline = t0 + 10
        while time.monotonic() < deadline:
            if driver.execute_script(f"return !!document.querySelector('#signal-state [data-signal={flag}]')"):
                break
            time.sleep(0.005)
        samples.append((time.monotonic() - t0) * 1000)
    samples.sort()
    return round(samples[len(samples) // 2], 1)


def measure(n_runs: int, seconds: float) -> dict:
    root = Path(tempfile.mkdtemp(prefix="phyagentos-view-load-"))
    ws = Workspace.create(root / "ws")
    register_runs(ws, n_runs)
    view, url = start_view(root / "ws")
    driver = browser()
    out: dict = {"runs": n_runs}
    try:
        driver.set_page_load_timeout(60)
        t0 = time.monotonic()
        driver.get(url + "/")
        deadline = time.monotonic() + 60
        while not driver.execute_script("return document.querySelectorAll('table.runs tr').length") \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        out["index_load_s"] = round(time.monotonic() - t0, 3)
        time.sleep(1.0)
        for phase in ("idle", "churn"):
            churn = Churn(ws, n_runs) if phase == "churn" else None
            req0, cpu0, w0 = fragment_requests(driver), cpu_seconds(view.pid), time.monotonic()
            while time.monotonic() - w0 < seconds:
                if churn:
                    churn.step()
                time.sleep(0.05)
            time.sleep(0.3)  # let the last event be served
            wall = time.monotonic() - w0
            out[f"{phase}_cpu_pct"] = round(100 * (cpu_seconds(view.pid) - cpu0) / wall, 1)
            out[f"{phase}_fragment_requests"] = fragment_requests(driver) - req0
        out["rows_shown"] = driver.execute_script("return document.querySelectorAll('table.runs tbody tr').length")
        out["update_latency_ms"] = update_latency_ms(ws, driver)
    finally:
        driver.quit()
        view.terminate()
        try:
            view.wait(timeout=10)
        except subprocess.TimeoutExpired:
            view.kill()
        shutil.rmtree(root, ignore_errors=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, nargs="+", default=[1, 1000])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = ap.parse_args()
    rows = [measure(n, args.seconds) for n in args.runs]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    cols = ("runs", "index_load_s", "rows_shown", "idle_cpu_pct", "churn_cpu_pct", "idle_fragment_requests",
            "churn_fragment_requests", "update_latency_ms")
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(str(r.get(c, "")) for c in cols))
    return 0


if __name__ == "__main__":
    sys.exit(main())
