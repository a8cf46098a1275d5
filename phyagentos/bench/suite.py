"""Benchmark suites: which goal graphs run, over which seeded initial states.

A suite is a YAML file (``phyagentos/bench/suites/<name>.yaml``, or any path)::

    version: 1
    name: tabletop
    description: Franka tabletop manipulation under seeded randomised initial states.
    episodes: 13                 # default episodes per task (seeds 0 .. episodes-1)
    heldout_seed_offset: 10000   # held-out split: seeds offset .. offset+episodes-1
    perturbations:               # optional, see below
      rate: 0.25
      kinds: [heavy_object]
    safety:                      # optional: safety.yaml keys this suite's cell needs
      workspace_box: {min: [-1.0, -0.2, 1.6], max: [0.5, 1.0, 2.4]}
    tasks:
      - id: pick_and_place
        goal_graph: pick_and_place.yaml          # relative to phyagentos/data/goal_graphs/ or the suite file
        target: franka_tabletop                  # optional: override every node's target
        safety: {}                               # optional: this task's safety.yaml keys, over the suite's
        randomize:
          - {names: [cube], xy: [0.05, 0.05], yaw: 0.6}

``randomize`` moves scene items (objects, regions, obstacles) named together by one
offset drawn uniformly from ``[-xy[0], xy[0]] x [-xy[1], xy[1]]`` metres (world frame),
and turns objects by a yaw drawn from ``[-yaw, yaw]`` rad. Draws come from
``numpy.random.default_rng([suite_seed_tag, task_index, seed])``, so an episode's initial
state is a pure function of (suite, task, seed) and reproducible on any machine.

``random_world: {distractors: [0, 4]}`` (or ``true``) makes the target draw the declared
objects' shape, size, mass, friction, yaw and position and 0-4 distractors from a seed the
compiler writes into the scene's ``randomise`` block (:mod:`phyagentos.targets.world`); the
draw itself reaches only ``ground_truth.yaml``.

``seed_to_scene: KEY`` writes each episode's seed into its scene under ``KEY`` (LIBERO's
suites: ``init``, the index of one of the task's fixed initial states).

``safety`` overrides keys of the bench workspace's safety.yaml in the episodes (a
different cell, e.g. the kitchen's workspace box); a task's own ``safety`` overrides the
suite's for that task's episodes (tasks standing in different cells). The merged file is
validated as :class:`~phyagentos.protocol.SafetyConfig` and recorded with the episode
workspaces.

Perturbations (``kinds`` from :data:`phyagentos.bench.perturb.PERTURBATIONS`) are
switched on for an episode with probability ``rate``, drawn from the same episode RNG;
the draw is recorded in every session's ``evaluation`` block.
"""

from __future__ import annotations

import copy
import hashlib
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from phyagentos.errors import BenchError, TargetError, format_choices, format_location
from phyagentos.resources import goal_graphs_dir
from phyagentos.yamlsource import item_line, line_of, read_yaml, to_plain

__all__ = ["RandomizeRule", "TaskSpec", "PerturbationConfig", "Suite", "load_suite", "suite_dir", "available_suites",
           "episode_rng"]

logger = logging.getLogger(__name__)

_SUITE_KEYS = {"version", "name", "description", "episodes", "heldout_seed_offset", "perturbations", "safety", "tasks"}
_TASK_KEYS = {"id", "goal_graph", "target", "randomize", "description", "random_world", "seed_to_scene", "safety"}
_RULE_KEYS = {"names", "xy", "yaw"}
_PERTURB_KEYS = {"rate", "kinds"}


def suite_dir() -> Path:
    """Directory of the suites shipped with the package."""
    return Path(__file__).resolve().parent / "suites"


def available_suites() -> tuple[str, ...]:
    """Names of the shipped suites (file stems of :func:`suite_dir`)."""
    return tuple(sorted(p.stem for p in suite_dir().glob("*.yaml")))


@dataclass(frozen=True)
class RandomizeRule:
    """Move ``names`` together by one uniform xy offset (m) and turn objects by a yaw (rad)."""

    names: tuple[str, ...]
    xy: tuple[float, float] = (0.0, 0.0)
    yaw: float = 0.0


