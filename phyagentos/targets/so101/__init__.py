"""The simulated SO-101 arm on a tabletop behind the Target contract (driver ``mujoco_so101``).

:mod:`.target`: :class:`SO101Target`, its model builder and its datasheet constants.
"""

from .target import *  # noqa: F403 - the embodiment's public names
from .target import __all__  # noqa: F401
