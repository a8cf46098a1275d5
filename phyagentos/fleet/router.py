"""``phyagentos router``: a zenoh router in this process (any zenoh router, e.g. ``zenohd``
with the same auth settings, does as well)."""

from __future__ import annotations

import logging
import threading

from phyagentos.errors import FleetError

from .config import FleetConfig
from .link import FleetLink

__all__ = ["run_router"]

log = logging.getLogger(__name__)


def run_router(config: FleetConfig, *, stop: threading.Event, on_ready=None) -> None:
    """Run a router listening on ``config.listen`` until ``stop`` is set.

    With ``config.auth`` (and its ``users_file``), only the peers listed there get in.

    Raises:
        FleetError: no listen endpoint, a port in use, or auth without a users file.
    """
    if not config.listen:
        raise FleetError("a router needs --listen ENDPOINT (e.g. tcp/0.0.0.0:7447) or listen: in fleet.yaml")
    if config.auth is not None and config.auth.users_file is None:
        raise FleetError("router auth needs users_file (the 'user:password' lines of the peers let in)")
    link = FleetLink(config, mode="router")
    try:
        if on_ready is not None:
            on_ready()
        stop.wait()
    finally:
        link.close()