@dataclass(frozen=True)
class TaskSpec:
    """One task of a suite: a goal graph, an optional target override, randomisation rules."""

    id: str
    goal_graph: Path
    target: str | None = None
    randomize: tuple[RandomizeRule, ...] = ()
    description: str = ""
    #: ``None``, or ``{distractors: [min, max]}``: the episode's objects and distractors are
    #: drawn by the target from a seed (:mod:`phyagentos.targets.world`).
    random_world: Mapping[str, Any] | None = None
    #: ``None``, or a scene key the episode's seed is written to (LIBERO: ``init``, the
    #: seed is the index of one of the task's fixed initial states).
    seed_to_scene: str | None = None
    #: safety.yaml keys this task's episodes override on top of the suite's ``safety`` (a
    #: suite whose tasks stand in different cells, e.g. LIBERO-10's kitchen, living-room and
    #: study scenes, each with its own workspace box).
    safety: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class PerturbationConfig:
    """Perturbations switched on per episode with probability ``rate`` (0 disables)."""

    rate: float = 0.0
    kinds: tuple[str, ...] = ()


@dataclass(frozen=True)
class Suite:
    """A validated suite definition (see the module docstring)."""

    name: str
    path: Path
    description: str
    episodes: int
    heldout_seed_offset: int
    perturbations: PerturbationConfig
    tasks: tuple[TaskSpec, ...]
    safety: Mapping[str, Any] = field(default_factory=dict)
    raw: Mapping[str, Any] = field(default_factory=dict, compare=False, repr=False)

    @property
    def task_ids(self) -> tuple[str, ...]:
        return tuple(t.id for t in self.tasks)

    def task(self, task_id: str) -> TaskSpec:
        for t in self.tasks:
            if t.id == task_id:
                return t
        raise BenchError(f"suite {self.name!r} has no task {task_id!r}; tasks: {format_choices(self.task_ids)}")

    def seeds(self, *, episodes: int | None = None, split: str = "measurement") -> tuple[int, ...]:
        """Seeds of a split: ``0 .. n-1`` (measurement) or offset by ``heldout_seed_offset`` (heldout)."""
        n = self.episodes if episodes is None else episodes
        if n < 1:
            raise BenchError(f"episodes must be >= 1, got {n}")
        base = {"measurement": 0, "heldout": self.heldout_seed_offset}.get(split)
        if base is None:
            raise BenchError(f"unknown split {split!r}; valid splits: 'heldout', 'measurement'")
        return tuple(range(base, base + n))

    def tag(self) -> int:
        """Stable 32-bit integer naming this suite in RNG seeds (sha256 of its name)."""
        return int(hashlib.sha256(self.name.encode()).hexdigest()[:8], 16)

    def to_dict(self) -> dict[str, Any]:
        return copy.deepcopy(dict(self.raw))


def episode_rng(suite: Suite, task_index: int, seed: int) -> np.random.Generator:
    """The RNG of one episode: ``default_rng([suite tag, task index, seed])``."""
    return np.random.default_rng([suite.tag(), int(task_index), int(seed)])


def _problem(path: Path, msg: str, line: int | None = None) -> BenchError:
    """A suite error naming ``path:line`` (the 1-based line of the offending key or item,
    where the YAML has one)."""
    return BenchError(f"{format_location(path, line)}: {msg}")


