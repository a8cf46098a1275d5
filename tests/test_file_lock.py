"""Workspace locks (phyagentos/protocol/file_lock.py): exclusive between processes and
threads, re-entrant within a thread, released by the kernel when the holder dies."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from phyagentos.errors import LockTimeout, ProtocolError
from phyagentos.protocol import Workspace
from phyagentos.protocol.file_lock import WorkspaceLock, workspace_lock

REPO = Path(__file__).resolve().parents[1]
_ENV = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}

#: A child that takes the lock, says so on stdout, then waits for a line on stdin
#: (or is killed) before it lets go.
HOLDER = (
    "import sys\n"
    "from phyagentos.protocol.file_lock import workspace_lock\n"
    "lock = workspace_lock(sys.argv[1]).acquire()\n"
    "print('held', flush=True)\n"
    "sys.stdin.readline()\n"
    "lock.release()\n"
)


def _holder(path: Path) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(path)], env=_ENV, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_lock_held_by_another_process_times_out_and_is_free_once_that_process_lets_go(tmp_path):
    path = tmp_path / "a.lock"
    proc = _holder(path)
    try:
        lock = workspace_lock(path)
        started = time.monotonic()
        with pytest.raises(LockTimeout) as info:
            lock.acquire(timeout=0.05)
        assert time.monotonic() - started >= 0.05
        assert isinstance(info.value, TimeoutError) and isinstance(info.value, ProtocolError)
        assert str(path) in str(info.value)
        assert not lock.held
    finally:
        proc.stdin.write("\n")
        proc.stdin.flush()
        proc.wait(timeout=30)
    with lock:
        assert lock.held
    assert not lock.held


def test_the_kernel_frees_the_lock_of_a_killed_holder(tmp_path):
    path = tmp_path / "a.lock"
    proc = _holder(path)
    with pytest.raises(LockTimeout):
        workspace_lock(path).acquire(timeout=0)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    lock = workspace_lock(path).acquire(timeout=5)
    lock.release()


def test_a_blocked_waiter_takes_the_lock_as_soon_as_the_other_process_releases_it(tmp_path):
    path = tmp_path / "a.lock"
    proc = _holder(path)
    lock = workspace_lock(path)
    taken = threading.Event()

    def wait() -> None:
        with lock:  # no timeout: blocks in the kernel
            taken.set()

    waiter = threading.Thread(target=wait)
    waiter.start()
    try:
        assert not taken.wait(0.2)  # still held by the other process
    finally:
        proc.stdin.write("\n")
        proc.stdin.flush()
        proc.wait(timeout=30)
    assert taken.wait(10)
    waiter.join(10)


def test_threads_of_one_process_exclude_each_other(tmp_path):
    path = tmp_path / "count.lock"
    counter = tmp_path / "count"
    counter.write_text("0")
    threads, rounds = 4, 200

    def work() -> None:
        for _ in range(rounds):
            with workspace_lock(path):
                value = int(counter.read_text())
                time.sleep(0)  # let another thread run inside the critical section if it could
                counter.write_text(str(value + 1))

    pool = [threading.Thread(target=work) for _ in range(threads)]
    for t in pool:
        t.start()
    for t in pool:
        t.join(60)
    assert int(counter.read_text()) == threads * rounds


def test_one_thread_holding_the_lock_keeps_it_from_another_thread_until_its_last_release(tmp_path):
    lock = workspace_lock(tmp_path / "a.lock")
    other: list[bool] = []

    def try_once() -> None:
        try:
            lock.acquire(timeout=0)
        except LockTimeout:
            other.append(False)
        else:
            other.append(True)
            lock.release()

    with lock:
        with lock:  # re-entrant in this thread
            pass
        t = threading.Thread(target=try_once)
        t.start()
        t.join(10)
        assert other == [False]  # one level is still held
    t = threading.Thread(target=try_once)
    t.start()
    t.join(10)
    assert other[-1] is True


def test_workspace_objects_of_one_directory_share_its_locks_so_nesting_them_does_not_wait(tmp_path, monkeypatch):
    Workspace.create(tmp_path / "ws")
    (tmp_path / "alias").symlink_to(tmp_path / "ws")
    monkeypatch.chdir(tmp_path)
    spellings = [Workspace(tmp_path / "ws"), Workspace("ws"), Workspace(tmp_path / "alias"), Workspace("./ws/")]
    done = threading.Event()

    def nest() -> None:
        with spellings[0].session_lock("s1"):
            with spellings[1].session_lock("s1"):
                with spellings[2].session_lock("s1"):
                    with spellings[3].session_lock("s1"):
                        done.set()

    t = threading.Thread(target=nest, daemon=True)
    t.start()
    assert done.wait(10), "a nested acquisition through another Workspace object waited for itself"
    locks = [w.session_lock("s1") for w in spellings]  # held together: ids of objects alive at once
    assert all(lock is locks[0] for lock in locks)


def test_a_forked_child_does_not_inherit_its_parents_hold(tmp_path):
    lock = workspace_lock(tmp_path / "a.lock")
    with lock:
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: not holding; the parent's flock keeps it out
            code = 0
            try:
                if lock.held:
                    code = 3
                else:
                    try:
                        lock.acquire(timeout=0)
                        code = 4
                    except LockTimeout:
                        code = 0
            finally:
                os.write(write, bytes([code]))
                os._exit(0)
        os.close(write)
        answer = os.read(read, 1)
        os.waitpid(pid, 0)
    assert answer == bytes([0])


def test_release_without_holding_the_lock_is_an_error_and_a_missing_lock_directory_is_made(tmp_path):
    path = tmp_path / "made" / "on" / "use.lock"
    lock = WorkspaceLock(path)
    with pytest.raises(RuntimeError, match="does not hold"):
        lock.release()
    with lock:
        assert path.exists()


def test_a_lock_taken_without_keeping_a_reference_is_the_same_lock_at_its_release(tmp_path):
    import gc

    path = tmp_path / "a.lock"
    workspace_lock(path).acquire()
    gc.collect()  # no reference is left to the object but the module's own
    again = workspace_lock(path)
    assert again.held
    again.acquire(timeout=0)  # re-entrant: the same object, not a second descriptor waiting for the first
    again.release()
    again.release()
    assert not again.held
    probe = subprocess.run([sys.executable, "-c",
                            "import sys\nfrom phyagentos.protocol.file_lock import workspace_lock\n"
                            "workspace_lock(sys.argv[1]).acquire(timeout=0)\n", str(path)], env=_ENV, timeout=60)
    assert probe.returncode == 0  # released for other processes too
