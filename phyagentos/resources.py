"""Where the project's authored files live: ``skills/``, ``trees/``, ``protocol/``, ``goal_graphs/``.

They sit at the repository's top level next to the package (the package is
installed in editable mode by the set-up scripts). ``PHYAGENTOS_HOME`` overrides
the root, e.g. for a deployment that keeps its own skills and trees.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["project_root", "skills_dir", "trees_dir", "templates_dir", "goal_graphs_dir"]


def project_root() -> Path:
    """The directory holding ``skills/``, ``trees/`` and ``protocol/``."""
    env = os.environ.get("PHYAGENTOS_HOME")
    return Path(env) if env else Path(__file__).resolve().parent.parent


def skills_dir() -> Path:
    return project_root() / "skills"


def trees_dir() -> Path:
    return project_root() / "trees"


def templates_dir() -> Path:
    return project_root() / "protocol"


def goal_graphs_dir() -> Path:
    return project_root() / "goal_graphs"
