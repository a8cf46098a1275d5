"""The whole-graph check of ``phyagentos run``, with the idle runner or in a child of its forkserver.

:func:`phyagentos.app.graph_check.check_goal_graph` builds every node's behaviour tree and
solves IK for every pick and place pose: it needs the primitives and the motion stack
(MuJoCo, mink, toppra), about 1.5 s of imports. The runner's forkserver
(:mod:`phyagentos.runtime.worker`), which ``run`` starts before anything else, imports
exactly those once. :func:`check_goal_graph_forked` forks a short-lived child from it
that runs the same check and sends its result back over a pipe, so the ``run`` process
itself never imports the motion stack: the import is paid once per run (in the
forkserver), not twice, and not on the main process's path.

When ``run`` has prestarted a runner (it has, unless another run took it), the check
runs in this process instead and hands its runtime steps (trees, scenes, reachability,
:class:`~phyagentos.app.graph_check.RuntimeChecks`) to that idle runner as three jobs: the
runner has the runtime imported and is building the graph's targets anyway, so neither a
second process nor a second compile of the scene's meshes is paid, and this process still
imports no motion code (scenes come back as pickles it hands back unopened).

The check, its inputs and its errors are exactly those of ``check_goal_graph``. Where no
forkserver can be used, where this process has the motion stack imported already (nothing
left to save), or where a caller replaced ``check_goal_graph`` (a test or a library user
adapting the check; the child would run the original) and no idle runner is there, it runs
here. The choice depends only on those facts, never on which module imported what first.
"""

from __future__ import annotations

import logging
import sys
import traceback
from pathlib import Path
from typing import TYPE_CHECKING

from phyagentos import errors
from phyagentos.errors import GoalGraphError, PhyAgentOSError

if TYPE_CHECKING:
    from phyagentos.app.graph_check import GraphCheck

__all__ = ["check_goal_graph_forked"]

logger = logging.getLogger(__name__)

#: The check of a large graph solves a few IK problems per pick and place; a child that
#: has not answered in this long is killed and the check runs in this process (s).
CHECK_TIMEOUT_S = 300.0


def _check_here(path: Path, root: Path, target: str | None, dirs: tuple[str, str]) -> "GraphCheck":
    from phyagentos.app.graph_check import check_goal_graph  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415
    from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime  # noqa: PLC0415

    runtime = BuiltinSkillRuntime.from_dirs(*dirs)
    return check_goal_graph(path, Workspace.open(root), runtime, target=target)


#: Modules whose presence means this process could check in place at no import cost.
_RUNTIME_MODULES = ("mujoco", "phyagentos.motion", "phyagentos.primitives")


def _runtime_loaded_here() -> bool:
    return all(name in sys.modules for name in _RUNTIME_MODULES)


def _check_adapted() -> bool:
    """A caller replaced :func:`phyagentos.app.graph_check.check_goal_graph` (a forked
    child would import the original and ignore the replacement)."""
    module = sys.modules.get("phyagentos.app.graph_check")
    return module is not None and getattr(module.check_goal_graph, "__module__", None) != module.__name__


class _RunnerFailed(Exception):
    """The idle runner could not do its part of the check (died, timed out, raised)."""


class _RunnerChecks:
    """:class:`~phyagentos.app.graph_check.RuntimeChecks` done by an idle runner (job
    ``graph_checks``): one round trip per step (trees, scenes, reach)."""

    def __init__(self, runner, root: Path, timeout_s: float) -> None:
        self.runner, self.root, self.timeout_s = runner, root, timeout_s

    def _ask(self, stage: str, items: list) -> list:
        from phyagentos.runtime.worker import RunnerDied  # noqa: PLC0415

        try:
            kind, msg = self.runner.request("graph_checks", timeout=self.timeout_s, expect=("graph_checked",),
                                            root=str(self.root), stage=stage, items=items)
        except RunnerDied as exc:
            raise _RunnerFailed(str(exc)) from None
        if kind != "graph_checked" or msg.get("stage") != stage:
            raise _RunnerFailed(msg.get("message", f"unexpected reply {kind!r}"))
        return msg["results"]

    def build_trees(self, items):
        return self._ask("trees", items)

    def check_scenes(self, items):
        return self._ask("scenes", items)

    def check_reach(self, items):
        return self._ask("reach", items)


def _check_with_runner(path: Path, root: Path, target: str | None, dirs: tuple[str, str],
                       timeout_s: float) -> "GraphCheck | None":
    """The check in this process with its runtime steps done by the idle runner that
    ``run`` prestarted (and is warming the graph's targets): no second process, no second
    import of networkx, and the runner's meshes are decoded already. None when there is
    no idle runner for ``dirs`` or it failed (the caller then forks the check)."""
    from phyagentos.runtime.worker import borrow_runner, park_runner  # noqa: PLC0415

    runner = borrow_runner(*dirs)
    if runner is None:
        return None
    try:
        return _check_borrowed(runner, path, root, target, dirs, timeout_s)
    finally:
        park_runner(runner)  # for the supervisor's take_runner (closed if it died)


