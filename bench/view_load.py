"""Page loads, CPU and memory of the ``phyagentos view`` server, in a real headless Chromium.

    .venv/bin/python bench/view_load.py [--runs 1 1000] [--seconds 10] [--pages] [--json]
    .venv/bin/python bench/view_load.py --soak-minutes 60 [--soak-interval 3] [--soak-out soak.json]

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

``--pages`` adds page loads of every page kind. A real ``phyagentos run ... --record all``
(a pick of a heavy cube that slips, replanned with a firmer grip: a ``replanned`` session
and its ``succeeded`` child, both recorded) is made once; each run count's workspace is a
copy of it plus that many registered runs. Each page (index, the run's DAG, the replanned
session, the compare page of the two sessions) is loaded once cold and ``--page-repeats``
times more, and timed from ``driver.get`` until every panel is filled from its fragment
(``panels_s``) and until the page is complete: the panels, every timeline drawn and every
3D image rendered (``complete_s``). The first session-page load includes rebuilding the
session's MuJoCo model for the 3D panel.

``--soak-minutes N`` (memory after N minutes of browsing) serves a copy of that run's
workspace under churn (as above, but one new run every ``--soak-run-every`` s) to two real
headless Chromiums: one keeps the index open the whole time (its live updates), the other
clicks through index, run, both session pages (clicking the timeline at a random instant,
so the 3D panel renders that frame; overlays toggled on every other visit), compare and
memory, one navigation every ``--soak-interval`` s. Every ``--soak-sample`` s it samples
the view server's RSS (``VmRSS``), both pages' JS heap after a forced garbage collection
(Chrome DevTools ``Runtime.getHeapUsage``) and both browsers' proportional set size
(``Pss`` summed over chromedriver's process tree). Reported: start, end and max of each,
and the least-squares slope in MiB per hour over all samples and from minute 10 on;
samples are written to ``--soak-out`` as they come.
"""

from __future__ import annotations

import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from _harness import parser, write_json

from phyagentos.protocol import Workspace
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.protocol.schemas import RunRecord, utc_now_iso

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--window-size=1280,1000")
GRAPH = "version: 1\nname: bench\nnodes: []\n"
#: True once every panel of the page has been filled from its fragment.
PANELS_JS = ("return document.readyState === 'complete' && "
             "[...document.querySelectorAll('[data-fragment]')].every(e => e.dataset.html !== undefined)")
#: True once the panels are filled, every timeline drawn and every 3D image rendered.
COMPLETE_JS = (PANELS_JS
               + " && [...document.querySelectorAll('section.timeline')].every(s => s.dataset.ready === 'true')"
               " && [...document.querySelectorAll('img.scene')].every(i => !!i.dataset.source)")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (s), from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def register_runs(ws: Workspace, n: int, start: int = 0) -> None:
    for i in range(start, start + n):
        ws.runs.register(RunRecord(run_id=f"r{i:05d}", goal_graph="bench.yaml", graph_file="", submitted_at=utc_now_iso()),
                         GRAPH)


def start_view(workspace: Path) -> tuple[subprocess.Popen, str]:
    """A real ``phyagentos view`` on ``workspace``; its output goes to ``view.log`` next to
    the workspace (a pipe nobody reads would fill and block the server's logging)."""
    log = (workspace.parent / "view.log").open("w")
    proc = subprocess.Popen([sys.executable, "-m", "phyagentos.cli", "view", str(workspace), "--port", "0"],
                            stdout=log, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "COLUMNS": "200"}, cwd=workspace.parent)  # PYTHONPATH picks the code
    log.close()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if m := re.search(r"(http://\S+/)", (workspace.parent / "view.log").read_text()):
            return proc, m.group(1).rstrip("/")
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("phyagentos view did not announce its URL")


def browser(*extra_flags: str):
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    options = Options()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for flag in (*CHROMIUM_FLAGS, *extra_flags):
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tempfile.mkdtemp(prefix='phyagentos-bench-chromium-')}")
    return webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"), options=options)


class Churn:
    """Writes what a live run writes to the watched directories (see the module docstring)."""

    def __init__(self, ws: Workspace, first_run: int, *, run_every_steps: int = 20) -> None:
        self.ws = ws
        self.run_every_steps = run_every_steps
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
        if self.i % self.run_every_steps == 0:
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


