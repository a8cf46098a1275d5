"""The tunables of a WatchdogSupervisor."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SupervisorConfig"]


@dataclass(frozen=True)
class SupervisorConfig:
    """Tunables of a WatchdogSupervisor (all times in seconds).

    Attributes:
        lease_s: lease duration; renewed every ``lease_s / 3`` while the runner is healthy.
            A crashed supervisor's sessions are recovered about this long after it died.
        poll_interval_s: longest sleep between checks (bounds a missed wake-up).
        maintenance_interval_s: how often expired leases and queue timeouts are checked.
        cancel_grace_s: a runner must stop this long after a cancel or it is killed.
        estop_grace_s: as ``cancel_grace_s`` for an e-stop.
        execution_grace_s: the supervisor's execution deadline is the session's
            ``execution_timeout_s`` plus this (the runner enforces the exact one).
        checkpoint_interval_s: the runner persists the target state this often while running.
        reply_timeout_s: longest wait for a runner's reply to a quick job (includes its start-up).
        recover_timeout_s: longest wait for a safe-stop of a target.
        drain_s: on SIGINT/SIGTERM, in-flight sessions get this long to finish before
            they are cancelled.
        reconcile_interval_s: how often the state hints are reconciled with the session files.
        inotify: False forces the polling fallback (benchmarks compare both).
        targets: claim only sessions on these targets (None: any target).
    """

    lease_s: float = 10.0
    poll_interval_s: float = 1.0
    maintenance_interval_s: float = 1.0
    cancel_grace_s: float = 3.0
    estop_grace_s: float = 0.5
    execution_grace_s: float = 2.0
    checkpoint_interval_s: float = 0.25
    reply_timeout_s: float = 120.0
    recover_timeout_s: float = 120.0
    drain_s: float = 5.0
    reconcile_interval_s: float = 60.0
    inotify: bool = True
    targets: tuple[str, ...] | None = None
