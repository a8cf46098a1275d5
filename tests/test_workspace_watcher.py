"""WorkspaceWatcher wake-ups are not held back by watchdog's move pairing.

watchdog holds an unmatched ``IN_MOVED_FROM`` for its pairing delay (0.5 s by default)
and delivers nothing after it meanwhile. A session file archived out of ``sessions/``
is such an event, so, before ``phyagentos.protocol.watch`` set that delay to zero,
every wake-up of a two-process agent or supervisor in the half second after an
archive came 0.5 s late (a two-process chain of 0 s holds ran at 2 sessions/s).
"""

from __future__ import annotations

import os
import time

from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.protocol.watch import WorkspaceWatcher

#: Well under the 0.5 s a held move costs, well over an inotify wake-up on a loaded machine.
PROMPT_S = 0.25


def _woke_within(watcher: WorkspaceWatcher, action) -> float:
    watcher.clear()
    start = time.monotonic()
    action()
    assert watcher.wait(5.0), "no wake-up at all"
    return time.monotonic() - start


def test_a_file_moved_out_of_a_watched_directory_wakes_at_once_and_holds_back_no_later_write(tmp_path):
    (tmp_path / "archive").mkdir()
    watcher = WorkspaceWatcher(tmp_path, dirs=("sessions",))
    try:
        assert watcher.mode == "inotify"
        for i in range(3):
            active = tmp_path / "sessions" / f"s{i}.md"
            atomic_write_text(active, "submitted")
            time.sleep(0.05)
            moved = _woke_within(watcher, lambda: os.rename(active, tmp_path / "archive" / active.name))
            assert moved < PROMPT_S, f"archive move woke after {moved:.3f} s"
            # the next session's write, right after the archive, is not queued behind it
            written = _woke_within(watcher, lambda: atomic_write_text(tmp_path / "sessions" / f"n{i}.md", "next"))
            assert written < PROMPT_S, f"write after an archive woke after {written:.3f} s"
    finally:
        watcher.close(wait=True)


def test_a_signal_file_replaced_in_the_root_wakes_the_watcher_and_other_root_files_do_not(tmp_path):
    watcher = WorkspaceWatcher(tmp_path, dirs=("sessions",), files=("RUNTIME_SIGNAL.md",))
    try:
        for i in range(20):
            watcher.clear()
            atomic_write_text(tmp_path / "TASK.md", f"view {i}")
            assert not watcher.wait(0.05), "a write of another root file woke the watcher"
            assert _woke_within(watcher, lambda: atomic_write_text(tmp_path / "RUNTIME_SIGNAL.md", f"{i}")) < 5.0
    finally:
        watcher.close(wait=True)
