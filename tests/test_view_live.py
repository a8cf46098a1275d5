"""The live view's three bugs of issue 34, each in a real headless Chromium.

One real ``phyagentos run`` (a pick of a heavy cube that slips, replanned with a firmer
grip, recorded with ``--record all``) gives a workspace with a ``replanned`` session and
its recording; a real ``phyagentos view`` serves it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from selenium.webdriver.common.by import By
from test_view_browser import browser, screenshot, start_view, wait_for

from phyagentos.protocol import Workspace
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.protocol.schemas import RunRecord, utc_now_iso

CLI = [sys.executable, "-m", "phyagentos.cli"]
ROOT = Path(__file__).resolve().parents[1]



def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


@pytest.fixture(scope="module")
def replanned(tmp_path_factory):
    """A finished run whose first session was replanned, recorded; its view server and a browser."""
    root = tmp_path_factory.mktemp("replan")
    ws_dir = root / "ws"
    proc = subprocess.run([*CLI, "run", "replan_demo", "--workspace", str(ws_dir), "--record", "all"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ws = Workspace.open(ws_dir)
    sessions = {s.state: s for s in ws.list_sessions()}
    assert set(sessions) == {"replanned", "succeeded"}, sessions
    view, url, _token = start_view(ws_dir)
    driver = browser(root / "chromium")
    try:
        yield {"ws": ws, "url": url, "driver": driver, "failed": sessions["replanned"],
               "child": sessions["succeeded"], "view": view}
    finally:
        driver.quit()
        _stop(view)


def _loaded(driver) -> bool:
    """Every panel of the page has been filled from its fragment at least once."""
    return driver.execute_script("return document.readyState === 'complete' && "
                                 "[...document.querySelectorAll('[data-fragment]')].every(e => e.dataset.html !== undefined)")


def test_many_navigations_in_one_tab_and_seven_tabs_all_load_quickly(replanned):
    driver, url = replanned["driver"], replanned["url"]
    run_id, failed = replanned["failed"].run_id, replanned["failed"].session_id
    driver.set_page_load_timeout(20)
    pages = ["/", f"/run/{run_id}", f"/session/{failed}", "/memory"]
    times = []
    for i in range(10):  # more than Chromium's 6 connections per host
        t0 = time.monotonic()
        driver.get(url + pages[i % len(pages)])
        wait_for(lambda: _loaded(driver), timeout=8, what=f"navigation {i + 1} to load")
        wait_for(lambda: driver.execute_script("return window.phyagentosStream() === 1"), timeout=8,
                 what=f"navigation {i + 1}'s live stream to open")
        times.append(time.monotonic() - t0)
    # back and forward through the cache: the page comes back with its stream reopened
    driver.back()
    wait_for(lambda: driver.execute_script("return window.phyagentosStream() === 1"), timeout=8,
             what="the stream after going back")
    first = driver.current_window_handle
    for i in range(7):  # seven tabs, each with the live index
        driver.switch_to.new_window("tab")
        t0 = time.monotonic()
        driver.get(url + "/")
        wait_for(lambda: _loaded(driver), timeout=8, what=f"tab {i + 2} to load")
        times.append(time.monotonic() - t0)
    assert max(times) < 8, times
    for handle in driver.window_handles:
        if handle != first:
            driver.switch_to.window(handle)
            driver.close()
    driver.switch_to.window(first)


def test_the_3d_panel_of_a_replanned_session_shows_its_recording(replanned):
    driver, url, failed = replanned["driver"], replanned["url"], replanned["failed"]
    assert (replanned["ws"].root / "evidence" / failed.session_id / "frames.npz").is_file()
    driver.get(f"{url}/session/{failed.session_id}")
    wait_for(lambda: driver.find_element(By.ID, "session-state").get_attribute("data-state") == "replanned",
             timeout=15, what="the replanned state")
    assert driver.find_element(By.ID, "session-state").get_attribute("data-finished") == "true"
    wait_for(lambda: driver.find_element(By.CSS_SELECTOR, "img.scene").get_attribute("data-source") == "recording",
             timeout=20, what="the 3D scene rendered from the recording")
    slider = driver.find_element(By.CSS_SELECTOR, "input.frame")
    assert slider.is_enabled() and int(slider.get_attribute("max")) > 10
    # the tree table never lies over the 3D image (narrow window: the columns stack or scroll)
    wait_for(lambda: driver.find_elements(By.CSS_SELECTOR, "table.tree tr.bt"), timeout=15, what="the tree")
    for width in (1280, 900):
        driver.set_window_size(width, 1000)
        hit = driver.execute_script("const i = document.querySelector('img.scene'); i.scrollIntoView({block: 'center'});"
                                    "const r = i.getBoundingClientRect();"
                                    "const e = document.elementFromPoint(r.left + 5, r.top + r.height / 2);"
                                    "return e ? e.tagName + '.' + e.className : ''")
        assert hit == "IMG.scene", (width, hit)
    driver.set_window_size(1280, 1000)
    # overlays: perceived object, grasp target and the tool path drawn into the same frame
    frame = driver.find_element(By.CSS_SELECTOR, "img.scene").get_attribute("data-shown")
    driver.find_element(By.CSS_SELECTOR, "input.overlays").click()
    wait_for(lambda: int(driver.find_element(By.CSS_SELECTOR, "img.scene").get_attribute("data-overlays") or 0) > 10,
             timeout=20, what="the overlays drawn")
    img = driver.find_element(By.CSS_SELECTOR, "img.scene")
    assert img.get_attribute("data-shown") == frame and img.get_attribute("data-source") == "recording"
    driver.execute_script("document.querySelector('img.scene').scrollIntoView({block: 'start'})")
    screenshot(driver, "session_replanned")


def _kinds(img) -> dict[str, int]:
    text = img.get_attribute("data-overlay-kinds") or ""
    return {k: int(v) for k, v in (item.split("=") for item in text.split(",") if item)}


def test_the_3d_overlays_draw_the_planned_path_camera_frustums_and_the_cloud_perceived_at_that_instant(replanned):
    import io
    import urllib.request

    from PIL import Image

    driver, url, failed = replanned["driver"], replanned["url"], replanned["failed"]
    sid = failed.session_id
    evidence = replanned["ws"].root / "evidence" / sid
    trace = [json.loads(line) for line in (evidence / "trace.jsonl").read_text().splitlines()]
    # the runtime recorded the plan (joint path, bounded) and perception its object cloud per observation
    plans = [r for r in trace if r["kind"] == "plan" and r.get("path_rad")]
    assert plans and all(2 <= len(p["path_rad"]) <= 64 and len(p["path_rad"][0]) == 7 for p in plans)
    clouds = {p.name: np.load(p)["points"] for p in (evidence / "frames").glob("*_cloud.npz")}
    assert {"initial_cloud.npz", "01_ObserveScene_cloud.npz", "terminal_cloud.npz"} <= set(clouds)
    assert all(0 < len(c) <= 4000 and c.shape[1] == 3 for c in clouds.values())
    observed_at = next(r["stamp_s"] for r in trace if r["kind"] == "observe")

    driver.get(f"{url}/session/{sid}")
    img = wait_for(lambda: (lambda i: i if i.get_attribute("data-source") == "recording" else None)(
        driver.find_element(By.CSS_SELECTOR, "img.scene")), timeout=20, what="the 3D scene from the recording")
    legend = driver.find_element(By.CSS_SELECTOR, ".scene3d .legend")
    assert legend.find_element(By.CSS_SELECTOR, ".gt-label").text == "ground truth"
    assert "robot's own data" in legend.find_element(By.CSS_SELECTOR, ".ov-label").text
    for word in ("planned path", "camera frustums", "point cloud"):
        assert word in legend.text
    driver.find_element(By.CSS_SELECTOR, "input.frame")  # the frame slider is there (raises otherwise)
    frames = driver.execute_script(f"return fetch('/api/frames/{sid}').then(r => r.json()).then(j => j.t)")

    def show_frame(i: int) -> None:
        driver.execute_script(f"const s = document.querySelector('input.frame'); s.value = '{i}';"
                              "s.dispatchEvent(new Event('input'))")
        wait_for(lambda: img.get_attribute("data-shown") == str(i), timeout=20, what=f"frame {i}")

    show_frame(0)
    assert img.get_attribute("data-overlays") == "0" and _kinds(img) == {}
    driver.find_element(By.CSS_SELECTOR, "input.overlays").click()
    wait_for(lambda: int(img.get_attribute("data-overlays") or 0) > 0, timeout=20, what="the overlays drawn")
    kinds = _kinds(img)
    assert kinds["planned_path"] >= len(plans)  # the tool along every plan, joined
    assert kinds["frustum"] == 16  # overview and wrist cameras of sensors.yaml, 8 edges each
    assert kinds["cloud"] == len(clouds["initial_cloud.npz"])  # the cloud perceived before the skill
    assert kinds["perceived"] >= 1 and kinds["tcp_path"] > 10 and kinds["grasp"] >= 1
    assert img.get_attribute("data-cloud") == "initial_cloud.npz"
    info = driver.find_element(By.CSS_SELECTOR, ".overlay-info").text
    assert "planned_path=" in info and "cloud of initial" in info
    # the cloud in force follows the instant: the first observation's after it, the terminal one at the end
    after = next(i for i, t in enumerate(frames) if t >= observed_at)
    show_frame(after)
    wait_for(lambda: img.get_attribute("data-cloud") == "01_ObserveScene_cloud.npz", timeout=20,
             what="the first observation's cloud")
    assert _kinds(img)["cloud"] == len(clouds["01_ObserveScene_cloud.npz"])
    show_frame(len(frames) - 1)
    wait_for(lambda: img.get_attribute("data-cloud") == "terminal_cloud.npz", timeout=20, what="the terminal cloud")
    # drawn, not only counted: the same instant with overlays has cyan (planned path) and blue
    # (perceived cloud and objects) pixels that the plain ground-truth render has not
    def pixels(overlays: bool) -> np.ndarray:
        q = f"/api/scene/{sid}.png?frame={after}&az=140&el=-25&dist=1.2" + ("&overlays=1" if overlays else "")
        with urllib.request.urlopen(url + q, timeout=60) as r:
            return np.asarray(Image.open(io.BytesIO(r.read())).convert("RGB")).astype(int)

    plain, drawn = pixels(False), pixels(True)
    r, g, b = drawn[..., 0], drawn[..., 1], drawn[..., 2]
    cyan = (g > 120) & (b > 120) & (r < 60) & (np.abs(g - b) < 40)
    blue = (b > 120) & (r < 60) & (g < b - 50)
    pr, pg, pb = plain[..., 0], plain[..., 1], plain[..., 2]
    assert cyan.sum() > 30 and blue.sum() > 100, (cyan.sum(), blue.sum())
    assert (((pg > 120) & (pb > 120) & (pr < 60)) | ((pb > 120) & (pr < 60) & (pg < pb - 50))).sum() < 10
    # zoomed in on the grasp, for the docs
    show_frame(after)
    for _ in range(5):
        driver.execute_script("document.querySelector('img.scene').dispatchEvent("
                              "new WheelEvent('wheel', {deltaY: -100, cancelable: true}))")
    wait_for(lambda: "dist=1.12" in (driver.execute_script("return performance.getEntriesByType('resource')"
                                                           ".map(e => e.name).filter(n => n.includes('/api/scene/'))"
                                                           ".slice(-1)[0]") or ""), timeout=20, what="the zoom")
    wait_for(lambda: img.get_attribute("data-cloud") == "01_ObserveScene_cloud.npz", timeout=20, what="re-render")
    time.sleep(1.0)
    driver.execute_script("document.querySelector('.scene3d').scrollIntoView({block: 'start'})")
    screenshot(driver, "session_overlays")


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_the_index_with_1000_runs_stays_cheap_under_churn_and_is_paged(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    for i in range(1000):
        ws.runs.register(RunRecord(run_id=f"r{i:05d}", goal_graph="g.yaml", graph_file="",
                                   submitted_at=utc_now_iso()), "version: 1\nname: g\nnodes: []\n")
    view, url, _ = start_view(tmp_path / "ws")
    driver = browser(tmp_path / "chromium")
    try:
        driver.get(url + "/")
        wait_for(lambda: driver.find_element(By.CSS_SELECTOR, ".pager").get_attribute("data-pages") == "20",
                 timeout=20, what="the first page of 20")
        assert len(driver.find_elements(By.CSS_SELECTOR, "table.runs tbody tr")) == 50
        # churn: a session file rewritten at 20 Hz (what a live session does), an index hint
        # renamed at 2 Hz and a run registered every second, for 5 s
        index = ws.root / "sessions" / ".index"
        index.mkdir(parents=True, exist_ok=True)
        hint = index / "churn-1~running"
        hint.write_text("{}")
        cpu0, w0, i = _cpu_s(view.pid), time.monotonic(), 0
        while time.monotonic() - w0 < 5.0:
            i += 1
            atomic_write_text(ws.root / "sessions" / "churn-1.md", f"beat {i}\n")
            if i % 10 == 0:
                dest = index / ("churn-1~" + ("claimed" if hint.name.endswith("running") else "running"))
                os.rename(hint, dest)
                hint = dest
            if i % 20 == 0:
                ws.runs.register(RunRecord(run_id=f"new{i:04d}", goal_graph="g.yaml", graph_file="",
                                           submitted_at=utc_now_iso()), "version: 1\nname: g\nnodes: []\n")
            time.sleep(0.05)
        cpu = (_cpu_s(view.pid) - cpu0) / (time.monotonic() - w0)
        # the newest run is on page 1 without a reload
        wait_for(lambda: "new" in driver.find_element(By.CSS_SELECTOR, "table.runs tbody tr a").text, timeout=10,
                 what="the newest run at the top of page 1")
        assert cpu < 0.25, f"view server used {cpu:.0%} of a core under churn"
        driver.find_element(By.CSS_SELECTOR, ".pager a[rel=next]").click()
        wait_for(lambda: driver.find_element(By.CSS_SELECTOR, ".pager").get_attribute("data-page") == "2",
                 timeout=10, what="page 2")
    finally:
        driver.quit()
        _stop(view)


HOLD_GRAPH = """\
version: 1
name: paused_demo
description: One hold submitted while no supervisor runs.
defaults:
  target: franka_tabletop
