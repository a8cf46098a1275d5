"""The simulated Franka Panda on a tabletop behind the Target contract (driver ``mujoco_franka``).

:mod:`.target`: :class:`MuJoCoTarget`. The tabletop scene it is built from
(:mod:`phyagentos.targets.scene`) is shared with the SO-101.
"""

from .target import *  # noqa: F403 - the embodiment's public names
from .target import __all__  # noqa: F401
