"""How hard the drills push: ``make test`` runs them at their quick scale, ``make soak``
(``PHYAGENTOS_SOAK=1``) at their full one.

The drills (SIGKILLs of supervisors and runners during sessions and hand-offs, four
supervisors racing for one queue) cost CPU in proportion to their kills and sessions:
every kill restarts a supervisor or a runner, which re-imports MuJoCo and the
primitives. The quick scale keeps every kind of kill and every assertion; the soak scale
is the one the drills were written with, for a machine with time to spare.
"""

from __future__ import annotations

import os

__all__ = ["SOAK", "scaled"]

#: True when the drills run at their full scale (``PHYAGENTOS_SOAK`` set and not ``0``).
SOAK = os.environ.get("PHYAGENTOS_SOAK", "") not in ("", "0")


def scaled(quick: int, soak: int) -> int:
    """``soak`` under ``make soak``, else ``quick``."""
    return soak if SOAK else quick