def _number(value: Any) -> bool:
    """A finite int or float, not a bool (YAML's ``true`` is no number of metres)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _pair(value: Any, path: Path, where: str, line: int | None) -> tuple[float, float]:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2 \
            or not all(_number(v) for v in value):
        raise _problem(path, f"{where} must be two finite numbers [x, y] in metres, got {value!r}", line)
    a, b = (float(v) for v in value)
    if a < 0 or b < 0:
        raise _problem(path, f"{where} must be >= 0, got {value!r}", line)
    return a, b


def _resolve_graph(value: Any, suite_path: Path, line: int | None) -> Path:
    if not isinstance(value, str) or not value:
        raise _problem(suite_path, f"goal_graph must be a file name, got {value!r}", line)
    for candidate in (suite_path.parent / value, goal_graphs_dir() / value, Path(value)):
        if candidate.is_file():
            return candidate.resolve()
    raise _problem(suite_path, f"goal graph {value!r} not found next to the suite or in {goal_graphs_dir()}", line)


def _first_line(mapping: Any, keys: set) -> int | None:
    """The earliest line among ``keys`` of ``mapping`` (the first of several unknown keys)."""
    lines = [line for line in (line_of(mapping, k) for k in keys) if line is not None]
    return min(lines) if lines else line_of(mapping)


def load_suite(name_or_path: str | Path) -> Suite:
    """Load a suite by shipped name (``tabletop``) or by path.

    Raises:
        BenchError: unknown suite (valid names listed), unreadable YAML, unknown keys,
            missing tasks or goal graphs, or malformed randomisation/perturbation blocks.
    """
    from .perturb import PERTURBATIONS  # noqa: PLC0415 - perturb imports suite types

    p = Path(name_or_path)
    if not p.suffix:
        p = suite_dir() / f"{name_or_path}.yaml"
        if not p.is_file():
            from phyagentos.targets.libero.catalog import STANDARD_SUITES, SUITES  # noqa: PLC0415 - names only
            from phyagentos.targets.libero.catalog import available_suites as libero_suites  # noqa: PLC0415

            try:
                pro = [s for s in libero_suites() if s not in SUITES]
            except TargetError:  # LIBERO not installed
                pro = []
            raise BenchError(f"unknown suite {str(name_or_path)!r}; shipped suites: {format_choices(available_suites())}"
                             f", LIBERO's suites: {format_choices(STANDARD_SUITES)}, 'libero_90'"
                             + (f", LIBERO-PRO's and others installed: {format_choices(pro)}" if pro else "")
                             + " (or give a path to a suite YAML)")
    if not p.is_file():
        raise BenchError(f"suite file {p} does not exist")
    # Line-carrying containers (yamlsource.SourceMap/SourceList): every problem below names
    # the file and the line of the offending key or item; a YAML error already carries both.
    raw = read_yaml(p, error=BenchError, plain=False)
    if not isinstance(raw, dict):
        raise _problem(p, "top level must be a mapping", line_of(raw) or 1)
    unknown = set(raw) - _SUITE_KEYS
    if unknown:
        raise _problem(p, f"unknown key(s) {format_choices(unknown)}; valid keys: {format_choices(_SUITE_KEYS)}",
                       _first_line(raw, unknown))
    if raw.get("version") != 1 or isinstance(raw.get("version"), bool):
        raise _problem(p, f"unsupported version {raw.get('version')!r}; valid versions: 1", line_of(raw, "version"))
    name = raw.get("name")
    if not isinstance(name, str) or not name.replace("_", "").isalnum():
        raise _problem(p, f"name must be an identifier (letters, digits, _), got {name!r}", line_of(raw, "name"))
    episodes = raw.get("episodes", 10)
    if not isinstance(episodes, int) or isinstance(episodes, bool) or episodes < 1:
        raise _problem(p, f"episodes must be an integer >= 1, got {episodes!r}", line_of(raw, "episodes"))
    offset = raw.get("heldout_seed_offset", 10_000)
    if not isinstance(offset, int) or isinstance(offset, bool) or offset < 1:
        raise _problem(p, f"heldout_seed_offset must be an integer >= 1, got {offset!r}",
                       line_of(raw, "heldout_seed_offset"))

    pert_raw = raw.get("perturbations") or {}
    if not isinstance(pert_raw, dict) or set(pert_raw) - _PERTURB_KEYS:
        where = _first_line(pert_raw, set(pert_raw) - _PERTURB_KEYS) if isinstance(pert_raw, dict) else None
        raise _problem(p, f"perturbations must be a mapping with keys {format_choices(_PERTURB_KEYS)}",
                       where or line_of(raw, "perturbations"))
    rate = pert_raw.get("rate", 0.0)
    if not _number(rate) or not 0.0 <= rate <= 1.0:
        raise _problem(p, f"perturbations.rate must be a number in [0, 1], got {rate!r}", line_of(pert_raw, "rate"))
    kinds_raw = pert_raw.get("kinds") or ()
    if isinstance(kinds_raw, (str, dict)) or not isinstance(kinds_raw, (list, tuple)):
        raise _problem(p, f"perturbations.kinds must be a list of perturbations, got {kinds_raw!r}",
                       line_of(pert_raw, "kinds"))
    kinds = tuple(kinds_raw)
    for index, k in enumerate(kinds):
        if not isinstance(k, str) or k not in PERTURBATIONS:
            raise _problem(p, f"unknown perturbation {k!r}; valid perturbations: {format_choices(PERTURBATIONS)}",
                           item_line(kinds_raw, index) or line_of(pert_raw, "kinds"))
    if rate > 0 and not kinds:
        raise _problem(p, "perturbations.rate > 0 needs at least one kind", line_of(pert_raw, "rate"))

    tasks_raw = raw.get("tasks")
    if not isinstance(tasks_raw, list) or not tasks_raw:
        raise _problem(p, "tasks must be a non-empty list", line_of(raw, "tasks"))
    tasks: list[TaskSpec] = []
    for i, t in enumerate(tasks_raw):
        if not isinstance(t, dict):
            raise _problem(p, f"tasks[{i}] must be a mapping", item_line(tasks_raw, i))
        unknown = set(t) - _TASK_KEYS
        if unknown:
            raise _problem(p, f"tasks[{i}]: unknown key(s) {format_choices(unknown)}; valid keys: {format_choices(_TASK_KEYS)}",
                           _first_line(t, unknown))
        tid = t.get("id")
        if not isinstance(tid, str) or not tid.replace("_", "").isalnum() or not tid[:1].isalpha():
            raise _problem(p, f"tasks[{i}].id must be an identifier starting with a letter, got {tid!r}",
                           line_of(t, "id"))
        if tid in {x.id for x in tasks}:
            raise _problem(p, f"duplicate task id {tid!r}", line_of(t, "id"))
        rules = []
        rules_raw = t.get("randomize") or ()
        if not isinstance(rules_raw, (list, tuple)):
            raise _problem(p, f"tasks[{i}].randomize must be a list of rules, got {rules_raw!r}",
                           line_of(t, "randomize"))
        for j, r in enumerate(rules_raw):
            where = f"tasks[{i}].randomize[{j}]"
            if not isinstance(r, dict) or set(r) - _RULE_KEYS or "names" not in r:
                raise _problem(p, f"{where} must be a mapping with 'names' and optional 'xy', 'yaw'",
                               item_line(rules_raw, j))
            names = r["names"]
            if isinstance(names, (str, dict)) or not isinstance(names, (list, tuple)) or not names:
                raise _problem(p, f"{where}.names must be a non-empty list of scene names", line_of(r, "names"))
            yaw = r.get("yaw", 0.0)
            if not _number(yaw) or yaw < 0:
                raise _problem(p, f"{where}.yaw must be a finite number >= 0 rad, got {yaw!r}", line_of(r, "yaw"))
            rules.append(RandomizeRule(names=tuple(str(n) for n in names),
                                       xy=_pair(r.get("xy", (0.0, 0.0)), p, f"{where}.xy", line_of(r, "xy")),
                                       yaw=float(yaw)))
        target = t.get("target")
        if target is not None and not isinstance(target, str):
            raise _problem(p, f"tasks[{i}].target must be a target name, got {target!r}", line_of(t, "target"))
        rw = t.get("random_world")
        if rw is True:
            rw = {}
        if rw is not None and rw is not False and (not isinstance(rw, dict) or set(rw) - {"distractors"}):
            raise _problem(p, f"tasks[{i}].random_world must be true or a mapping with 'distractors: [min, max]', got {rw!r}",
                           line_of(t, "random_world"))
        seed_key = t.get("seed_to_scene")
        if seed_key is not None and (not isinstance(seed_key, str) or not seed_key.isidentifier()):
            raise _problem(p, f"tasks[{i}].seed_to_scene must be a scene key (an identifier), got {seed_key!r}",
                           line_of(t, "seed_to_scene"))
        task_safety = t.get("safety") or {}
        if not isinstance(task_safety, dict):
            raise _problem(p, f"tasks[{i}].safety must be a mapping of safety.yaml keys to override, "
                              f"got {type(task_safety).__name__}", line_of(t, "safety"))
        tasks.append(TaskSpec(id=tid, goal_graph=_resolve_graph(t.get("goal_graph"), p, line_of(t, "goal_graph")),
                              target=target, randomize=tuple(rules), description=str(t.get("description", "")),
                              random_world=to_plain(rw) if isinstance(rw, dict) else None, seed_to_scene=seed_key,
                              safety=to_plain(task_safety)))
    safety = raw.get("safety") or {}
    if not isinstance(safety, dict):
        raise _problem(p, f"safety must be a mapping of safety.yaml keys to override, got {type(safety).__name__}",
                       line_of(raw, "safety"))
    return Suite(name=name, path=p.resolve(), description=str(raw.get("description", "")), episodes=episodes,
                 heldout_seed_offset=offset, perturbations=PerturbationConfig(rate=float(rate), kinds=kinds),
                 tasks=tuple(tasks), safety=to_plain(safety), raw=to_plain(raw))