def make_real_run(root: Path) -> Path:
    """A workspace under ``root`` holding one real recorded run of the shipped example
    ``replan_demo`` (a heavy cube that slips, then a firmer grip: the one the view's tests
    use); returns it."""
    ws_dir = root / "ws"
    proc = subprocess.run([sys.executable, "-m", "phyagentos.cli", "run", "replan_demo", "--workspace", str(ws_dir),
                           "--record", "all"], capture_output=True, text=True, timeout=900, cwd=root)
    if proc.returncode != 0:
        raise RuntimeError(f"the real run failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    return ws_dir


def real_pages(ws: Workspace) -> dict[str, str]:
    """Paths of each page kind in a workspace made by :func:`make_real_run`."""
    sessions = {s.state: s for s in ws.list_sessions()}
    failed, child = sessions["replanned"], sessions["succeeded"]
    return {"index": "/", "run": f"/run/{failed.run_id}", "session": f"/session/{failed.session_id}",
            "compare": f"/compare?a={failed.session_id}&b={child.session_id}", "memory": "/memory",
            "session_child": f"/session/{child.session_id}"}


def timed_load(driver, url: str, timeout: float = 60.0) -> dict:
    """Load ``url``; seconds from ``driver.get`` until the panels are filled and until complete."""
    t0 = time.monotonic()
    driver.get(url)
    out: dict = {}
    deadline = t0 + timeout
    while time.monotonic() < deadline:
        if "panels_s" not in out and driver.execute_script(PANELS_JS):
            out["panels_s"] = round(time.monotonic() - t0, 3)
        if "panels_s" in out and driver.execute_script(COMPLETE_JS):
            out["complete_s"] = round(time.monotonic() - t0, 3)
            return out
        time.sleep(0.02)
    state = driver.execute_script(
        "const live = document.getElementById('live');"
        "return {readyState: document.readyState, live: live ? live.className : null,"
        " stream: window.phyagentosStream ? window.phyagentosStream() : null,"
        " unfilled: [...document.querySelectorAll('[data-fragment]')].filter(e => e.dataset.html === undefined)"
        "   .map(e => e.dataset.fragment)}")
    raise TimeoutError(f"{url} not complete after {timeout} s ({out}; page: {json.dumps(state)})")


def page_loads(driver, url: str, pages: dict[str, str], repeats: int) -> dict:
    """Per page kind: the first (cold) load and the median of ``repeats`` more (see the module docstring)."""
    out = {}
    for kind in ("index", "run", "session", "compare"):
        first = timed_load(driver, url + pages[kind])
        again = [timed_load(driver, url + pages[kind]) for _ in range(repeats)]
        out[kind] = {"first_panels_s": first["panels_s"], "first_complete_s": first["complete_s"],
                     "panels_s": float(np.median([a["panels_s"] for a in again])) if again else None,
                     "complete_s": float(np.median([a["complete_s"] for a in again])) if again else None}
    return out


def measure(n_runs: int, seconds: float, *, template: Path | None = None, repeats: int = 3) -> dict:
    root = Path(tempfile.mkdtemp(prefix="phyagentos-view-load-"))
    if template is not None:  # a copy of the real run, plus n_runs - 1 registered runs
        shutil.copytree(template, root / "ws", symlinks=True)
        ws = Workspace.open(root / "ws")
        register_runs(ws, n_runs - 1)
    else:
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
        if template is not None:
            out["pages"] = page_loads(driver, url, real_pages(ws), repeats)
            driver.get(url + "/")
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


def rss_mib(pid: int) -> float:
    """Resident set size of process ``pid`` (MiB), ``VmRSS`` from /proc."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def tree_pss_mib(pid: int) -> float:
    """Proportional set size (MiB) of ``pid`` and all its descendants (``Pss`` of smaps_rollup)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(d.name))
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        todo += children.get(p, [])
        try:
            for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    total += int(line.split()[1])
                    break
        except OSError:
            continue
    return total / 1024


def js_heap_mib(driver) -> float:
    """The current page's used JS heap (MiB) after a forced garbage collection."""
    driver.execute_cdp_cmd("HeapProfiler.collectGarbage", {})
    return driver.execute_cdp_cmd("Runtime.getHeapUsage", {})["usedSize"] / (1024 * 1024)


