"""WatchdogSupervisor: the Runtime plane's single entry point for sessions.

It supervises rather than controls. It claims a pending session atomically with a
lease, has its runner process (:mod:`phyagentos.runtime.worker`) run compatibility
preflight and then the session, watches the runner's heartbeats and the session's
deadlines, renews the lease while the runner is healthy, acts on RUNTIME_SIGNAL.md,
and writes every transition of the session file itself (the runner never does).
It never judges success: that is the Agent plane's SessionVerifier.

One session at a time per supervisor; run several supervisors (``phyagentos watch``
processes) on one workspace for parallelism. What keeps them safe together:

- **Claims** happen under the session's file lock and only from ``pending``, and
  carry a lease ``{owner, token, expires_at}``; every later write presents the token
  (:meth:`Workspace.update_session`), so a supervisor that lost its lease can never
  overwrite the one that took the session over.
- **Targets**: a session is claimed only after the runner holds the target's
  actuation lock (:mod:`phyagentos.runtime.target_lock`), so a target runs one
  session at a time, and ``inflight.yaml`` tells the next holder which session
  ended abnormally on it. The runner's preflight (read-only; it writes that marker)
  runs while the claim is written, and the session is prepared while ``start`` is
  written; nothing moves before ``go``, sent once ``start`` is durable. A claim that
  fails clears the marker its preflight wrote; one left by a crash names a session
  that is not leased, which the next holder's preflight replaces.
- **Crashes**: a session whose lease expired is taken over. If it had not started
  actuating it goes back to ``pending``. If it was actuating (``running``,
  ``finalizing``) it is never re-run: a fresh runner restores the target's last
  checkpoint, halts it, persists the halted state and writes a terminal snapshot,
  and the session goes to ``awaiting_verification`` with attempt outcome
  ``unknown`` (``outcome_unknown``), for the verifier to judge from that fresh
  observation before anything moves again.
- **Runner failures**: a runner that dies, goes silent (``heartbeat.*``), overruns
  its execution deadline or ignores a cancel is killed (SIGKILL) and the target put
  in a safe state the same way; the session ends attributed (docs/ERRORS.md).
- **Timeouts**: queue (pending too long after submit), preflight and execution,
  each enforced here whatever the runner does.
- **Signals**: cancel, pause/resume, e-stop/clear_estop from RUNTIME_SIGNAL.md.
- **Wake-ups**: inotify on ``sessions/``, ``sessions/.index/`` and RUNTIME_SIGNAL.md,
  plus the runner's pipe, with a bounded polling fallback; idle, it sleeps.

Use :meth:`serve` for the long-running process (``phyagentos watch``) and
:meth:`run_once` to process what is claimable now and return (``phyagentos run``).
"""

from .config import SupervisorConfig
from .core import WatchdogSupervisor
from .inflight import PHASES, InflightSession
from .presence import PRESENCE_DIR, read_presence

__all__ = ["WatchdogSupervisor", "SupervisorConfig", "InflightSession", "PHASES", "PRESENCE_DIR", "read_presence"]
