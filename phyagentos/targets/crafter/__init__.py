"""The Crafter game behind the Target contract (driver ``crafter``).

:mod:`.target`: :class:`CrafterTarget` and its :class:`CrafterScene`. Registered like
every other driver (entry point ``crafter`` in ``pyproject.toml``).
"""

from .target import *  # noqa: F403 - the embodiment's public names
from .target import __all__  # noqa: F401