def _check_borrowed(runner, path: Path, root: Path, target: str | None, dirs: tuple[str, str],
                    timeout_s: float) -> "GraphCheck | None":
    from types import SimpleNamespace  # noqa: PLC0415

    from phyagentos.app.graph_check import check_goal_graph  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415
    from phyagentos.runtime.skills import SkillRegistry  # noqa: PLC0415

    try:
        return check_goal_graph(path, Workspace.open(root), SimpleNamespace(skills=SkillRegistry(dirs[0])),
                                target=target, checks=_RunnerChecks(runner, root, timeout_s))
    except _RunnerFailed as exc:
        logger.warning("graph check with the idle runner failed (%s); forking the check", exc)
        return None


def _child(conn, path: str, root: str, target: str | None, dirs: tuple[str, str]) -> None:
    """Entry point of the forked child: one ``(kind, payload)`` message, then exit."""
    try:
        result = _check_here(Path(path), Path(root), target, dirs)
        conn.send(("ok", result))
    except GoalGraphError as exc:
        conn.send(("located", (type(exc).__name__, exc.detail, exc.path, exc.line)))
    except PhyAgentOSError as exc:  # e.g. a malformed TARGETS.md: re-raised as itself in the parent
        if hasattr(exc, "detail"):  # path:line errors rebuild from their parts
            conn.send(("located", (type(exc).__name__, exc.detail, exc.path, exc.line)))
        else:
            conn.send(("error", exc))
    except BaseException as exc:  # noqa: BLE001 - reported, the parent checks in-process
        conn.send(("crash", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))
    finally:
        conn.close()


def check_goal_graph_forked(path: str | Path, workspace_root: str | Path, *, target: str | None = None,
                            fork: bool | None = None, timeout_s: float = CHECK_TIMEOUT_S) -> "GraphCheck":
    """:func:`phyagentos.app.graph_check.check_goal_graph` of ``path`` against the workspace
    at ``workspace_root`` with the shipped skills and trees, run in a child of the
    runner's forkserver (this process imports neither the primitives nor the motion
    stack).

    Args:
        fork: ``None`` (default): in this process when it has the motion stack imported
            already; else with the idle runner (the check itself, and any replacement of
            ``check_goal_graph`` a caller made, runs here and only its runtime steps go
            to the runner); else here if ``check_goal_graph`` was replaced; else in a
            forked child. ``True``: the idle runner, else a forked child. ``False``:
            in this process.

    Raises:
        GoalGraphError: the graph is invalid (the same message, file and line as the
            in-process check).
        PhyAgentOSError: what the check raises otherwise (e.g. a malformed TARGETS.md).
    """
    from phyagentos.resources import skill_dirs, tree_dirs  # noqa: PLC0415

    path, root = Path(path), Path(workspace_root)
    dirs = (skill_dirs(), tree_dirs())  # resolved here: the forkserver's environment may be older
    if fork is False or (fork is None and _runtime_loaded_here()):
        return _check_here(path, root, target, dirs)
    checked = _check_with_runner(path, root, target, dirs, timeout_s)
    if checked is not None:
        return checked
    if fork is None and _check_adapted():
        return _check_here(path, root, target, dirs)
    try:
        from phyagentos.runtime.worker import forkserver_context  # noqa: PLC0415

        ctx = forkserver_context()
        parent, child = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_child, name="phyagentos-graph-check", daemon=True,
                           args=(child, str(path), str(root), target, dirs))
        proc.start()
    except (OSError, ValueError, ImportError) as exc:  # no forkserver here: check in this process
        logger.info("graph check in this process (no forkserver: %s)", exc)
        return _check_here(path, root, target, dirs)
    child.close()
    try:
        if not parent.poll(timeout_s):
            raise TimeoutError(f"no answer within {timeout_s:.0f} s")
        kind, payload = parent.recv()
    except (OSError, EOFError, TimeoutError) as exc:
        logger.warning("graph check child failed (%s); checking in this process", exc)
        proc.kill()
        return _check_here(path, root, target, dirs)
    finally:
        parent.close()
        proc.join(timeout=5)
    if kind == "ok":
        return payload
    if kind == "located":
        name, detail, where, line = payload
        raise getattr(errors, name, GoalGraphError)(detail, path=where, line=line)
    if kind == "error":
        raise payload
    logger.warning("graph check child crashed; checking in this process:\n%s", payload)
    return _check_here(path, root, target, dirs)
