"""What the Agent knows about skills: their parameters, read from ``skills/*.yaml``.

The Agent plane may not import the Runtime's skill registry, but the manifests are
authored files both planes read (like goal graphs). A skill's *required* parameters
define the task (which object, which region); its optional ones are strategy knobs
that recovery and memory may revise.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from phyagentos import resources
from phyagentos.errors import SkillError
from phyagentos.yamlsource import load_yaml

__all__ = ["SkillInfo", "skill_catalog"]


@dataclass(frozen=True)
class SkillInfo:
    """A skill's parameter names: ``required`` (the task) and ``optional`` (strategy);
    ``acquires`` / ``releases``: the parameter naming the object the skill leaves in,
    or takes out of, its target's gripper (``None``: no such effect); ``runtime``: the
    SkillRuntime its manifest names (``builtin``, ``policy``, ``agent``; ``None``: not given)."""

    name: str
    required: frozenset[str]
    optional: frozenset[str]
    acquires: str | None = None
    releases: str | None = None
    runtime: str | None = None

    @property
    def parameters(self) -> frozenset[str]:
        return self.required | self.optional


@lru_cache(maxsize=8)
def _load(directory: str) -> dict[str, SkillInfo]:
    out = {}
    # a search path (os.pathsep-joined, first wins), like the runtime's SkillRegistry
    paths = [p for folder in directory.split(os.pathsep) if folder for p in sorted(Path(folder).glob("*.yaml"))]
    for path in paths:
        try:
            data = load_yaml(path.read_text(encoding="utf-8"), path=path, error=SkillError) or {}
        except (SkillError, OSError, UnicodeDecodeError):
            continue  # the runtime's registry reports malformed manifests
        if not isinstance(data, dict) or not isinstance(data.get("name"), str):
            continue  # the runtime's registry reports malformed manifests
        params = data.get("params") or {}
        required = frozenset(k for k, d in params.items() if isinstance(d, dict) and d.get("required"))
        effect = {k: data.get(k) if isinstance(data.get(k), str) else None for k in ("acquires", "releases")}
        if data["name"] in out:
            continue  # shadowed by an earlier folder of the search path
        out[data["name"]] = SkillInfo(name=data["name"], required=required, optional=frozenset(params) - required,
                                      runtime=data["runtime"] if isinstance(data.get("runtime"), str) else None,
                                      **effect)
    return out


def skill_catalog(directory: str | Path | None = None) -> dict[str, SkillInfo]:
    """Skill name -> :class:`SkillInfo` for the manifests in ``directory`` (one folder or
    an ``os.pathsep``-joined search path, first wins; default: the shipped skills plus
    ``PHYAGENTOS_SKILLS_PATH``, :func:`phyagentos.resources.skill_dirs`). Cached per path."""
    return dict(_load(str(directory if directory is not None else resources.skill_dirs())))
