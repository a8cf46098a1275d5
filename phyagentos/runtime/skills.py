"""Skill manifests: ``skills/<name>.yaml`` maps a skill name to its tree and needs.

::

    version: 1
    name: pick
    description: Grasp an object from the table and lift it.
    runtime: builtin                 # SkillRuntime that executes it (SKILLRUNTIME.md)
    tree: pick                       # trees/pick.yaml
    acquires: object                 # the gripper holds params[object] afterwards (releases: likewise)
    requires:
      capabilities: [arm_7dof, parallel_gripper, grasp]   # must be in the target's capabilities
      observations: [joint_positions, object_poses]       # must be in the target's observations
    params:
      object: {required: true, description: name of the object to pick}

Preflight compares ``requires`` with the target's entry in TARGETS.md; the
BuiltinSkillRuntime builds ``tree`` with the session's parameters.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from phyagentos.errors import SkillError, format_choices
from phyagentos.yamlsource import SourceMap, load_yaml

from .param_decls import check_param_decls

__all__ = ["SkillManifest", "SkillRegistry", "search_dirs"]

logger = logging.getLogger(__name__)


def search_dirs(directory: str | Path | Sequence[str | Path]) -> tuple[Path, ...]:
    """Folders of a search path given as one path, an ``os.pathsep``-joined string or a sequence."""
    if isinstance(directory, (str, Path)):
        parts = str(directory).split(os.pathsep) if isinstance(directory, str) else [directory]
    else:
        parts = list(directory)
    return tuple(Path(p) for p in parts if str(p))


_dirs = search_dirs

_KEYS = {"version", "name", "description", "runtime", "tree", "requires", "params", "policy", "acquires", "releases"}
_REQUIRES = {"capabilities", "observations"}


@dataclass(frozen=True)
class SkillManifest:
    """A parsed skill manifest (see module docstring for the file format)."""

    name: str
    description: str
    runtime: str
    tree: str | None
    capabilities: tuple[str, ...]
    observations: tuple[str, ...]
    params: Mapping[str, Mapping[str, Any]]
    path: Path
    policy: Mapping[str, Any] | None = None  # runtime: policy (see phyagentos.runtime.policy_runtime)
    acquires: str | None = None  # parameter naming the object the gripper holds afterwards
    releases: str | None = None  # parameter naming the object the gripper lets go of

    def check_params(self, params: Mapping[str, Any]) -> list[str]:
        """Problems with session ``params`` for this skill (empty when fine)."""
        problems = [f"missing required parameter {k!r}" for k, d in self.params.items()
                    if d.get("required") and k not in params]
        problems += [f"unknown parameter {k!r} (declared: {format_choices(self.params) or 'none'})"
                     for k in params if k not in self.params]
        return problems


class SkillRegistry:
    """All manifests along a search path of ``skills/`` folders, parsed eagerly so errors
    surface early.

    Args:
        directory: one folder, several joined with ``os.pathsep`` or a sequence, first
            wins (:func:`phyagentos.resources.skill_dirs`). A name found again in a later
            folder is recorded in :attr:`shadowed` and logged as a warning.

    Raises:
        SkillError: a malformed manifest (file and line), or a name used twice in one folder.
    """

    def __init__(self, directory: str | Path | Sequence[str | Path]):
        self.directories = _dirs(directory)
        self._skills: dict[str, SkillManifest] = {}
        #: (name, path that wins, path shadowed by it)
        self.shadowed: list[tuple[str, Path, Path]] = []
        for folder in self.directories:
            here: dict[str, Path] = {}
            for path in sorted(folder.glob("*.yaml")):
                manifest = _parse(path)
                if manifest.name in here:
                    raise SkillError(f"duplicate skill name {manifest.name!r} (also in {here[manifest.name]})", path=path)
                here[manifest.name] = path
                if manifest.name in self._skills:
                    winner = self._skills[manifest.name].path
                    self.shadowed.append((manifest.name, winner, path))
                    logger.warning("skill %r in %s is shadowed by %s, which comes first in the search path",
                                   manifest.name, path, winner)
                    continue
                self._skills[manifest.name] = manifest

    @property
    def directory(self) -> str:
        """The search path as one ``os.pathsep``-joined string (what the runner process takes)."""
        return os.pathsep.join(str(d) for d in self.directories)

    def manifests(self) -> list[SkillManifest]:
        """Every skill that wins its name, sorted by name."""
        return [self._skills[n] for n in sorted(self._skills)]

    def names(self) -> list[str]:
        return sorted(self._skills)

    def get(self, name: str) -> SkillManifest:
        """The manifest of skill ``name``.

        Raises:
            SkillError: unknown skill; the message lists the valid ones.
        """
        try:
            return self._skills[name]
        except KeyError:
            raise SkillError(f"unknown skill {name!r}; valid skills: {format_choices(self._skills)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._skills


def _parse(path: Path) -> SkillManifest:
    data = load_yaml(path.read_text(encoding="utf-8"), path=path, error=SkillError)
    if not isinstance(data, SourceMap):
        raise SkillError("a skill manifest must be a mapping", path=path, line=1)
    for key in data:
        if key not in _KEYS:
            raise SkillError(f"unknown key {key!r}; valid keys: {format_choices(_KEYS)}", path=path, line=data.key_line(key))
    runtime = str(data.get("runtime", "builtin"))
    # A builtin skill is a tree; a policy skill is a policy declaration instead.
    for key in ("name", "tree") if runtime == "builtin" else ("name",):
        if not isinstance(data.get(key), str):
            raise SkillError(f"{key!r} must be a string", path=path, line=data.key_line(key))
    if runtime == "policy" and not isinstance(data.get("policy"), dict):
        raise SkillError("a skill with 'runtime: policy' needs a 'policy' mapping", path=path, line=data.key_line("runtime"))
    if data.get("version") != 1:
        raise SkillError(f"unsupported version {data.get('version')!r}; supported: 1", path=path, line=data.key_line("version"))
    requires = data.get("requires") or {}
    if not isinstance(requires, dict):
        raise SkillError("'requires' must be a mapping", path=path, line=data.key_line("requires"))
    for key in requires:
        if key not in _REQUIRES:
            raise SkillError(f"unknown requirement {key!r}; valid: {format_choices(_REQUIRES)}", path=path, line=requires.key_line(key))
    params = check_param_decls(data.get("params"), path=path, line=data.key_line("params"))
    if not isinstance(data.get("description", ""), str):
        raise SkillError("'description' must be one string", path=path, line=data.key_line("description"))
    for key in ("acquires", "releases"):
        value = data.get(key)
        if value is not None and (not isinstance(value, str) or value not in params):
            raise SkillError(f"{key!r} must name one of the skill's parameters ({format_choices(params) or 'none'}), "
                             f"got {value!r}", path=path, line=data.key_line(key))
    return SkillManifest(
        name=data["name"],
        description=str(data.get("description", "")),
        runtime=runtime,
        tree=data.get("tree"),
        capabilities=tuple(requires.get("capabilities") or ()),
        observations=tuple(requires.get("observations") or ()),
        params=params,
        path=path,
        policy=data.get("policy"),
        acquires=data.get("acquires"),
        releases=data.get("releases"),
    )
