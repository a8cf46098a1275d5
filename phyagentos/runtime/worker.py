"""The runner process: the only place where sessions touch targets.

The WatchdogSupervisor supervises; it never runs a skill itself. Each supervisor
owns one runner process and talks to it over a duplex pipe with small
``(kind, payload)`` messages. Keeping the runner in its own process is what makes
cancellation enforceable: a runner that does not stop in time is killed with
SIGKILL, and a fresh runner puts the target in a safe state.

Runners are forked from a ``multiprocessing`` *forkserver* that has imported the
runtime (MuJoCo, the primitives, the motion stack) once: the server is a clean,
single-threaded process that never created a GL context or a target, and a
replacement runner is ready in tens of milliseconds instead of the second a fresh
interpreter needs.

Jobs (supervisor -> runner; each gets exactly one reply, except ``go``):

==============  ====================================================  ==================================
job             does                                                  reply
==============  ====================================================  ==================================
``reserve``     take the target's actuation lock (non-blocking)       ``reserved`` {marker} | ``busy``
``unreserve``   drop it                                               ``unreserved``
``preflight``   compatibility preflight; if it passes, write the      ``preflight`` {ok, plan, ...}
                in-flight marker (target_lock.py), reply, then
                prepare the session (below)
``go``          run the session (SessionRunner.run)                   ``finished`` {outcome}, then
                                                                      ``done`` {AttemptReport}
``recover``     restore the checkpoint, halt, persist, snapshot       ``recovered`` {AttemptReport}
``release``     clear the marker and the actuation lock               ``released``
``warm``        build targets and open their cameras ahead of the     ``warmed`` {built, errors}
                first session (best effort; moves nothing)
``exit``        release everything and exit                           (none)
==============  ====================================================  ==================================

Control messages are handled at once by a reader thread, even while a job runs:
``cancel`` {reason, code} sets the session's cancel token (checked between ticks);
``estop`` also engages the process-wide e-stop latch (the SafetyGuard and the
target's own hook halt the arm at the next command or physics step); ``clear_estop``
releases it. If the supervisor dies, the pipe reaches EOF: the runner cancels its
session (halting the target at the next tick), writes its evidence and exits,
and only then does the kernel release the actuation lock.

After replying to a passed preflight the runner prepares the session
(:meth:`SessionRunner.prepare`: target acquired, initial snapshot, skill context and
safety guard; nothing moves) while the supervisor makes ``start`` durable, so ``go``
writes the checkpoint and the initial evidence and ticks. ``go`` carries the digest of the started session's runtime fields
(:func:`~phyagentos.runtime.session_basis.runtime_basis`); the preparation is used only
if it was made from the same fields, and any other job first discards it
(:meth:`SessionRunner.discard`).

Heartbeats travel through shared memory (:mod:`phyagentos.runtime.heartbeat`), not
the pipe, so a runner stuck inside a tick goes silent even though its reader thread
still answers.
"""

from __future__ import annotations

import atexit
import logging
import multiprocessing
import os
import queue
import signal
import threading
import time
import traceback
from pathlib import Path
from typing import Any

from phyagentos.errors import SupervisorError

from .heartbeat import ARRAY_LENGTH, Heartbeats

__all__ = ["RunnerProcess", "RunnerDied", "runner_main", "take_runner", "park_runner", "prestart_runner",
           "forkserver_context", "warm_runner", "borrow_runner"]

logger = logging.getLogger(__name__)

_CONTROL = frozenset({"cancel", "estop", "clear_estop"})
#: An orphaned runner (its supervisor died) exits at the latest this long after noticing (s).
_ORPHAN_EXIT_S = 10.0


#: Imported once by the forkserver, so forked runners start with them loaded. The last,
#: ``forkserver_freeze``, moves all of it into the collector's permanent generation.
_PRELOAD = ["phyagentos.runtime.forkserver_exit", "phyagentos.runtime.worker", "phyagentos.runtime.runner", "phyagentos.runtime.preflight",
            "phyagentos.runtime.target_pool", "phyagentos.runtime.target_lock", "phyagentos.runtime.forkserver_freeze"]


def _context():
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(_PRELOAD)
    return ctx


