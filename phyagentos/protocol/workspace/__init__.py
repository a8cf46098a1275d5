"""The State-as-a-File workspace: protocol documents, session files, evidence.

Layout (see docs/ARCHITECTURE.md)::

    ws/SESSIONS.md ... RUNTIME_SIGNAL.md safety.yaml
    ws/sessions/<id>.md                    one document per active session (the source of truth)
    ws/sessions/.index/<id>~<state>        state hints of active sessions (session_index.py)
    ws/sessions/archive/YYYY-MM-DD/<id>.md terminal sessions, moved out of the way (archive.py)
    ws/runs/<run_id>/                      submitted goal graphs (runs.py)
    ws/evidence/<id>/                      evidence bundles
    ws/targets/<target>/                   simulated target state
    ws/log/                                archive-YYYY-MM.jsonl, LOG.md entries that aged out
    ws/.locks/                             lock files (flock, file_lock.py)

Every write is read-validate-modify-atomic-write under a file lock, so
concurrent processes never lose each other's updates and a malformed file is
reported (``DocumentError``) and never overwritten.

Cost does not grow with history: a transition writes one session file, renames
one hint and rewrites the bounded SESSIONS.md; queries over active sessions scan
``sessions/.index/``; a run's finished sessions are found through its archive
catalogue. Only :meth:`Workspace.list_sessions` without a run filter reads the
whole archive.
"""

from .core import Workspace, templates_dir
from .states import LEASED_STATES, WAITING_STATES

__all__ = ["Workspace", "templates_dir", "LEASED_STATES", "WAITING_STATES"]