def _summary(t_min: list[float], y: list[float]) -> dict:
    t, v = np.asarray(t_min, float), np.asarray(y, float)
    out = {"start": round(float(v[0]), 1), "end": round(float(v[-1]), 1), "max": round(float(v.max()), 1)}
    if len(t) >= 3:
        out["slope_mib_per_h"] = round(float(np.polyfit(t / 60, v, 1)[0]), 2)
    late = t >= 10
    if late.sum() >= 3:
        out["slope_from_10_min_mib_per_h"] = round(float(np.polyfit(t[late] / 60, v[late], 1)[0]), 2)
    return out


class Browsing:
    """One navigation per :meth:`step` through the pages of the real run (see the module docstring)."""

    def __init__(self, driver, url: str, pages: dict[str, str]) -> None:
        self.driver, self.url, self.pages = driver, url, pages
        self.plan = ["index", "run", "session", "session_child", "compare", "memory"]
        self.i = 0
        self.visits: dict[str, int] = {}
        self.loads: list[float] = []
        self.errors: list[str] = []

    def step(self) -> None:
        from selenium.common.exceptions import StaleElementReferenceException
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.by import By

        kind = self.plan[self.i % len(self.plan)]
        self.i += 1
        self.visits[kind] = self.visits.get(kind, 0) + 1
        d = self.driver
        try:
            if kind == "memory":
                t0 = time.monotonic()
                d.get(self.url + self.pages[kind])
                while not d.execute_script(PANELS_JS) and time.monotonic() - t0 < 60:
                    time.sleep(0.05)
                return
            self.loads.append(timed_load(d, self.url + self.pages[kind])["complete_s"])
            if kind in ("session", "session_child") and self.visits[kind] % 2 == 0:
                d.find_element(By.CSS_SELECTOR, "input.overlays").click()
            if kind in ("session", "session_child", "compare"):
                fraction = random.random()
                for attempt in range(3):  # a live refresh may redraw the timeline under the click
                    try:
                        canvas = d.find_elements(By.CSS_SELECTOR, "canvas.tl-canvas")[0]
                        w = canvas.size["width"]
                        x = 52 + (w - 60) * fraction
                        ActionChains(d).move_to_element_with_offset(canvas, int(x - w / 2), 0).click().perform()
                        break
                    except StaleElementReferenceException:
                        if attempt == 2:
                            raise
        except Exception as exc:  # noqa: BLE001 - counted and reported; the soak goes on
            msg = str(exc).splitlines()[0][:600] if str(exc) else ""
            self.errors.append(f"{kind}: {type(exc).__name__}: {msg}")
            print(f"navigation {self.i} ({kind}) failed: {type(exc).__name__}: {msg}", file=sys.stderr, flush=True)


