"""A fleet over the network (issue 31): the Runtime plane at each robot (``edge``), the
Agent plane anywhere (``run --fleet``), kept in step through a zenoh router.

Modules: :mod:`.config` (fleet.yaml), :mod:`.link` (the zenoh session and key
expressions), :mod:`.replication` (revisions and the convergence rule), :mod:`.catchup`,
:mod:`.presence` (liveliness), :mod:`.ownership`, :mod:`.link_loss`, :mod:`.edge` (Runtime
plane side), :mod:`.agent_side` (Agent plane side), :mod:`.router`. See docs/fleet.md.

The package imports nothing heavy at import time; zenoh loads with the first link.
"""

__all__: list[str] = []