nodes:
  - id: settle
    skill: hold
    params: {duration_s: 0.5}
    accept: {still: {max_joint_motion_rad: 0.01}}
"""


def test_pause_and_estop_in_force_show_on_the_run_and_session_pages(tmp_path):
    graph = tmp_path / "paused_demo.yaml"
    graph.write_text(HOLD_GRAPH, encoding="utf-8")
    ws_dir = tmp_path / "ws"
    proc = subprocess.run([*CLI, "submit", str(graph), "--workspace", str(ws_dir)], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    ws = Workspace.open(ws_dir)
    (sid, state, ident), = ws.active_sessions()
    assert state == "pending"
    view, url, _ = start_view(ws_dir)
    driver = browser(tmp_path / "chromium")
    try:
        driver.get(url + "/")
        pause = wait_for(lambda: driver.find_element(By.CSS_SELECTOR, "button.sig[data-kind=pause]"), timeout=15,
                         what="the pause button")
        assert pause.text == "pause dispatch" and "no new session" in pause.get_attribute("title")
        pause.click()
        wait_for(lambda: driver.find_elements(By.CSS_SELECTOR, "#signal-state [data-signal=paused]"), timeout=15,
                 what="the pause on the index")
        driver.get(f"{url}/run/{ident.run_id}")

        def node_text() -> str:
            return driver.execute_script("const e = document.querySelector('.nodestate[data-node=\"settle\"]');"
                                         "return e ? e.textContent : ''")

        wait_for(lambda: node_text() == "paused", timeout=15, what="the node shown paused on the run page")
        assert driver.find_elements(By.CSS_SELECTOR, ".signal-state [data-signal=paused]")
        assert "state-paused" in driver.find_element(By.ID, "node-settle").get_attribute("class")
        screenshot(driver, "run_paused")
        driver.get(f"{url}/session/{sid}")
        wait_for(lambda: driver.find_element(By.ID, "session-state").get_attribute("data-held") == "paused",
                 timeout=15, what="the session held by the pause")
        assert "running" not in driver.find_element(By.ID, "session-state").text
        driver.find_element(By.CSS_SELECTOR, "button.sig.estop").click()
        wait_for(lambda: driver.find_element(By.ID, "session-state").get_attribute("data-held") == "held_by_estop",
                 timeout=15, what="the session held by the e-stop, without a reload")
        assert driver.find_elements(By.CSS_SELECTOR, ".signal-state [data-signal=estop]")
        assert driver.find_elements(By.CSS_SELECTOR, ".signal-state [data-signal=paused]")
    finally:
        driver.quit()
        _stop(view)


def test_one_cursor_moves_the_plots_the_3d_frame_the_images_and_the_transitions(replanned):
    from selenium.webdriver.common.action_chains import ActionChains

    driver, url, failed = replanned["driver"], replanned["url"], replanned["failed"]
    driver.get(f"{url}/session/{failed.session_id}")
    wait_for(lambda: driver.find_element(By.CSS_SELECTOR, "section.timeline").get_attribute("data-ready") == "true",
             timeout=20, what="the timeline")
    names = driver.execute_script("return [...document.querySelectorAll('.tl-plot')].map(p => p.dataset.name)")
    assert names == ["joint positions", "gripper opening", "finger effort", "wrist force", "tracking error"], names
    sig = driver.execute_script(f"return fetch('/api/signals/{failed.session_id}').then(r => r.json())")
    frames, t0, t1 = sig["frames"], sig["t0"], sig["t1"]
    assert [e["code"] for e in sig["events"]] == ["grasp.slip"]  # the slip that made the verifier replan

    def state():
        return driver.execute_script(
            "const img = document.querySelector('img.scene');"
            "return {cursor: Number(document.querySelector('section.timeline').dataset.cursorT),"
            " slider: Number(document.querySelector('input.frame').value), shown: img.dataset.shown,"
            " t3d: Number(img.dataset.t), at: [...document.querySelectorAll('ol.timeline li')]"
            "   .findIndex(li => li.classList.contains('at-cursor')),"
            " images: [...document.querySelectorAll('.tl-images img')].map(i => i.dataset.name)}")

    hist = driver.execute_script(f"return fetch('/files/evidence/{failed.session_id}/tree_history.json')"
                                 ".then(r => r.json())")
    assert hist["entries"] and all(e[1] is not None for e in hist["entries"])

    def tree_at_cursor():
        return driver.execute_script(
            "const b = document.querySelector('.tree-graph');"
            "return {tick: b ? Number(b.dataset.replayTick) : -1,"
            " codes: [...document.querySelectorAll('.tree-graph g.btn')].map(g => g.getAttribute('class')),"
            " leaves: [...document.querySelectorAll('.tree-graph g.active-leaf title')].map(t => t.textContent)}")

    canvas = driver.find_elements(By.CSS_SELECTOR, "canvas.tl-canvas")[3]  # the wrist force plot
    width = canvas.size["width"]
    ticks = []
    for fraction in (0.3, 0.75):
        # click at `fraction` of the time axis (52 px left margin, 8 px right)
        x = 52 + (width - 60) * fraction
        ActionChains(driver).move_to_element_with_offset(canvas, int(x - width / 2), 0).click().perform()
        want = t0 + (t1 - t0) * fraction
        wait_for(lambda: abs(state()["cursor"] - want) < (t1 - t0) * 0.02, timeout=5, what="the cursor on the plots")
        s = state()
        nearest = min(range(len(frames)), key=lambda i: abs(frames[i] - s["cursor"]))
        wait_for(lambda: state()["shown"] == str(nearest) and abs(state()["t3d"] - frames[nearest]) < 1e-3,
                 timeout=15, what=f"the 3D scene at frame {nearest}")
        assert state()["slider"] == nearest
        assert state()["at"] == 3  # the item after "start": the session is running at that instant
        assert any(n.startswith("01_ObserveScene") for n in state()["images"])  # the last camera image before it
        # the tree replays the history entry in force at the cursor: statuses and the running leaf
        cur = state()["cursor"]
        entry = [e for e in hist["entries"] if e[1] <= cur + 1e-9][-1]
        wait_for(lambda: tree_at_cursor()["tick"] == entry[0], timeout=5, what=f"the tree at tick {entry[0]}")
        tree = tree_at_cursor()
        names = {"R": "running", "S": "success", "F": "failure", "I": "invalid"}
        assert [c.split()[1] for c in tree["codes"]] == [f"bt-{names[c]}" for c in entry[2]]
        running_leaves = [n for n, c in zip(hist["nodes"], entry[2]) if c == "R" and n["kind"] == "leaf"]
        assert len(tree["leaves"]) == len(running_leaves) >= 1
        assert tree["leaves"][0].startswith(running_leaves[0]["name"])
        ticks.append(entry[0])
    assert ticks[0] < ticks[1]
    screenshot(driver, "timeline")
    # the 3D slider moves the cursor (and so the plots) back
    driver.execute_script("const s = document.querySelector('input.frame'); s.value = '2';"
                          "s.dispatchEvent(new Event('input'))")
    wait_for(lambda: abs(state()["cursor"] - frames[2]) < 1e-3, timeout=5, what="the cursor following the slider")
    assert state()["at"] in (0, 3)


def test_a_session_exports_as_a_rerun_recording_that_reads_back(replanned, tmp_path):
    from rerun.chunk import RrdReader

    ws, failed = replanned["ws"], replanned["failed"]
    sid = failed.session_id
    proc = subprocess.run([*CLI, "view", str(ws.root), "--export-rrd", sid], cwd=ROOT, capture_output=True,
                          text=True, timeout=180)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    path = ws.root / "evidence" / sid / "recording.rrd"
    assert path.is_file() and str(path) in proc.stdout.replace("\n", "")
    reader = RrdReader(path)
    assert [r.recording_id for r in reader.recordings()] == [sid]
    columns: dict[str, dict[str, list]] = {}
    for chunk in reader.store().stream().to_chunks():
        batch = chunk.to_record_batch()
        col = columns.setdefault(chunk.entity_path, {})
        for name in batch.schema.names:
            if name in ("sim_time", "Scalars:scalars", "TextLog:text"):
                col.setdefault(name, []).extend(batch.column(name).to_pylist())
    frames = np.load(ws.root / "evidence" / sid / "frames.npz")
    assert {f"/joints/joint{i}" for i in range(1, 8)} <= set(columns)
    assert len(columns["/joints/joint2"]["Scalars:scalars"]) == len(frames["t"])
    assert np.allclose([v[0] for v in columns["/joints/joint2"]["Scalars:scalars"]], frames["qpos"][:, 1], atol=1e-4)
    trace = [json.loads(line) for line in (ws.root / "evidence" / sid / "trace.jsonl").read_text().splitlines()]
    loads = [(r["stamp_s"], r["wrist_load_n"]) for r in trace if r["kind"] == "proprio" and r["wrist_load_n"] is not None]
    got = sorted(zip((t.total_seconds() for t in columns["/wrist/force_n/load"]["sim_time"]),
                     (v[0] for v in columns["/wrist/force_n/load"]["Scalars:scalars"])))
    assert np.allclose(got, sorted(loads), atol=1e-3)
    slip = next(r for r in trace if r["kind"] == "slip")
    assert any("grasp.slip" in text[0] for text in columns["/events"]["TextLog:text"])
    assert abs(columns["/events"]["sim_time"][0].total_seconds() - slip["stamp_s"]) < 1e-3
    hist = json.loads((ws.root / "evidence" / sid / "tree_history.json").read_text())
    assert len(columns["/tree"]["TextLog:text"]) == len(hist["entries"])
    assert {"/camera/overview", "/camera/wrist", "/world/tcp", "/transitions"} <= set(columns)


def test_the_compare_page_shows_a_failed_attempt_and_its_replan_child_under_one_cursor(replanned):
    from selenium.webdriver.common.action_chains import ActionChains

    driver, url, failed, child = replanned["driver"], replanned["url"], replanned["failed"], replanned["child"]
    assert child.parent_session_id == failed.session_id
    driver.get(f"{url}/session/{failed.session_id}")
    link = wait_for(lambda: driver.find_element(By.CSS_SELECTOR, "a.compare-link"), timeout=15, what="compare link")
    link.click()
    wait_for(lambda: driver.execute_script("return [...document.querySelectorAll('section.timeline')]"
                                           ".filter(s => s.dataset.ready === 'true').length") == 2,
             timeout=20, what="both timelines")
    states = driver.execute_script("return [...document.querySelectorAll('.compare-col .session-state')]"
                                   ".map(s => s.dataset.state)")
    assert states == ["replanned", "succeeded"]
    # the child gripped harder (the revision's firmer grip): its finger effort peaks higher
    peaks = driver.execute_script(
        "return Promise.all([...document.querySelectorAll('section.timeline')].map(s =>"
        " fetch('/api/signals/' + s.dataset.session).then(r => r.json()).then(j =>"
        " Math.max(...j.plots.find(p => p.name === 'finger effort').lines[0].y.filter(y => y !== null)))))")
    assert peaks[1] > peaks[0] > 0, peaks
    canvases = driver.find_elements(By.CSS_SELECTOR, ".compare-col:first-child canvas.tl-canvas")
    width = canvases[0].size["width"]
    ActionChains(driver).move_to_element_with_offset(canvases[0], int(52 + (width - 60) * 0.5 - width / 2), 0) \
        .click().perform()
    cursors = wait_for(lambda: (lambda c: c if len(set(c)) == 1 and c[0] else None)(driver.execute_script(
        "return [...document.querySelectorAll('section.timeline')].map(s => s.dataset.cursorT)")),
        timeout=5, what="one cursor in both columns")
    assert float(cursors[0]) > 0
    # each column on its own session's clock: the child's axis starts at 0 too, so the cursor lies inside both
    spans = driver.execute_script("return [...document.querySelectorAll('.tl-info')].map(i => i.textContent)")
    assert all(x.startswith("0.00–") for x in spans), spans
    screenshot(driver, "compare")