def soak(template: Path, minutes: float, *, interval: float, sample_every: float, run_every: float,
         out_path: Path | None) -> dict:
    """Memory after ``minutes`` of browsing (see the module docstring)."""
    root = Path(tempfile.mkdtemp(prefix="phyagentos-view-soak-"))
    shutil.copytree(template, root / "ws", symlinks=True)
    ws = Workspace.open(root / "ws")
    pages = real_pages(ws)
    view, url = start_view(root / "ws")
    flags = ("--enable-precise-memory-info",)
    resident, browsing = browser(*flags), browser(*flags)
    stop = threading.Event()
    churn = Churn(ws, 0, run_every_steps=max(1, round(run_every / 0.05)))

    def churn_loop() -> None:
        while not stop.is_set():
            churn.step()
            time.sleep(0.05)

    samples: list[dict] = []
    result: dict = {"minutes": minutes, "interval_s": interval, "run_every_s": run_every, "samples": samples}
    thread = threading.Thread(target=churn_loop, name="churn", daemon=True)
    try:
        for d in (resident, browsing):
            d.set_page_load_timeout(60)
        resident.get(url + "/")
        walker = Browsing(browsing, url, pages)
        walker.step()
        thread.start()
        t0 = time.monotonic()
        next_sample = t0
        cpu0 = cpu_seconds(view.pid)
        while True:
            now = time.monotonic()
            if now >= next_sample:
                samples.append({
                    "t_min": round((now - t0) / 60, 2), "server_rss_mib": round(rss_mib(view.pid), 1),
                    "server_cpu_pct": round(100 * (cpu_seconds(view.pid) - cpu0) / max(now - t0, 1e-9), 1),
                    "resident_heap_mib": round(js_heap_mib(resident), 2),
                    "browsing_heap_mib": round(js_heap_mib(browsing), 2),
                    "resident_browser_pss_mib": round(tree_pss_mib(resident.service.process.pid), 1),
                    "browsing_browser_pss_mib": round(tree_pss_mib(browsing.service.process.pid), 1),
                    "navigations": walker.i, "errors": len(walker.errors), "runs": churn.next_run,
                    "resident_visible": resident.execute_script("return document.visibilityState")})
                print(json.dumps(samples[-1]), file=sys.stderr, flush=True)
                if out_path is not None:
                    write_json(out_path, result, indent=1, say=False)
                next_sample += sample_every
                if now - t0 >= minutes * 60:
                    break
            step_start = time.monotonic()
            walker.step()
            time.sleep(max(0.0, interval - (time.monotonic() - step_start)))
        loads = sorted(walker.loads)
        result.update({
            "navigations": walker.i, "visits": walker.visits, "errors": walker.errors[-20:],
            "error_count": len(walker.errors), "runs_registered": churn.next_run,
            "load_complete_s_median": loads[len(loads) // 2] if loads else None,
            "load_complete_s_p95": loads[int(len(loads) * 0.95)] if loads else None,
            **{key: _summary([x["t_min"] for x in samples], [x[key] for x in samples])
               for key in ("server_rss_mib", "resident_heap_mib", "browsing_heap_mib", "resident_browser_pss_mib",
                           "browsing_browser_pss_mib")}})
        if out_path is not None:
            write_json(out_path, result, indent=1, say=False)
    finally:
        stop.set()
        for d in (resident, browsing):
            d.quit()
        view.terminate()
        try:
            view.wait(timeout=10)
        except subprocess.TimeoutExpired:
            view.kill()
        shutil.rmtree(root, ignore_errors=True)
    return result


def main() -> int:
    ap = parser(__doc__, "view_load", out=False)
    ap.add_argument("--runs", type=int, nargs="+", default=[1, 1000])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--pages", action="store_true", help="also time the run, session and compare pages of a real run")
    ap.add_argument("--page-repeats", type=int, default=3, help="loads of each page after the first (median)")
    ap.add_argument("--soak-minutes", type=float, help="only the memory soak: browse for this many minutes")
    ap.add_argument("--soak-interval", type=float, default=3.0, help="seconds per navigation in the soak")
    ap.add_argument("--soak-sample", type=float, default=60.0, help="seconds between memory samples")
    ap.add_argument("--soak-run-every", type=float, default=30.0, help="seconds between new runs in the soak's churn")
    ap.add_argument("--soak-out", type=Path, help="write the soak's samples here as they come (JSON)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = ap.parse_args()
    template = None
    if args.pages or args.soak_minutes:
        made = Path(tempfile.mkdtemp(prefix="phyagentos-view-run-"))
        print("making the real run ...", file=sys.stderr, flush=True)
        template = make_real_run(made)
    if args.soak_minutes:
        result = soak(template, args.soak_minutes, interval=args.soak_interval, sample_every=args.soak_sample,
                      run_every=args.soak_run_every, out_path=args.soak_out)
        shutil.rmtree(template.parent, ignore_errors=True)
        print(json.dumps({k: v for k, v in result.items() if k != "samples"}, indent=2))
        return 0
    rows = [measure(n, args.seconds, template=template, repeats=args.page_repeats) for n in args.runs]
    if template is not None:
        shutil.rmtree(template.parent, ignore_errors=True)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    cols = ("runs", "index_load_s", "rows_shown", "idle_cpu_pct", "churn_cpu_pct", "idle_fragment_requests",
            "churn_fragment_requests", "update_latency_ms")
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(str(r.get(c, "")) for c in cols))
    for r in rows:
        for kind, p in r.get("pages", {}).items():
            print(f"{r['runs']} runs, {kind} page: first load {p['first_panels_s']} s panels / "
                  f"{p['first_complete_s']} s "
                  f"complete; again (median) {p['panels_s']} s / {p['complete_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