def forkserver_context():
    """The ``multiprocessing`` context whose forkserver runners are forked from (the
    runtime preloaded): other short-lived runtime-side children (e.g. the whole-graph
    check of ``phyagentos run``) are forked from it too, without importing the runtime
    again."""
    return _context()


class RunnerDied(SupervisorError):
    """The runner process exited or closed its pipe."""


class RunnerProcess:
    """Supervisor-side handle of one runner process.

    Args:
        skills_dir, trees_dir: where the runner loads skill manifests and trees.
        log_level: logging level inside the runner (default: the caller's root level).

    The process starts at construction and imports its runtime in the background;
    the first reply arrives once that is done (about a second).
    """

    def __init__(self, *, skills_dir: str | os.PathLike[str], trees_dir: str | os.PathLike[str],
                 log_level: int | None = None) -> None:
        ctx = _context()
        self._hb_array = ctx.RawArray("d", ARRAY_LENGTH)
        self.heartbeats = Heartbeats(self._hb_array)
        self.conn, self._child = ctx.Pipe(duplex=True)
        level = logging.getLogger().getEffectiveLevel() if log_level is None else log_level
        self.process = ctx.Process(target=runner_main, name="phyagentos-runner", daemon=True,
                                   args=(self._child, self._hb_array, str(skills_dir), str(trees_dir), level))
        self.skills_dir, self.trees_dir = str(skills_dir), str(trees_dir)
        self.reserved: set[tuple[str, str]] = set()
        self._dead = False
        # ``Process.start`` blocks until the forkserver has imported the runtime (about a
        # second, more on a loaded machine): do it in the background, so the caller goes
        # on with its own work. Jobs sent meanwhile wait in the pipe.
        self._start_error: BaseException | None = None
        self._started = threading.Event()
        threading.Thread(target=self._start, name="phyagentos-runner-start", daemon=True).start()

    def _start(self) -> None:
        try:
            self.process.start()
        except BaseException as exc:  # noqa: BLE001 - reported by wait_started
            self._start_error = exc
            self._dead = True
        finally:
            self._child.close()
            self._started.set()

    def wait_started(self, timeout: float | None = None) -> bool:
        """Block until the process exists (True) or failed to start / ``timeout`` passed (False)."""
        return self._started.wait(timeout) and self._start_error is None

    @property
    def pid(self) -> int | None:
        self._started.wait()
        return self.process.pid

    def alive(self) -> bool:
        """True unless the runner exited, was killed or could not start (True while starting)."""
        if self._dead:
            return False
        if not self._started.is_set():
            return True
        return self._start_error is None and self.process.is_alive()

    def fileno(self) -> int:
        """Readable when the runner sent something (or died)."""
        return self.conn.fileno()

    def send(self, kind: str, **payload: Any) -> None:
        """Send a job or control message.

        Raises:
            RunnerDied: the pipe is closed.
        """
        try:
            self.conn.send((kind, payload))
        except (OSError, EOFError, BrokenPipeError) as exc:
            self._dead = True
            raise RunnerDied(f"runner {self.pid} is gone: {exc}") from None

    def poll(self, timeout: float = 0.0) -> tuple[str, dict] | None:
        """The next message, waiting at most ``timeout`` s; None if nothing arrived.

        Raises:
            RunnerDied: the runner exited or closed the pipe.
        """
        try:
            if not self.conn.poll(timeout):
                return None
            return self.conn.recv()
        except (OSError, EOFError) as exc:
            self._dead = True
            raise RunnerDied(f"runner {self.pid} exited (code {self.process.exitcode}): {exc!r}") from None

    def request(self, kind: str, *, timeout: float, expect: tuple[str, ...], **payload: Any) -> tuple[str, dict]:
        """Send a job and wait for its reply (one of ``expect``, or ``error`` from this
        job); replies to earlier jobs still on the pipe are skipped.

        Raises:
            RunnerDied: the runner died, or did not answer within ``timeout`` s
                (it is then killed: a runner that cannot answer cannot be trusted).
        """
        self.send(kind, **payload)
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self.kill()
                raise RunnerDied(f"runner {self.pid} did not answer {kind!r} within {timeout:.1f} s; killed")
            msg = self.poll(left)
            if msg is None:
                continue
            if msg[0] in expect or (msg[0] == "error" and msg[1].get("job") in (None, kind)):
                return msg
            logger.debug("runner %s: ignoring stale %s while waiting for %s", self.pid, msg[0], expect)

    def kill(self) -> None:
        """SIGKILL the runner (it may be stuck anywhere) and reap it."""
        self._dead = True
        self.reserved.clear()
        self._started.wait()
        if self._start_error is None and self.process.is_alive():
            try:
                os.kill(self.process.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if self._start_error is None:
            self.process.join(timeout=5)
        self.conn.close()

    def close(self, timeout: float = 5.0) -> None:
        """Ask the runner to exit (releasing its locks); kill it if it does not."""
        self._started.wait()
        if self.alive():
            try:
                self.send("exit")
            except RunnerDied:
                pass
            self.process.join(timeout=timeout)
        if self._start_error is None and self.process.is_alive():
            self.kill()
        else:
            self._dead = True
            self.conn.close()
        self.reserved.clear()


# -- a process-wide pool of idle runner processes ------------------------------------
# A runner takes about a second to start (the forkserver imports MuJoCo and the
# primitives), so successive supervisors in one process (``phyagentos run``, benchmark
# episodes) reuse idle ones, and ``phyagentos run`` starts one before it has even
# imported the Agent plane (:func:`prestart_runner`).

_IDLE_RUNNERS: list[RunnerProcess] = []
_POOL_LOCK = threading.Lock()


def take_runner(skills_dir: str | os.PathLike[str], trees_dir: str | os.PathLike[str]) -> RunnerProcess:
    """An idle (or starting) runner for these skill and tree directories, else a new one."""
    key = (str(skills_dir), str(trees_dir))
    while True:
        with _POOL_LOCK:
            runner = _IDLE_RUNNERS.pop() if _IDLE_RUNNERS else None
        if runner is None:
            return RunnerProcess(skills_dir=skills_dir, trees_dir=trees_dir)
        if runner.alive() and (runner.skills_dir, runner.trees_dir) == key:
            return runner
        runner.close()


def park_runner(runner: RunnerProcess) -> None:
    """Keep ``runner`` for the next supervisor of this process (at most two), else close it."""
    with _POOL_LOCK:
        if runner.alive() and not runner.reserved and len(_IDLE_RUNNERS) < 2:
            _IDLE_RUNNERS.append(runner)
            return
    runner.close()


def prestart_runner(skills_dir: str | os.PathLike[str], trees_dir: str | os.PathLike[str]) -> None:
    """Start a runner now, in the background, for the next :func:`take_runner`.

    Cold start of ``phyagentos run``: the forkserver imports the runtime while the
    caller imports and prepares the Agent plane, instead of one after the other.
    """
    with _POOL_LOCK:
        if _IDLE_RUNNERS:
            return
    park_runner(RunnerProcess(skills_dir=skills_dir, trees_dir=trees_dir))


def warm_runner(root: str | os.PathLike[str], targets: list[dict[str, Any]]) -> bool:
    """Have the idle runner that the next :func:`take_runner` returns build ``targets``
    now (``[{"name": ..., "scene": raw scene or None}]``, see :meth:`TargetPool.warm`),
    while the caller does other work (``run``: the whole-graph check). The reply
    (``warmed``) is read, and ignored, by the supervisor's next request. Returns False
    if no idle runner was there to warm.
    """
    with _POOL_LOCK:
        runner = _IDLE_RUNNERS[-1] if _IDLE_RUNNERS else None
    if runner is None or not runner.alive():
        return False
    try:
        runner.send("warm", root=str(root), targets=list(targets))
    except RunnerDied:
        return False
    return True


def borrow_runner(skills_dir: str | os.PathLike[str], trees_dir: str | os.PathLike[str]) -> RunnerProcess | None:
    """Take the idle runner the next :func:`take_runner` of these directories would
    return out of the pool, for jobs before a supervisor takes it (e.g. the runtime's
    steps of ``run``'s whole-graph check), or None if there is none. Nobody else can
    take it meanwhile; hand it back with :func:`park_runner`."""
    with _POOL_LOCK:
        runner = _IDLE_RUNNERS[-1] if _IDLE_RUNNERS else None
        if runner is None or (runner.skills_dir, runner.trees_dir) != (str(skills_dir), str(trees_dir)):
            return None
        _IDLE_RUNNERS.pop()
    if not runner.alive():
        runner.close()
        return None
    return runner


@atexit.register
def _close_idle_runners() -> None:
    while _IDLE_RUNNERS:
        _IDLE_RUNNERS.pop().close(timeout=2)


# ---------------------------------------------------------------------------
# Inside the runner process.


def _return_freed_memory() -> None:
    """Collect garbage and hand the C heap's free pages back to the system (glibc's
    ``malloc_trim``; nothing elsewhere). Models, MjData arenas and renderer buffers of
    closed targets are large, and glibc keeps freed heap memory for reuse, so without
    this a runner's resident size grows with every workspace it served."""
    import ctypes  # noqa: PLC0415
    import gc  # noqa: PLC0415

    gc.collect()
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


class _Runner:
    """The runner process's state: runtime, target pools, locks, the current session."""

    def __init__(self, conn, heartbeats: Heartbeats, skills_dir: str, trees_dir: str) -> None:
        from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: PLC0415

        self.conn = conn
        self.heartbeats = heartbeats
        self.runtime = BuiltinSkillRuntime.from_dirs(skills_dir, trees_dir)
        self.pools: dict[str, Any] = {}
        self.locks: dict[tuple[str, str], Any] = {}
        self.jobs: queue.Queue = queue.Queue()
        self.cancel = None  # CancelToken of the running session
        self.prepared = None  # (root, SessionRunner, ExitStack of its write batch) awaiting its go
        self.send_lock = threading.Lock()
        from phyagentos.runtime.evidence_writer import EvidenceImageWriter  # noqa: PLC0415

        self.images = EvidenceImageWriter()

    # -- plumbing --------------------------------------------------------

    def reply(self, kind: str, **payload: Any) -> None:
        with self.send_lock:
            try:
                self.conn.send((kind, payload))
            except (OSError, EOFError):
                pass  # the supervisor is gone; the reader thread handles it

    def read_forever(self) -> None:
        """Reader thread: control messages act at once, jobs queue up, EOF means orphaned."""
        while True:
            try:
                kind, payload = self.conn.recv()
            except (EOFError, OSError):
                # Orphaned: stop actuating (halt at the next tick), write evidence, exit.
                # A runner stuck inside a tick is not waited for forever.
                self.control("cancel", {"reason": "supervisor lost (pipe closed)", "code": "cancelled.shutdown"})
                self.jobs.put(("exit", {}))
                timer = threading.Timer(_ORPHAN_EXIT_S, os._exit, args=(3,))
                timer.daemon = True
                timer.start()
                return
            if kind in _CONTROL:
                self.control(kind, payload)
            else:
                self.jobs.put((kind, payload))

    def control(self, kind: str, payload: dict) -> None:
        if kind in ("cancel", "estop"):
            code = payload.get("code") or ("cancelled.estop" if kind == "estop" else "cancelled.operator")
            if kind == "estop":
                self._estop_latch().engage(payload.get("reason", ""), source="supervisor")
            token = self.cancel
            if token is not None and not token.is_set():
                token.cancel(payload.get("reason", ""), code)
        elif kind == "clear_estop":
            self._estop_latch().clear()

    @staticmethod
    def _estop_latch():
        from phyagentos.runtime.safety_guard import PROCESS_ESTOP  # noqa: PLC0415

        return PROCESS_ESTOP

    def workspace(self, root: str):
        from phyagentos.protocol import Workspace  # noqa: PLC0415

        return Workspace.open(root)

    def pool(self, root: str):
        from phyagentos.runtime.target_pool import TargetPool  # noqa: PLC0415

        pool = self.pools.get(root)
        if pool is None:
            self._evict_pools(keep=1)
            pool = self.pools[root] = TargetPool(Path(root) / "targets")
        return pool

    def _evict_pools(self, *, keep: int) -> None:
        """Close the oldest target pools beyond ``keep`` of workspaces where this runner
        holds no target lock, and forget those workspaces' released locks: a runner that
        serves one workspace after another (a long ``watch``, benchmark episodes, an
        idle runner reused by the next ``run``) keeps the targets, models and renderers
        of at most two. An idle pool holding a target too big to keep twice
        (``KEEP_WHEN_IDLE`` false: a LIBERO world, 1.5-2 GB) is closed whatever ``keep``
        says, so the next workspace's world is not built beside it."""
        held = {r for (r, _), lock in self.locks.items() if lock.held}
        idle = [r for r in self.pools if r not in held]
        oldest = idle[: max(0, len(self.pools) - keep)]
        evicted = [r for r in idle if r in oldest or not self.pools[r].keep_when_idle]
        for old_root in evicted:
            self.pools.pop(old_root).close()
            for key in [k for k in self.locks if k[0] == old_root]:
                del self.locks[key]
        if evicted:
            _return_freed_memory()

    def lock(self, root: str, target: str):
        from phyagentos.runtime.target_lock import TargetLock  # noqa: PLC0415

        key = (root, target)
        if key not in self.locks:
            self.locks[key] = TargetLock(Path(root) / ".locks", target)
        return self.locks[key]

    def release_all(self) -> None:
        for lock in self.locks.values():
            lock.release()

    # -- jobs ------------------------------------------------------------

    def job_reserve(self, root: str, target: str) -> None:
        from phyagentos.runtime.target_lock import read_marker  # noqa: PLC0415

        lock = self.lock(root, target)
        if not lock.try_acquire():
            self.reply("busy", target=target)
            return
        self.reply("reserved", target=target, marker=read_marker(Path(root) / "targets", target))

    def job_unreserve(self, root: str, target: str) -> None:
        self.lock(root, target).release()
        self.reply("unreserved", target=target)

    def job_preflight(self, root: str, session_id: str, token: str, owner: str, record: Any = None) -> None:
        """Preflight ``session_id`` (``record``: its record as the supervisor's claim
        writes it, or None to read the session file); reply, and prepare it if it passed."""
        from phyagentos.runtime.preflight import run_preflight  # noqa: PLC0415
        from phyagentos.runtime.target_lock import write_marker  # noqa: PLC0415
        from phyagentos.targets.registry import DRIVERS  # noqa: PLC0415

        started = time.perf_counter()
        ws = self.workspace(root)
        rec = record if record is not None and record.session_id == session_id else ws.load_session(session_id)
        result = run_preflight(rec, targets=ws.read("TARGETS").data, runtimes=ws.read("SKILLRUNTIME").data,
                               skills=self.runtime.skills, trees=self.runtime.trees, drivers=DRIVERS,
                               safety=ws.read_safety(), root=ws.root)
        if result.ok:
            if not self.lock(root, rec.target).held:
                raise SupervisorError(f"preflight of {session_id}: target {rec.target!r} is not reserved")
            write_marker(Path(root) / "targets", rec.target, session_id=session_id, token=token, owner=owner)
        plan = result.plan.to_dict() if result.plan else None
        manifest = result.manifest.to_dict() if result.manifest else None
        self.reply("preflight", ok=result.ok, session_id=session_id, plan=plan, manifest=manifest,
                   rejections=[r.model_dump(mode="json") for r in result.rejections],
                   duration_s=time.perf_counter() - started)
        if result.ok:
            # What ``start`` will record (the supervisor copies plan and manifest from this reply).
            self._prepare(root, rec.model_copy(update={"adapter_plan": plan, "tool_manifest": manifest}))

    def _session_runner(self, root: str, ws, rec):
        from phyagentos.primitives.context import CancelToken  # noqa: PLC0415
        from phyagentos.runtime.runner import SessionRunner  # noqa: PLC0415

        hb = self.heartbeats

        def beat() -> None:
            now = time.monotonic()
            hb.beat("runner", now)
            hb.beat("target", now)  # the in-process simulated target answered this tick

        return SessionRunner(ws, rec, self.runtime, self.pool(root), cancel=CancelToken(), heartbeat=beat,
                             on_execution_clock=hb.start_execution, images=self.images)

    def _prepare(self, root: str, rec) -> None:
        """Set up ``rec``'s session for its first tick while the supervisor persists
        ``start`` (:meth:`SessionRunner.prepare`; moves nothing). The session's batch of
        durable writes (fsynced when it ends, as in ``go``) begins here."""
        from contextlib import ExitStack  # noqa: PLC0415

        from phyagentos.protocol.atomic import batched_durability  # noqa: PLC0415

        stack = ExitStack()
        stack.enter_context(batched_durability())
        runner = self._session_runner(root, self.workspace(root), rec)
        try:
            runner.prepare()
        except BaseException:
            stack.close()
            raise
        self.prepared = (root, runner, stack)

    def discard_prepared(self) -> None:
        """Undo the preparation of a session that was not started (any job but its ``go``)."""
        prepared, self.prepared = self.prepared, None
        if prepared is not None:
            self._discard(prepared)

    @staticmethod
    def _discard(prepared: tuple) -> None:
        _, runner, stack = prepared
        try:
            runner.discard()
        finally:
            stack.close()
        logger.debug("runner: preparation of %s discarded", runner.record.session_id)

    def job_go(self, root: str, session_id: str, checkpoint_interval_s: float, basis: str | None = None) -> None:
        from phyagentos.protocol.atomic import batched_durability  # noqa: PLC0415
        from phyagentos.runtime.session_basis import runtime_basis  # noqa: PLC0415

        prepared, self.prepared = self.prepared, None
        runner = stack = None
        if prepared is not None:
            p_root, p_runner, _ = prepared
            if (p_root, p_runner.record.session_id) == (root, session_id) and basis is not None \
                    and runtime_basis(p_runner.record) == basis and self.lock(root, p_runner.record.target).held:
                _, runner, stack = prepared
            else:
                # Started from other fields than were prepared (e.g. the file was edited
                # in between): set up afresh from the session file.
                logger.info("runner: preparation of %s not used for go of %s", p_runner.record.session_id, session_id)
                self._discard(prepared)
        if runner is None:
            ws = self.workspace(root)
            rec = ws.load_session(session_id)
            if not self.lock(root, rec.target).held:
                raise SupervisorError(f"go {session_id}: target {rec.target!r} is not reserved")
            runner = self._session_runner(root, ws, rec)
        self.cancel = runner.cancel
        if self._estop_latch().is_set():
            self.cancel.cancel("e-stop engaged", "cancelled.estop")

        def finished(outcome) -> None:
            self.reply("finished", session_id=session_id, status=outcome.status, error_code=outcome.error_code,
                       message=outcome.message, ticks=outcome.ticks)

        runner.on_finished = finished
        runner.checkpoint_interval_s = checkpoint_interval_s
        # The bundle's files, the checkpoints and ENVIRONMENT.md are fsynced together
        # when the session ends, before ``done`` (after which the supervisor records
        # ``awaiting_verification``): a verifier never sees a bundle that is not durable.
        # A killed runner loses nothing by this (the page cache survives it); the
        # recovering runner writes its own durable snapshot. A prepared session's batch
        # began with its preparation.
        try:
            with stack if stack is not None else batched_durability():
                report = runner.run()
        finally:
            self.cancel = None
            self.images.release(runner.workspace.evidence_dir(session_id))  # rendered in the background from here
        self.reply("done", session_id=session_id, **report.to_dict())

    def job_recover(self, root: str, session_id: str, status: str, error_code: str, message: str) -> None:
        from phyagentos.runtime.runner import SessionRunner  # noqa: PLC0415

        ws = self.workspace(root)
        rec = ws.load_session(session_id)
        if not self.lock(root, rec.target).held:
            raise SupervisorError(f"recover {session_id}: target {rec.target!r} is not reserved")
        from phyagentos.primitives.context import CancelToken  # noqa: PLC0415

        runner = SessionRunner(ws, rec, self.runtime, self.pool(root), cancel=CancelToken())
        report = runner.recover(status=status, error_code=error_code, message=message)
        self.reply("recovered", session_id=session_id, **report.to_dict())

    def job_warm(self, root: str, targets: list[dict[str, Any]]) -> None:
        """Build targets ahead of their first session (:meth:`TargetPool.warm`). Best effort:
        a target that does not build is left to the session, whose preflight and runner
        report it properly; this job never replies ``error`` (a supervisor waiting for
        another reply would take that for its own job's failure)."""
        built, errors = [], []
        try:
            ws = self.workspace(root)
            specs = {t.name: t for t in ws.read("TARGETS").data.targets}
            pool = self.pool(root)
            for item in targets:
                spec = specs.get(item.get("name"))
                if spec is None:
                    continue
                try:
                    if pool.warm(spec, item.get("scene")):
                        built.append(spec.name)
                except Exception as exc:  # noqa: BLE001 - left to the session to report
                    errors.append(f"{spec.name}: {type(exc).__name__}: {exc}")
        except Exception as exc:  # noqa: BLE001 - e.g. a malformed TARGETS.md: the run reports it
            errors.append(f"{type(exc).__name__}: {exc}")
        if errors:
            logger.info("runner: warming skipped for %s", "; ".join(errors))
        self.reply("warmed", built=built, errors=errors)

    def job_graph_checks(self, root: str, stage: str, items: list) -> None:
        """The runtime's steps of a whole-graph check (:mod:`phyagentos.app.graph_check`), in
        batches (:func:`~phyagentos.runtime.graph_preflight.build_trees`, ``check_scenes``,
        ``check_reach``), with this runner's tree library. Scenes travel as pickles the
        caller hands back unopened, so it never imports the scene code. Reachability
        builds its own model of the scene: nothing of a warmed or running target is used."""
        import pickle  # noqa: PLC0415

        from phyagentos.runtime import graph_preflight as gp  # noqa: PLC0415

        if stage == "trees":
            results: list = gp.build_trees(self.runtime.trees, items)
        elif stage == "scenes":
            results = [(pickle.dumps(scene), problems, names)
                       for scene, problems, names in gp.check_scenes(items, root=Path(root))]
        elif stage == "reach":
            results = gp.check_reach([(driver, name, pickle.loads(scene), picks, places)
                                      for driver, name, scene, picks, places in items])
        else:
            raise SupervisorError(f"unknown graph check stage {stage!r}; valid stages: reach, scenes, trees")
        self.reply("graph_checked", stage=stage, results=results)

    def job_release(self, root: str, target: str, session_id: str | None = None) -> None:
        from phyagentos.runtime.target_lock import clear_marker  # noqa: PLC0415

        lock = self.lock(root, target)
        if lock.held:
            clear_marker(Path(root) / "targets", target, session_id=session_id)
        lock.release()
        self.reply("released", target=target)

    def serve(self) -> None:
        threading.Thread(target=self.read_forever, name="runner-pipe", daemon=True).start()
        while True:
            kind, payload = self.jobs.get()
            if kind == "exit":
                break
            if kind == "ping":
                self.reply("pong")
                continue
            handler = getattr(self, f"job_{kind}", None)
            try:
                if self.prepared is not None and kind != "go":
                    self.discard_prepared()  # the prepared session was not started
                if handler is None:
                    raise SupervisorError(f"unknown runner job {kind!r}")
                handler(**payload)
            except Exception as exc:  # noqa: BLE001 - report, keep serving
                logger.exception("runner job %s failed", kind)
                self.reply("error", job=kind, message=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc())
        self.discard_prepared()
        self.release_all()
        self.images.close()  # owed images first: the targets' models must outlive their renders
        for pool in self.pools.values():
            pool.close()


def runner_main(conn, hb_array, skills_dir: str, trees_dir: str, log_level: int = logging.WARNING) -> None:
    """Entry point of the runner process (see the module docstring)."""
    # Ctrl-C reaches the whole foreground process group; stopping is the supervisor's
    # decision, delivered as a cancel message, so the runner ignores SIGINT.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import phyagentos  # noqa: F401,PLC0415 - selects the headless GL backend before mujoco loads

    logging.basicConfig(level=log_level, format="runner %(process)d %(name)s: %(message)s")
    logging.getLogger("transitions").setLevel(max(log_level, logging.WARNING))
    logging.getLogger("toppra").setLevel(max(log_level, logging.WARNING))
    runner = _Runner(conn, Heartbeats(hb_array), skills_dir, trees_dir)
    runner.serve()
    conn.close()
