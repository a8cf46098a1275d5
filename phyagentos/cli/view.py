"""``phyagentos view`` and the ``--record`` option of ``run`` and ``bench``.

    phyagentos view WORKSPACE [--host H] [--port N]
    phyagentos view WORKSPACE --export-rrd SESSION_ID [--rrd-out PATH]
    phyagentos run GOAL_GRAPH --workspace DIR --record [all|failures] [--record-camera C] [--record-fps F]
    phyagentos bench SUITE --workspace DIR --record failures

Registered in :mod:`phyagentos.cli` by :func:`add_view_commands` (parser) and
:func:`with_view` (handlers).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:  # rich is imported where it prints (a quiet command never loads it)
    from rich.console import Console


__all__ = ["add_view_commands", "with_view"]

Handler = Callable[[argparse.Namespace, "Console", "Console"], int]


def _add_record(parser: argparse.ArgumentParser, *, default_mode: str) -> None:
    parser.add_argument("--record", nargs="?", const=default_mode, choices=("all", "failures"),
                        help=f"write evidence/<session>/video.mp4 (+ frames.npz with qpos per frame); 'failures' keeps "
                             f"only sessions whose verdict is not success (bare --record: {default_mode})")
    parser.add_argument("--record-camera", default="",
                        help="camera to record (default: the target's own view: overview on the built tabletops, "
                             "agentview on LIBERO)")
    parser.add_argument("--record-fps", type=float, default=10.0,
                        help="frames per second of simulated time (default 10)")


def add_view_commands(sub: argparse._SubParsersAction) -> None:
    """Add ``view``, and ``--record`` to the ``run`` and ``bench`` parsers already in ``sub``."""
    view = sub.add_parser("view", help="serve a live web view of a workspace (runs, DAGs, trees, sessions, 3D, memory)")
    view.add_argument("workspace", type=Path)
    view.add_argument("--host", default="127.0.0.1",
                      help="address to bind (default 127.0.0.1); any other needs the printed access token to signal")
    view.add_argument("--port", type=int, default=8787, help="port (default 8787; 0: any free port)")
    view.add_argument("--export-rrd", metavar="SESSION_ID",
                      help="write the session's signals, events, tree changes and images as a rerun recording "
                           "(evidence/<session>/recording.rrd; needs rerun-sdk) and exit instead of serving")
    view.add_argument("--rrd-out", type=Path, help="with --export-rrd: the file to write instead")
    _add_record(sub.choices["run"], default_mode="all")
    _add_record(sub.choices["bench"], default_mode="failures")


def _no_workspace_hint(path: Path) -> str:
    """What to type when ``path`` holds no workspace yet (a plain CLI hint, no Python API)."""
    state = "does not exist" if not path.exists() else ("is empty" if path.is_dir() and not any(path.iterdir())
                                                        else "holds no SESSIONS.md")
    return (f"{path} is not a PhyAgentOS workspace yet ({state}).\n"
            f"A workspace is created by the first run submitted to it, e.g.:\n"
            f"    phyagentos run hold --workspace {path}   (hold: a shipped example; phyagentos examples lists them)\n"
            f"then, in another terminal (or after it):\n"
            f"    phyagentos view {path}")


def _cmd_view(args, out: Console, err: Console) -> int:
    from phyagentos.view import serve  # noqa: PLC0415 - starlette/uvicorn only for this command

    if not (Path(args.workspace) / "SESSIONS.md").is_file():
        err.print(_no_workspace_hint(Path(args.workspace)), markup=False, highlight=False, soft_wrap=True)
        return 2

    def announce(url: str, token: str) -> None:
        out.print(f"phyagentos view of {args.workspace}: [bold]{url}[/bold]", soft_wrap=True)
        out.print(f"access token (signals): {token}", soft_wrap=True)
        out.file.flush()

    if args.export_rrd:
        return _export_rrd(args, out, err)
    serve(args.workspace, host=args.host, port=args.port, announce=announce)
    return 0


def _export_rrd(args, out: Console, err: Console) -> int:
    from phyagentos.errors import PhyAgentOSError  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415
    from phyagentos.view.rerun_export import export_rrd  # noqa: PLC0415
    from phyagentos.view.scene3d import SceneRenderer  # noqa: PLC0415

    try:
        renderer = SceneRenderer(Workspace.open(args.workspace))
        try:
            layout = renderer.joint_layout(args.export_rrd)
        except PhyAgentOSError:
            layout = None  # joints labelled q1..q7
        finally:
            renderer.close()
        path = export_rrd(args.workspace, args.export_rrd, out=args.rrd_out, layout=layout)
    except PhyAgentOSError as exc:
        err.print(f"error: {exc}", markup=False, highlight=False, soft_wrap=True)
        return 1
    out.print(f"wrote {path}  (open it with: rerun {path})", markup=False, highlight=False, soft_wrap=True)
    return 0


def _recording(handler: Handler, *, workspaces: Callable[[argparse.Namespace, set], list[Path]]) -> Handler:
    """``handler`` with PHYAGENTOS_RECORD set for its runner processes, and the recordings of
    successful sessions pruned afterwards under ``--record failures``."""

    def run(args, out: Console, err: Console) -> int:
        if not getattr(args, "record", None):
            # Imported only when recording: ``run`` starts its runner first thing, and the
            # recording module (the protocol layer, numpy) would delay that by ~0.2-0.5 s.
            return handler(args, out, err)
        from phyagentos.runtime.recording import ENV_VAR, RecordingConfig, prune_recordings  # noqa: PLC0415

        config = RecordingConfig(mode=args.record, camera=args.record_camera, fps=args.record_fps)
        before = set(_bench_dirs(args.workspace))
        previous = os.environ.get(ENV_VAR)
        os.environ[ENV_VAR] = config.to_env()  # before any runner process or forkserver starts
        try:
            code = handler(args, out, err)
        finally:
            if previous is None:
                os.environ.pop(ENV_VAR, None)
            else:
                os.environ[ENV_VAR] = previous
        if config.mode == "failures":
            from phyagentos.protocol import Workspace  # noqa: PLC0415

            pruned = sum(prune_recordings(Workspace.open(d)) for d in workspaces(args, before)
                         if (d / "SESSIONS.md").is_file())
            err.print(f"[dim]--record failures: dropped the recordings of {pruned} successful session(s)[/dim]")
        return code

    return run


def _bench_dirs(workspace: Path) -> list[Path]:
    return sorted(p for p in (Path(workspace) / "bench").glob("*") if p.is_dir())


def _bench_episode_workspaces(args, before: set) -> list[Path]:
    return [ep for d in _bench_dirs(args.workspace) if d not in before for ep in sorted((d / "episodes").glob("*"))]


def with_view(handlers: dict[str, Handler]) -> dict[str, Handler]:
    """``handlers`` plus ``view``, with ``run`` and ``bench`` honouring ``--record``."""
    return {**handlers, "view": _cmd_view,
            "run": _recording(handlers["run"], workspaces=lambda args, before: [Path(args.workspace)]),
            "bench": _recording(handlers["bench"], workspaces=_bench_episode_workspaces)}
