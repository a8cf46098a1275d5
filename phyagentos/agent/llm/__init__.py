"""The Agent plane's side of language models: what it tells a model and what it accepts back.

* :mod:`.world` -- the entities a plan may name, from the scene the user gave (or what the
  runtime last perceived in ENVIRONMENT.md), never from the simulator's own state;
* :mod:`.policy` -- the text policy that screens instructions and names for injection;
* :mod:`.prompt` -- :class:`ModelContextBuilder`: request, environment, capabilities, prior
  attempts and lessons within a token budget, recording what it injected.

The model interface itself is plane-neutral: :mod:`phyagentos.llm`.
"""

from .policy import InjectionFinding, screen_text
from .prompt import ModelContext, ModelContextBuilder
from .world import Entity, World, perceived_world, world_from_environment, world_from_scene

__all__ = ["Entity", "InjectionFinding", "ModelContext", "ModelContextBuilder", "World", "screen_text",
           "perceived_world", "world_from_environment", "world_from_scene"]
