"""``phyagentos view``: a live web view of a workspace (runs, goal DAGs, behaviour trees,
sessions and their evidence, the robot in 3D, memory) with the runtime's signal buttons.

The protocol files stay the source of truth: the view reads them through
:mod:`phyagentos.protocol` and writes nothing but signals, through
:meth:`~phyagentos.protocol.Workspace.send_signal` (as ``phyagentos signal`` does).
A composition root: it reads Agent-plane data (node states) and rebuilds Runtime-plane
targets (for the 3D scene), so neither plane imports it.
"""

from .app import bind, create_app, serve
from .security import AccessPolicy, safe_path

__all__ = ["create_app", "serve", "bind", "AccessPolicy", "safe_path"]
