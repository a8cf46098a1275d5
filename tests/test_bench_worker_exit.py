"""A bench killed from outside leaves no worker running (found when a SIGTERM'd LIBERO bench
left its two pool workers, their forkservers and runners, 3 GB, and a test suite beside them
ran the machine out of memory).

A real process tree: a "bench" process starts the local executor's pool (spawn, the bench's own
``_worker_init``) and hands it a task that runs for a minute; the bench is then killed with
SIGKILL, which no handler sees. The worker must end within seconds, and the process it started
with it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

BENCH = textwrap.dedent('''
    import logging, multiprocessing, sys, time
    from concurrent.futures import ProcessPoolExecutor
    from phyagentos.bench.executor import _worker_init

    def child(path):
        open(path, "w").write(str(multiprocessing.current_process().pid))
        time.sleep(60)

    def task(out):
        ctx = multiprocessing.get_context("spawn")
        p = ctx.Process(target=child, args=(out + ".child",), daemon=True)
        p.start()
        open(out, "w").write(str(multiprocessing.current_process().pid))
        time.sleep(60)

    if __name__ == "__main__":
        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(1, mp_context=ctx, initializer=_worker_init, initargs=(logging.WARNING,)) as pool:
            pool.submit(task, sys.argv[1])
            time.sleep(120)
''')


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (exited, not yet reaped by init) is gone too
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def _wait_for(path: Path, timeout_s: float) -> int:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        if path.exists() and path.read_text().strip():
            return int(path.read_text())
        time.sleep(0.1)
    raise AssertionError(f"{path} was never written")


def test_a_bench_killed_with_sigkill_leaves_no_worker_or_runner_running(tmp_path):
    script = tmp_path / "bench.py"
    script.write_text(BENCH)
    out = tmp_path / "worker.pid"
    bench = subprocess.Popen([sys.executable, str(script), str(out)], cwd=tmp_path,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = child = None
    try:
        worker = _wait_for(out, 120.0)
        child = _wait_for(Path(str(out) + ".child"), 60.0)
        assert _alive(worker) and _alive(child)
        bench.send_signal(signal.SIGKILL)
        bench.wait(10)
        t0 = time.monotonic()
        while (_alive(worker) or _alive(child)) and time.monotonic() - t0 < 20.0:
            time.sleep(0.1)
        assert not _alive(worker), "the pool worker outlived the bench"
        assert not _alive(child), "the worker's own process outlived the bench"
    finally:
        for pid in (p for p in (worker, child) if p):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        bench.kill()
