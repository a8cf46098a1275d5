"""Leases: a time-bounded, fenced claim on a session.

A supervisor that claims a session writes a :class:`~phyagentos.protocol.schemas.Lease`
``{owner, token, expires_at}`` into the session file in the same atomic write as the
``claim`` transition, and renews ``expires_at`` while its runner's heartbeat is fresh.
Every later write by that supervisor presents its token (:meth:`Workspace.update_session`);
once the lease has expired another supervisor may take the session over with a new
token, after which the old owner's writes fail with :class:`~phyagentos.errors.LeaseError`
(fencing), so a supervisor that was merely slow can never overwrite its successor.

Expiry uses wall-clock time (``time.time()``, unix seconds) because leases are compared
across processes; on one host that clock is shared. ``EXPIRY_MARGIN_S`` absorbs
scheduling jitter between the owner's renewal and a rival's check.
"""

from __future__ import annotations

import secrets
import time

from .schemas import Lease

__all__ = ["EXPIRY_MARGIN_S", "new_lease", "renewed", "is_expired", "remaining_s"]

#: A rival treats a lease as expired only this long (s) after ``expires_at``.
EXPIRY_MARGIN_S = 0.25


def new_lease(owner: str, *, ttl_s: float, now: float | None = None) -> Lease:
    """A fresh lease for ``owner`` valid for ``ttl_s`` seconds, with a random 128-bit token.

    Raises:
        ValueError: ``ttl_s`` is not positive.
    """
    if not ttl_s > 0:
        raise ValueError(f"lease ttl_s must be > 0 seconds, got {ttl_s!r}")
    now = time.time() if now is None else now
    return Lease(owner=owner, token=secrets.token_hex(16), expires_at=now + ttl_s)


def renewed(lease: Lease, *, ttl_s: float, now: float | None = None) -> Lease:
    """The same lease (owner and token) extended to ``now + ttl_s``."""
    now = time.time() if now is None else now
    return Lease(owner=lease.owner, token=lease.token, expires_at=now + ttl_s)


def is_expired(lease: Lease | None, *, now: float | None = None, margin_s: float = EXPIRY_MARGIN_S) -> bool:
    """True when ``lease`` is missing or ended more than ``margin_s`` seconds ago."""
    if lease is None:
        return True
    now = time.time() if now is None else now
    return now > lease.expires_at + margin_s


def remaining_s(lease: Lease | None, *, now: float | None = None) -> float:
    """Seconds until ``lease`` expires (negative once expired; ``-inf`` without a lease)."""
    if lease is None:
        return float("-inf")
    now = time.time() if now is None else now
    return lease.expires_at - now
