"""``phyagentos view`` driven by a real headless Chromium through a real run.

One real ``phyagentos view`` server and one real ``phyagentos run`` (Agent plane,
WatchdogSupervisor, runner process, MuJoCo Franka) per module. Chromium and chromedriver
come from Debian's packages (scripts/setup.sh); nothing is downloaded.
Set PHYAGENTOS_VIEW_SCREENSHOTS=DIR to keep a screenshot of every page there
(docs/view_*.png were made so).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from selenium import webdriver
from selenium.webdriver.chrome.options import Options
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By

from phyagentos.protocol import Workspace

CLI = [sys.executable, "-m", "phyagentos.cli"]
ROOT = Path(__file__).resolve().parents[1]
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--window-size=1280,1000")

GRAPH = """\
version: 1
name: view_demo
description: A short hold, then one long enough to watch live and stop with the e-stop.
defaults:
  target: franka_tabletop
nodes:
  - id: settle
    skill: hold
    params: {duration_s: 0.5}
    accept: {still: {max_joint_motion_rad: 0.01}}
  - id: long_hold
    skill: hold
    params: {duration_s: 3600.0}
    accept: {still: {max_joint_motion_rad: 0.01}}
    depends_on: [settle]
    limits: {execution_timeout_s: 600}
  - id: after
    skill: hold
    params: {duration_s: 0.5}
    accept: {still: {max_joint_motion_rad: 0.01}}
    depends_on: [long_hold]
