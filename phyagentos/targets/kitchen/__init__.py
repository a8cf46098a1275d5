"""The FrankaKitchen environment (gymnasium-robotics) behind the Target contract
(driver ``gymnasium_kitchen``).

:mod:`.target`: :class:`FrankaKitchenTarget` and its :class:`KitchenScene`.
"""

from .target import *  # noqa: F403 - the embodiment's public names
from .target import __all__  # noqa: F401
