"""LIBERO behind the Target contract (driver ``libero``; docs/libero.md).

:mod:`.catalog`: suites, tasks, init states and BDDL problems, resolved without building a
world. :mod:`.target`: :class:`LiberoTarget` and its scene :class:`LiberoScene`, with its
mix-ins :mod:`.osc` (LIBERO's OSC_POSE action form), :mod:`.privileged` (LIBERO's checker and
true state, for scoring only) and :mod:`.sensing` (declared objects, perception parameters,
camera images). Needs the
``libero`` extra (``pip install -e '.[libero]'``).
"""

from .catalog import *  # noqa: F403 - the embodiment's public names
from .catalog import __all__ as _catalog_all
from .target import *  # noqa: F403
from .target import __all__ as _target_all

__all__ = [*_catalog_all, *_target_all]
