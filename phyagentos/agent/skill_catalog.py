"""What the Agent knows about skills: their parameters, read from ``skills/*.yaml``.

The Agent plane may not import the Runtime's skill registry, but the manifests are
authored files both planes read (like goal graphs). A skill's *required* parameters
define the task (which object, which region); its optional ones are strategy knobs
that recovery and memory may revise.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import yaml

from phyagentos import resources

__all__ = ["SkillInfo", "skill_catalog"]


@dataclass(frozen=True)
class SkillInfo:
    """A skill's parameter names: ``required`` (the task) and ``optional`` (strategy)."""

    name: str
    required: frozenset[str]
    optional: frozenset[str]

    @property
    def parameters(self) -> frozenset[str]:
        return self.required | self.optional


@lru_cache(maxsize=8)
def _load(directory: str) -> dict[str, SkillInfo]:
    out = {}
    for path in sorted(Path(directory).glob("*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
        if not isinstance(data, dict) or not isinstance(data.get("name"), str):
            continue  # the runtime's registry reports malformed manifests
        params = data.get("params") or {}
        required = frozenset(k for k, d in params.items() if isinstance(d, dict) and d.get("required"))
        out[data["name"]] = SkillInfo(name=data["name"], required=required, optional=frozenset(params) - required)
    return out


def skill_catalog(directory: str | Path | None = None) -> dict[str, SkillInfo]:
    """Skill name -> :class:`SkillInfo` for the manifests in ``directory``
    (default :func:`phyagentos.resources.skills_dir`). Cached per directory."""
    return dict(_load(str(directory if directory is not None else resources.skills_dir())))
