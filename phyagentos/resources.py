"""Where the project's authored files live: ``skills/``, ``trees/``, ``protocol/``, ``goal_graphs/``.

They sit at the repository's top level next to the package (the package is
installed in editable mode by the set-up scripts). ``PHYAGENTOS_HOME`` overrides
the root, e.g. for a deployment that keeps its own skills and trees.

Skills and trees are looked up along a *search path* (:func:`search_path`): the
workspace's own ``skills/`` and ``trees/``, then each ``--skills-path`` entry (a folder
holding ``skills/`` and/or ``trees/``; the CLI passes them to every process it starts
through ``PHYAGENTOS_SKILLS_PATH``, entries separated by ``os.pathsep``), then the
shipped ones. The first folder that has a name wins; a later one with the same name is
reported (``SkillRegistry.shadowed``), never silently used.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["project_root", "skills_dir", "trees_dir", "templates_dir", "goal_graphs_dir", "search_path",
           "skill_dirs", "tree_dirs", "SKILLS_PATH_ENV"]

#: Extra skill folders (``--skills-path``), ``os.pathsep``-separated.
SKILLS_PATH_ENV = "PHYAGENTOS_SKILLS_PATH"


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


def search_path(workspace: str | Path | None = None, extra: "list[str | Path] | tuple[str | Path, ...]" = ()) -> tuple[Path, ...]:
    """Folders searched for ``skills/`` and ``trees/``, first wins: ``workspace``, ``extra``
    (then :data:`SKILLS_PATH_ENV`'s entries), then :func:`project_root`. Duplicates dropped."""
    env = [p for p in os.environ.get(SKILLS_PATH_ENV, "").split(os.pathsep) if p]
    roots = ([Path(workspace)] if workspace is not None else []) + [Path(p) for p in (*extra, *env)] + [project_root()]
    out: list[Path] = []
    for root in roots:
        resolved = root.resolve()
        if resolved not in [r.resolve() for r in out]:
            out.append(root)
    return tuple(out)


def skill_dirs(workspace: str | Path | None = None, extra=()) -> str:
    """The existing ``skills/`` folders of :func:`search_path`, joined with ``os.pathsep``
    (what :class:`~phyagentos.runtime.skills.SkillRegistry` accepts)."""
    return os.pathsep.join(str(r / "skills") for r in search_path(workspace, extra)
                           if (r / "skills").is_dir() or r == project_root())


def tree_dirs(workspace: str | Path | None = None, extra=()) -> str:
    """As :func:`skill_dirs` for ``trees/``."""
    return os.pathsep.join(str(r / "trees") for r in search_path(workspace, extra)
                           if (r / "trees").is_dir() or r == project_root())
