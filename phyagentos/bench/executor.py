"""Executors: run compiled episodes in worker processes.

``local`` (default): a :class:`concurrent.futures.ProcessPoolExecutor` with ``workers``
processes started with ``spawn`` (a clean interpreter: no MuJoCo or OpenGL state
inherited from the parent); a worker ends itself and its children when the bench process
goes away, however it ended. Each worker runs whole episodes, one at a time; for each it
builds its own WatchdogSupervisor and AgentCoordinator on the episode's workspace, so
an episode's sessions (including verifier-triggered child sessions) stay on one worker
and its world state never crosses processes.

``ray``: the same episode function as Ray tasks (``ray.init()`` starts a local instance
when no cluster address is configured). Optional: needs the ``ray`` package.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path
from typing import Callable, Sequence

from phyagentos.errors import BenchError

from .episode import EpisodeOutcome, run_episode
from .memory import MemoryPolicy

__all__ = ["EXECUTORS", "execute_episodes"]

logger = logging.getLogger(__name__)

EXECUTORS: tuple[str, ...] = ("local", "ray")


def _exit_with_parent(parent: multiprocessing.process.BaseProcess) -> None:
    """Wait for the bench process ``parent`` to go away, then end this worker and the
    processes it started (an episode's session runners): a bench killed with SIGTERM or
    SIGKILL (a CI timeout, ``timeout``, a supervisor) otherwise left its pool's workers running
    the episodes they held, and their runners, 1.5-3 GB each on LIBERO."""
    parent.join()
    logger.warning("bench worker %d: the bench process is gone; stopping", os.getpid())
    for child in multiprocessing.active_children():
        child.terminate()
    os._exit(1)


def _worker_init(log_level: int) -> None:
    import phyagentos  # noqa: F401,PLC0415 - selects the headless GL backend before mujoco loads

    parent = multiprocessing.parent_process()
    if parent is not None:
        threading.Thread(target=_exit_with_parent, args=(parent,), name="bench-parent-watch", daemon=True).start()

    logging.basicConfig(level=log_level, format="%(processName)s %(name)s: %(message)s")
    logging.getLogger("transitions").setLevel(max(log_level, logging.WARNING))
    logging.getLogger("toppra").setLevel(max(log_level, logging.WARNING))
    # watchdog's inotify thread logs an ERROR when an episode's workspace watcher is
    # stopped between two events; that is the normal end of an episode here.
    logging.getLogger("watchdog").setLevel(logging.CRITICAL)


def _local(directories: Sequence[Path], workers: int, memory: MemoryPolicy,
           on_done: Callable[[EpisodeOutcome], None]) -> list[EpisodeOutcome]:
    ctx = multiprocessing.get_context("spawn")
    level = logging.getLogger().getEffectiveLevel()
    outcomes: list[EpisodeOutcome] = []
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(max(level, logging.WARNING),)) as pool:
        pending = {pool.submit(run_episode, str(d), memory=memory): d for d in directories}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                directory = pending.pop(fut)
                try:
                    outcome = fut.result()
                except Exception as exc:  # noqa: BLE001 - a crashed worker process is recorded, not lost
                    outcome = EpisodeOutcome(episode_id=Path(directory).name, status="error", wall_time_s=0.0,
                                             worker="?", error=f"worker process failed: {type(exc).__name__}: {exc}")
                outcomes.append(outcome)
                on_done(outcome)
    return outcomes


def _ray_env() -> dict[str, str]:
    """Environment of the Ray workers: the GL backend's variables, and Ray's worker niceness
    set to 0. Ray starts its task workers at nice 15 (``core_worker.cc``: "Adjusted worker
    niceness to 15"), which suits short tasks beside a busy driver, not an episode whose
    runner must keep its heartbeat: beside two nice-0 busy loops on this 2-core machine, the
    two nice-15 workers of ``tests/test_bench_ray.py`` were starved for 4.5 minutes after
    their episodes' work (308 s against 59 s beside one loop). Ray's own job manager sets
    the same variable to 0 for its job drivers (``ray.dashboard.modules.job.job_manager``)."""
    env = {k: v for k, v in os.environ.items() if k.startswith(("MUJOCO_", "PYOPENGL_"))}
    env["RAY_worker_niceness"] = "0"
    return env


def _ray(directories: Sequence[Path], workers: int, memory: MemoryPolicy,
         on_done: Callable[[EpisodeOutcome], None]) -> list[EpisodeOutcome]:
    try:
        import ray  # noqa: PLC0415
    except ImportError:
        raise BenchError("--executor ray needs the 'ray' package (pip install 'ray>=2.9'); "
                         "or use the default --executor local") from None
    started_here = not ray.is_initialized()
    if started_here:
        # A local instance unless RAY_ADDRESS names a cluster; workers share this file system.
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, runtime_env={"env_vars": _ray_env()})
    try:
        remote = ray.remote(num_cpus=1)(run_episode)
        refs = {remote.remote(str(d), memory=memory): d for d in directories}
        outcomes: list[EpisodeOutcome] = []
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            for ref in ready:
                directory = refs.pop(ref)
                try:
                    outcome = ray.get(ref)
                except Exception as exc:  # noqa: BLE001
                    outcome = EpisodeOutcome(episode_id=Path(directory).name, status="error", wall_time_s=0.0,
                                             worker="ray", error=f"ray task failed: {type(exc).__name__}: {exc}")
                outcomes.append(outcome)
                on_done(outcome)
        return outcomes
    finally:
        if started_here:
            ray.shutdown()


def execute_episodes(directories: Sequence[Path], *, workers: int, memory: MemoryPolicy, executor: str = "local",
                     on_done: Callable[[EpisodeOutcome], None] | None = None) -> list[EpisodeOutcome]:
    """Run every episode directory; returns one outcome per episode (completion order).

    Raises:
        BenchError: unknown executor (valid ones listed), ``workers < 1``, or the
            executor's package is missing.
    """
    if workers < 1:
        raise BenchError(f"workers must be >= 1, got {workers}")
    if executor not in EXECUTORS:
        raise BenchError(f"unknown executor {executor!r}; valid executors: {', '.join(EXECUTORS)}")
    callback = on_done or (lambda outcome: None)
    run = _local if executor == "local" else _ray
    return run(list(directories), workers, memory, callback)
