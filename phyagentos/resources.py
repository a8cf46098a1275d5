"""Where the shipped authored files live: ``skills/``, ``trees/``, ``protocol/``, ``goal_graphs/``.

They are package data under ``phyagentos/data/`` (:func:`data_root`), so an installed
wheel carries them and runs its example goal graphs from any directory; the set-up
scripts' editable install reads the same folder from the checkout. ``PHYAGENTOS_HOME``
overrides the root (a folder with the same four subfolders), e.g. for a deployment that
keeps its own skills, trees and templates.

Skills and trees are looked up along a *search path* (:func:`search_path`): the
workspace's own ``skills/`` and ``trees/``, then each ``--skills-path`` entry (a folder
holding ``skills/`` and/or ``trees/``; the CLI passes them to every process it starts
through ``PHYAGENTOS_SKILLS_PATH``, entries separated by ``os.pathsep``), then the
shipped ones. The first folder that has a name wins; a later one with the same name is
reported (``SkillRegistry.shadowed``), never silently used.

The shipped example goal graphs have names (:func:`example_graphs`): the CLI accepts
``pick_and_place`` where it takes a goal-graph path (:func:`goal_graph_path`).
"""

from __future__ import annotations

import os
from pathlib import Path

from phyagentos.errors import PhyAgentOSError

__all__ = ["data_root", "skills_dir", "trees_dir", "templates_dir", "goal_graphs_dir", "search_path",
           "skill_dirs", "tree_dirs", "example_graphs", "goal_graph_path", "ExampleNotFoundError",
           "SKILLS_PATH_ENV", "HOME_ENV"]

#: Extra skill folders (``--skills-path``), ``os.pathsep``-separated.
SKILLS_PATH_ENV = "PHYAGENTOS_SKILLS_PATH"
#: Replaces :func:`data_root` (a folder holding ``skills/``, ``trees/``, ``protocol/``, ``goal_graphs/``).
HOME_ENV = "PHYAGENTOS_HOME"


class ExampleNotFoundError(PhyAgentOSError):
    """A goal-graph argument is neither a file nor the name of a shipped example."""


def data_root() -> Path:
    """The directory holding ``skills/``, ``trees/``, ``protocol/`` and ``goal_graphs/``:
    ``$PHYAGENTOS_HOME`` if set, else the package's ``data/`` folder."""
    env = os.environ.get(HOME_ENV)
    return Path(env) if env else Path(__file__).resolve().parent / "data"


def skills_dir() -> Path:
    return data_root() / "skills"


def trees_dir() -> Path:
    return data_root() / "trees"


def templates_dir() -> Path:
    return data_root() / "protocol"


def goal_graphs_dir() -> Path:
    return data_root() / "goal_graphs"


def example_graphs() -> dict[str, Path]:
    """Name (file stem) -> path of every shipped example goal graph, sorted by name."""
    return {p.stem: p for p in sorted(goal_graphs_dir().glob("*.yaml"))}


def goal_graph_path(text: str | os.PathLike[str]) -> Path:
    """A goal-graph argument as a path: an existing file as given; else a bare name
    (no folder, no suffix) of a shipped example (``pick_and_place``) as that example's
    path. Anything else comes back unchanged, so the loader reports the missing file.

    Raises:
        ExampleNotFoundError: a bare name that is no file and no shipped example (the
            message lists the examples).
    """
    path = Path(text)
    if path.exists() or path.suffix or len(path.parts) != 1:
        return path
    examples = example_graphs()
    if path.name in examples:
        return examples[path.name]
    raise ExampleNotFoundError(f"goal graph {str(text)!r}: no such file, nor a shipped example "
                               f"(one of {', '.join(examples)}; in {goal_graphs_dir()})")


def search_path(workspace: str | Path | None = None, extra: "list[str | Path] | tuple[str | Path, ...]" = ()) -> tuple[Path, ...]:
    """Folders searched for ``skills/`` and ``trees/``, first wins: ``workspace``, ``extra``
    (then :data:`SKILLS_PATH_ENV`'s entries), then :func:`data_root`. Duplicates dropped."""
    env = [p for p in os.environ.get(SKILLS_PATH_ENV, "").split(os.pathsep) if p]
    roots = ([Path(workspace)] if workspace is not None else []) + [Path(p) for p in (*extra, *env)] + [data_root()]
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
                           if (r / "skills").is_dir() or r == data_root())


def tree_dirs(workspace: str | Path | None = None, extra=()) -> str:
    """As :func:`skill_dirs` for ``trees/``."""
    return os.pathsep.join(str(r / "trees") for r in search_path(workspace, extra)
                           if (r / "trees").is_dir() or r == data_root())
