"""PhyAgentOS: goal graphs to verified sessions on embodied targets.

Subpackages, in the order one session flows through them:

- :mod:`phyagentos.agent` (Agent plane): goal graphs, Session Compiler, SessionVerifier.
- :mod:`phyagentos.protocol` (boundary): protocol documents, schemas, Workspace, lifecycle.
- :mod:`phyagentos.runtime` (Runtime plane): WatchdogSupervisor, preflight,
  SessionRunner, BuiltinSkillRuntime and behaviour trees.
- :mod:`phyagentos.primitives`, :mod:`phyagentos.motion`, :mod:`phyagentos.targets`:
  py_trees primitives, mink/OMPL/toppra motion, MuJoCo targets.

Importing this package is cheap; subpackages load MuJoCo and friends on demand.
"""

import os as _os

# MuJoCo picks its OpenGL backend when it is first imported. Headless machines
# (no DISPLAY) get OSMesa, the software renderer that needs no GPU; set
# MUJOCO_GL=egl (GPU) or glfw (desktop) yourself to override.
if not _os.environ.get("DISPLAY"):
    _os.environ.setdefault("MUJOCO_GL", "osmesa")

__version__ = "0.1.0"
__all__ = ["__version__"]