"""


def wait_for(predicate, *, timeout: float, interval: float = 0.1, what: str = ""):
    deadline = time.monotonic() + timeout
    while True:
        try:
            value = predicate()
        except Exception:  # noqa: BLE001 - e.g. an element replaced while we read it
            value = None
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(interval)


def start_view(workspace: Path) -> tuple[subprocess.Popen, str, str]:
    """``phyagentos view WORKSPACE --port 0``; returns the process, its URL and token."""
    proc = subprocess.Popen([*CLI, "view", str(workspace), "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=ROOT, env={**os.environ, "COLUMNS": "200"})
    url = token = None
    deadline = time.monotonic() + 60
    while (url is None or token is None) and time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        if m := re.search(r"(http://\S+/)", line):
            url = m.group(1)
        if m := re.search(r"access token \(signals\): (\S+)", line):
            token = m.group(1)
    assert url and token, "phyagentos view did not announce its URL and token"
    return proc, url.rstrip("/"), token


def browser(profile_dir: Path) -> webdriver.Chrome:
    """Headless Chromium with its profile in ``profile_dir`` (a test's own temporary directory,
    so nothing is left behind in /tmp)."""
    options = Options()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    profile_dir.mkdir(parents=True, exist_ok=True)
    options.add_argument(f"--user-data-dir={profile_dir}")
    return webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"), options=options)


def screenshot(driver, name: str) -> None:
    directory = os.environ.get("PHYAGENTOS_VIEW_SCREENSHOTS")
    if directory:
        Path(directory).mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(Path(directory) / f"view_{name}.png"))


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """A workspace with a run in progress, its view server and a browser."""
    root = tmp_path_factory.mktemp("view")
    graph = root / "view_demo.yaml"
    graph.write_text(GRAPH, encoding="utf-8")
    ws_dir = root / "ws"
    Workspace.create(ws_dir)
    view, url, token = start_view(ws_dir)
    run = subprocess.Popen([*CLI, "run", str(graph), "--workspace", str(ws_dir)], stdout=subprocess.DEVNULL,
                           stderr=open(root / "run.log", "wb"), cwd=ROOT)
    driver = browser(root / "chromium")
    try:
        yield {"ws": Workspace.open(ws_dir), "url": url, "token": token, "driver": driver, "run": run, "root": root}
    finally:
        driver.quit()
        for proc in (run, view):
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    proc.kill()


def _run_id(ws: Workspace) -> str:
    return wait_for(lambda: next((p.name for p in (ws.root / "runs").iterdir() if not p.name.startswith(".")), None),
                    timeout=60, what="the run to register")


def _long_session(ws: Workspace, run_id: str) -> str:
    return f"{run_id}-long_hold-1"


def test_dag_shows_node_states_live_as_the_run_progresses(live):
    ws, driver = live["ws"], live["driver"]
    run_id = _run_id(ws)
    driver.get(f"{live['url']}/run/{run_id}")
    # The page is never reloaded: node states arrive through server-sent events.
    wait_for(lambda: driver.find_element(By.CSS_SELECTOR, ".dag svg"), timeout=30, what="the DAG svg")

    # Each read is one script: panels are replaced whenever the workspace changes.
    def node_state(node: str) -> str:
        return driver.execute_script(
            f"const e = document.querySelector('.nodestate[data-node=\"{node}\"]'); return e ? e.textContent : ''")

    wait_for(lambda: node_state("settle") == "succeeded" and node_state("long_hold") == "running",
             timeout=120, what="settle succeeded and long_hold running in the browser")
    assert node_state("after") == "waiting"
    svg_states = driver.execute_script("return Object.fromEntries([...document.querySelectorAll('.dag svg g.cluster')]"
                                       ".map(g => [g.id, g.getAttribute('class')]))")
    assert "dagnode state-succeeded" in svg_states["node-settle"]
    assert "dagnode state-running" in svg_states["node-long_hold"]
    # Session boxes link to their pages.
    links = driver.execute_script("return [...document.querySelectorAll('.dag svg a')].map("
                                  "a => a.getAttribute('xlink:href') || a.getAttribute('href'))")
    assert f"/session/{run_id}-settle-1" in links
    screenshot(driver, "run")


def test_live_tree_changes_while_the_session_runs_and_estop_halts_it(live):
    ws, driver = live["ws"], live["driver"]
    run_id = _run_id(ws)
    sid = _long_session(ws, run_id)
    wait_for(lambda: ws.load_session(sid).state == "running", timeout=120, what="long_hold running")
    driver.get(f"{live['url']}/session/{sid}")
    ticks = set()

    def tree_ticks():
        meta = driver.find_element(By.ID, "tree-meta")
        assert meta.get_attribute("data-final") == "false"
        ticks.add(int(meta.get_attribute("data-tick")))
        return len(ticks) >= 3

    wait_for(tree_ticks, timeout=60, what="three distinct tree ticks in the browser")
    # Read in one script: the panel is replaced on every change event.
    statuses = driver.execute_script("return Object.fromEntries([...document.querySelectorAll('table.tree tr.bt')]"
                                     ".map(r => [r.cells[0].textContent.trim(), r.dataset.status]))")
    assert statuses["Hold"] == "running" and statuses["HoldStill"] == "running"
    assert statuses["ObserveAfterHold"] == "invalid"
    # The 3D panel follows the runner's checkpoint of this session.
    wait_for(lambda: driver.find_element(By.CSS_SELECTOR, "img.scene").get_attribute("data-source") == "checkpoint",
             timeout=60, what="the 3D scene rendered from the live checkpoint")
    screenshot(driver, "session_live")

    driver.find_element(By.CSS_SELECTOR, "button.sig.estop").click()
    wait_for(lambda: ws.load_session(sid).state == "cancelled", timeout=30, what="the e-stop to halt the session")
    rec = ws.load_session(sid)
    assert rec.result.error.code == "cancelled.estop"
    signals = ws.read("RUNTIME_SIGNAL").data.signals
    assert [s.kind for s in signals] == ["estop"] and "(view," in signals[0].issued_by
    # The page shows it without a reload: the session state, and the tree's final status.
    wait_for(lambda: driver.find_element(By.ID, "session-state").get_attribute("data-state") == "cancelled",
             timeout=30, what="the cancelled state in the browser")
    wait_for(lambda: driver.find_element(By.ID, "tree-meta").get_attribute("data-final") == "true",
             timeout=30, what="the final tree")
    driver.get(live["url"] + "/")
    wait_for(lambda: "E-STOP engaged" in driver.find_element(By.ID, "signal-state").text, timeout=30,
             what="the e-stop flag on the overview")
    screenshot(driver, "overview")
    # The DAG: the cancelled node, and the node behind it blocked (drawn dashed).
    driver.get(f"{live['url']}/run/{run_id}")
    wait_for(lambda: driver.execute_script(
        "const c = id => (document.getElementById(id) || {getAttribute: () => ''}).getAttribute('class');"
        "return c('node-long_hold').includes('state-cancelled') && c('node-after').includes('state-blocked');"),
        timeout=30, what="long_hold cancelled and after blocked in the DAG")
    screenshot(driver, "run_blocked")


def test_a_malformed_document_shows_file_and_line_and_the_rest_works(live):
    ws, driver = live["ws"], live["driver"]
    if live["run"].poll() is None:  # the run's agent would otherwise trip over the broken LESSONS.md
        live["run"].terminate()
        live["run"].wait(timeout=60)
    lessons = ws.path("LESSONS")
    text = lessons.read_text(encoding="utf-8")
    broken = text.replace("version: 1", "version: 1\nlessons: [unclosed", 1)
    lessons.write_text(broken, encoding="utf-8")
    bad_line = broken.splitlines().index("lessons: [unclosed") + 1
    driver.get(live["url"] + "/memory")
    text = wait_for(lambda: driver.find_element(By.CSS_SELECTOR, ".error").text, timeout=30, what="the error box")
    m = re.search(r"LESSONS\.md:(\d+): YAML syntax error", text)
    assert m and bad_line <= int(m.group(1)) <= bad_line + 2, (bad_line, text)
    # The other memory documents still render as tables, and so do the other pages.
    assert "KNOWLEDGE.md" in driver.page_source and "SKILL.md" in driver.page_source
    screenshot(driver, "memory_error")
    lessons.write_text(text, encoding="utf-8")
    driver.get(live["url"] + "/")
    wait_for(lambda: driver.find_elements(By.CSS_SELECTOR, "table.runs a"), timeout=30, what="the runs table")
