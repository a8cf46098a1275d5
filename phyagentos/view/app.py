"""The ``phyagentos view`` web application (Starlette) and its server (uvicorn).

Routes (all read-only except ``POST /api/signal``):

==============================  ==========================================================
``/``                           signals in force, signal buttons, active sessions, runs
``/run/{run}``                  the run's goal DAG (SVG) with node and session states
``/session/{id}``               live behaviour tree, 3D scene with a timeline, transitions,
                                attempts, verdict, diagnosis, revision, events, perception,
                                evidence images and the recording
``/memory``                     LESSONS.md, KNOWLEDGE.md, SKILL.md with provenance links
``/compare?a=ID&b=ID``          two sessions side by side (e.g. a failed attempt and its replan child)
                                with their timelines under one cursor
``/fragment/...``               the panels of those pages, re-fetched on every change
``/events[?session=ID&f=URL…]`` server-sent events: ``change`` with the JSON list of the page's
                                fragments (``f``) whose inputs changed (changes.py; ``null``: all),
                                on inotify wake-ups of :class:`~phyagentos.protocol.WorkspaceWatcher`,
                                coalesced to at most 10 per second
``/api/tree/{id}``              ``tree.json`` as published by the runner
``/api/frames/{id}``            the recorded instants of a session (simulated time per frame)
``/api/signals/{id}``           the session's signals on one simulated-time axis (signals.py)
``/api/scene/{id}.png``         the scene at ``frame=N`` (or the current checkpoint) from a free
                                camera (``az``, ``el``, ``dist`` in degrees and metres)
``/files/{path}``               a file inside the workspace (never outside it; see security.py)
``POST /api/signal``            ``{kind, session_id?, reason?}`` through ``Workspace.send_signal``,
                                exactly as ``phyagentos signal``; needs the access token
==============================  ==========================================================
"""

from __future__ import annotations

import asyncio
import contextlib
import getpass
import json
import logging
import math
import re
import socket
from pathlib import Path

from phyagentos.errors import PhyAgentOSError, ViewError
from phyagentos.extras import missing_extra
from phyagentos.protocol import DOCUMENTS, SESSION_ID_PATTERN, Workspace, WorkspaceWatcher
from phyagentos.untrusted import NotConfined, NotRegular, confined, loads_json

from . import data, pages
from .changes import Tracker
from .evidence import frames_of
from .graph_svg import to_svg
from .scene3d import SceneRenderer
from .security import MAX_BODY_BYTES, TOKEN_HEADER, AccessPolicy, BodyLimit, evidence_dir, safe_path
from .signals import session_signals

try:  # the `view` extra
    import uvicorn
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.requests import Request
    from starlette.responses import (
        FileResponse,
        HTMLResponse,
        JSONResponse,
        PlainTextResponse,
        Response,
        StreamingResponse,
    )
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles
except ImportError as exc:
    raise missing_extra(exc, extra="view") from exc

__all__ = ["create_app", "serve", "bind"]

logger = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).with_name("static")
_ID = re.compile(f"^{SESSION_ID_PATTERN}$")
#: Farthest free-camera distance of ``/api/scene`` (m).
MAX_CAMERA_DISTANCE_M = 100.0
#: Server-sent events are coalesced to at most this rate (Hz).
MAX_EVENT_RATE_HZ = 10.0
_WATCHED_DIRS = ("sessions", "sessions/.index", "runs", "runs/.active")


class _HostGuard:
    """ASGI middleware: on loopback, refuse requests whose Host header names another host."""

    def __init__(self, app, *, policy: AccessPolicy) -> None:
        self.app = app
        self.policy = policy

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] == "http":
            host = dict(scope.get("headers") or []).get(b"host", b"").decode("latin-1")
            if not self.policy.host_allowed(host):
                await PlainTextResponse("refused: Host header is not a loopback name", status_code=421)(scope, receive, send)
                return
        await self.app(scope, receive, send)


def _check_id(value: str, what: str) -> str:
    if not _ID.match(value):
        raise ViewError(f"invalid {what} {value!r}")
    return value


def create_app(workspace: str | Path, *, policy: AccessPolicy | None = None) -> Starlette:
    """The view of ``workspace`` (must exist: it holds SESSIONS.md).

    Raises:
        ProtocolError: ``workspace`` is not a workspace.
    """
    ws = Workspace.open(workspace)
    policy = policy or AccessPolicy()
    renderer = SceneRenderer(ws)
    runs_cache = data.RunsCache()

    def shell(title: str, body: str, scope: str = "") -> HTMLResponse:
        return HTMLResponse(pages.page(title, body, token=policy.token_in_page(), scope=scope))

    def frag(url: str, cls: str = "") -> str:
        return f'<div class="panel {cls}" data-fragment="{url}"><p class="muted">loading…</p></div>'

    # -- pages ---------------------------------------------------------------
    def index(request: Request) -> Response:
        try:
            page = max(1, int(request.query_params.get("page", "1")))
        except ValueError:
            page = 1
        body = (f'<h1>{pages._E(str(ws.root))}</h1>' + pages.signal_buttons()
                + frag("/fragment/overview") + "<h2>runs</h2>" + frag(f"/fragment/runs?page={page}"))
        return shell("workspace", body)

    def run_page(request: Request) -> Response:
        run_id = _check_id(request.path_params["run_id"], "run id")
        body = f"<h1>run {pages._E(run_id)}</h1>" + pages.signal_buttons() + frag(f"/fragment/run/{run_id}")
        return shell(f"run {run_id}", body)

    def session_page(request: Request) -> Response:
        sid = _check_id(request.path_params["session_id"], "session id")
        body = (f"<h1>session {pages._E(sid)}</h1>" + pages.signal_buttons(session_id=sid)
                + '<div class="cols"><section><h2>behaviour tree</h2>' + frag(f"/fragment/tree/{sid}", "tree-panel")
                + f'</section><section><h2>robot (3D)</h2><div class="scene3d" data-session="{pages._E(sid)}">'
                  '<img class="scene" alt="scene" draggable="false"><div class="scrub">'
                  '<input type="range" class="frame" min="0" max="0" value="0" disabled>'
                  '<span class="frame-info small"></span></div>'
                  '<p class="small muted">drag to orbit, wheel to zoom</p>'
                  '<p class="small legend"><span class="gt-label">ground truth</span> the rendered robot and '
                  'objects are the simulator\'s state · <label><input type="checkbox" class="overlays"> '
                  '<span class="ov-label">overlays: the robot\'s own data</span></label> '
                  '<span style="color:#1a59ff">perceived objects (spheres) and point cloud (dots)</span>, '
                  '<span style="color:#1acc33">grasp</span> and <span style="color:#ff8c00">place</span> targets, '
                  '<span style="color:#00b3b3">planned path</span>, <span style="color:#e61a99">executed tool '
                  'path</span>, <span style="color:#c8a800">camera frustums</span>'
                  '<span class="overlay-info muted"></span></p></div></section></div>'
                + pages.timeline_section(sid)
                + frag(f"/fragment/session/{sid}"))
        return shell(f"session {sid}", body, scope=sid)

    def compare_page(request: Request) -> Response:
        a = _check_id(request.query_params.get("a", ""), "session id (a)")
        b = _check_id(request.query_params.get("b", ""), "session id (b)")
        cols = "".join(f'<div class="compare-col"><h2>session <a href="/session/{pages._E(s)}">{pages._E(s)}</a></h2>'
                       + pages.timeline_section(s) + frag(f"/fragment/session/{s}") + "</div>" for s in (a, b))
        body = ("<h1>compare two sessions</h1><p class='small muted'>one cursor for both: click or drag on any plot "
                "(simulated time of each session)</p>" + f'<div class="compare">{cols}</div>')
        return shell(f"compare {a} / {b}", body)

    def memory_page(request: Request) -> Response:
        return shell("memory", "<h1>memory</h1>" + frag("/fragment/memory"))

    # -- fragments -----------------------------------------------------------
    def f_overview(request: Request) -> Response:
        return HTMLResponse(pages.overview_fragment(data.panel(lambda: data.overview(ws))))

    def f_runs(request: Request) -> Response:
        try:
            page = int(request.query_params.get("page", "1"))
        except ValueError:
            page = 1
        return HTMLResponse(pages.runs_fragment(data.panel(lambda: data.runs_page(ws, page, cache=runs_cache))))

    def f_run(request: Request) -> Response:
        run_id = _check_id(request.path_params["run_id"], "run id")
        graph = data.panel(lambda: data.run_graph(ws, run_id))
        svg = data.panel(lambda: to_svg(graph.data)) if graph.data else data.Panel()
        return HTMLResponse(pages.run_fragment(graph, svg))

    def f_session(request: Request) -> Response:
        sid = _check_id(request.path_params["session_id"], "session id")
        return HTMLResponse(pages.session_fragment(data.panel(lambda: data.session_detail(ws, sid))))

    def f_tree(request: Request) -> Response:
        sid = _check_id(request.path_params["session_id"], "session id")
        return HTMLResponse(pages.tree_fragment(data.panel(lambda: data.tree_status(ws, sid))))

    def f_memory(request: Request) -> Response:
        return HTMLResponse(pages.memory_fragment(data.memory(ws)))

    # -- JSON and images -----------------------------------------------------
    def api_tree(request: Request) -> Response:
        sid = _check_id(request.path_params["session_id"], "session id")
        try:
            tree = data.tree_status(ws, sid)
        except (ViewError, NotConfined) as exc:
            return JSONResponse({"error": str(exc)}, status_code=403)
        except (NotRegular, ValueError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=422)
        except OSError as exc:
            return JSONResponse({"error": str(exc)}, status_code=500)
        return JSONResponse(tree or {})

    def api_frames(request: Request) -> Response:
        sid = _check_id(request.path_params["session_id"], "session id")
        try:
            frames = frames_of(evidence_dir(ws.root, sid), root=ws.root)
        except (OSError, ValueError) as exc:
            return JSONResponse({"error": str(exc)}, status_code=403 if isinstance(exc, NotConfined) else 422)
        if frames is None:
            return JSONResponse({"count": 0, "t": []})
        return JSONResponse({"count": len(frames["t"]), "t": [round(x, 3) for x in frames["t"]],
                             "camera": frames["camera"], "fps": frames["fps"]})

    def api_signals(request: Request) -> Response:
        sid = _check_id(request.path_params["session_id"], "session id")
        try:
            rec = ws.load_session(sid).model_dump(mode="json")
            try:
                layout = renderer.joint_layout(sid)
            except (PhyAgentOSError, ValueError, TimeoutError):
                layout = None  # plots fall back to q1..q7, no recorded opening
            return JSONResponse(session_signals(ws.root, rec, layout=layout))
        except PhyAgentOSError as exc:
            return JSONResponse({"error": str(exc)}, status_code=404)

    def api_scene(request: Request) -> Response:
        sid = _check_id(request.path_params["session_id"], "session id")
        q = request.query_params
        try:
            frame = int(q["frame"]) if q.get("frame") not in (None, "", "live") else None
            az, el, dist = float(q.get("az", 140)), float(q.get("el", -25)), float(q.get("dist", 1.9))
            if not all(math.isfinite(v) for v in (az, el, dist)) or not 0 < dist <= MAX_CAMERA_DISTANCE_M:
                raise ValueError(f"az and el must be finite degrees, dist finite metres in (0, {MAX_CAMERA_DISTANCE_M}]")
            png, info = renderer.render(sid, frame=frame, azimuth=az, elevation=el, distance=dist,
                                        overlays=q.get("overlays") == "1")
        except (PhyAgentOSError, ValueError, OSError) as exc:
            return PlainTextResponse(str(exc), status_code=404)
        return Response(png, media_type="image/png",
                        headers={"X-Scene-Source": info["source"], "X-Scene-Time": f"{info['t']:.3f}",
                                 "X-Scene-Overlays": str(info.get("overlays", 0)),
                                 "X-Scene-Overlay-Kinds": ",".join(f"{k}={v}" for k, v in
                                                                   sorted(info.get("overlay_kinds", {}).items())),
                                 "X-Scene-Cloud": info.get("cloud", ""),
                                 "Cache-Control": "no-store"})

    def _confined_dir(path: Path) -> bool:
        try:
            return confined(ws.root, path).is_dir()
        except OSError:
            return False

    def files(request: Request) -> Response:
        try:
            path = safe_path(ws.root, request.path_params["path"])
        except ViewError as exc:
            return PlainTextResponse(str(exc), status_code=404 if "no file" in str(exc) else 403)
        return FileResponse(path)

    async def api_signal(request: Request) -> Response:
        if not policy.token_ok(request.headers.get(TOKEN_HEADER)):
            return JSONResponse({"error": f"missing or wrong access token ({TOKEN_HEADER} header)"}, status_code=403)
        try:
            body = loads_json(await request.body(), max_bytes=MAX_BODY_BYTES)
            kind = str(body.get("kind", ""))
            sid = body.get("session_id") or None
            reason = str(body.get("reason") or "from phyagentos view")[:200]
        except (ValueError, AttributeError):
            return JSONResponse({"error": "body must be a JSON object {kind, session_id?, reason?}"}, status_code=400)
        who = f"{getpass.getuser()}@{socket.gethostname()} (view, {request.client.host if request.client else '?'})"
        try:
            sig = await asyncio.to_thread(ws.send_signal, kind, session_id=sid, reason=reason, issued_by=who)
        except PhyAgentOSError as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)
        return JSONResponse(sig.model_dump(mode="json"))

    async def events(request: Request) -> Response:
        sid = request.query_params.get("session") or None
        if sid:
            _check_id(sid, "session id")
        root_files = [f for f, _ in DOCUMENTS.values()]
        tracker = Tracker(ws, request.query_params.getlist("f"))

        def wanted_dirs() -> list[str]:
            extra = [f"evidence/{sid}"] if sid and _confined_dir(ws.root / "evidence" / sid) \
                else (["evidence"] if sid else [])
            return [d for d in (*_WATCHED_DIRS, *extra) if (ws.root / d).is_dir()]

        async def stream():
            loop = asyncio.get_running_loop()
            woke = asyncio.Event()
            dirs = wanted_dirs()
            watcher = WorkspaceWatcher(ws.root, dirs=dirs, files=root_files)

            def readable(w: WorkspaceWatcher) -> None:
                # Drain at once: the wake-up socket is level-triggered, and left readable during
                # the coalescing sleep it would call this on every loop iteration (a busy loop).
                w.clear()
                woke.set()

            loop.add_reader(watcher.fileno(), readable, watcher)
            count = 0
            try:
                yield "retry: 1000\n\n"
                while True:
                    if await request.is_disconnected():
                        break
                    polling = watcher.mode != "inotify"  # no inotify (e.g. watch limit): refresh every 2 s
                    try:
                        await asyncio.wait_for(woke.wait(), timeout=2.0 if polling else 5.0)
                        changed = True
                    except asyncio.TimeoutError:
                        changed = polling
                    if changed:
                        await asyncio.sleep(1.0 / MAX_EVENT_RATE_HZ)  # coalesce bursts of renames
                        watcher.clear()
                        woke.clear()
                        # Only the page's fragments whose inputs changed (changes.py); none: say nothing.
                        which = tracker.changed() if tracker.urls else None
                        if which is None or which:
                            count += 1
                            yield f"event: change\ndata: {json.dumps(which)}\n\n"
                    else:
                        yield ": keep-alive\n\n"
                    if wanted_dirs() != dirs:  # e.g. the session's evidence directory appeared
                        loop.remove_reader(watcher.fileno())
                        watcher.close()
                        dirs = wanted_dirs()
                        watcher = WorkspaceWatcher(ws.root, dirs=dirs, files=root_files)
                        loop.add_reader(watcher.fileno(), readable, watcher)
                        count += 1
                        yield "event: change\ndata: null\n\n"
            finally:
                loop.remove_reader(watcher.fileno())
                watcher.close()

        return StreamingResponse(stream(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    routes = [
        Route("/", index), Route("/run/{run_id}", run_page), Route("/session/{session_id}", session_page),
        Route("/memory", memory_page), Route("/compare", compare_page),
        Route("/fragment/overview", f_overview), Route("/fragment/runs", f_runs), Route("/fragment/run/{run_id}", f_run),
        Route("/fragment/session/{session_id}", f_session), Route("/fragment/tree/{session_id}", f_tree),
        Route("/fragment/memory", f_memory),
        Route("/api/tree/{session_id}", api_tree), Route("/api/frames/{session_id}", api_frames),
        Route("/api/signals/{session_id}", api_signals),
        Route("/api/scene/{session_id}.png", api_scene), Route("/api/signal", api_signal, methods=["POST"]),
        Route("/events", events), Route("/files/{path:path}", files),
        Mount("/static", app=StaticFiles(directory=STATIC_DIR), name="static"),
    ]
    @contextlib.asynccontextmanager
    async def lifespan(app):
        # Read every RUN.md once in the background, so the first index load only stats them.
        warm = asyncio.get_running_loop().run_in_executor(None, data.panel, lambda: runs_cache.rows(ws))
        yield
        await warm
        await asyncio.to_thread(renderer.close)

    async def view_error(request: Request, exc: Exception) -> Response:
        return PlainTextResponse(str(exc), status_code=400)

    app = Starlette(routes=routes, middleware=[Middleware(_HostGuard, policy=policy), Middleware(BodyLimit)],
                    lifespan=lifespan,
                    exception_handlers={ViewError: view_error})
    app.state.workspace = ws
    app.state.policy = policy
    return app


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on ``host:port`` (``port`` 0: any free port).

    Raises:
        ViewError: the address cannot be bound (the message says which).
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ViewError(f"cannot listen on {host}:{port}: {exc}") from exc
    sock.listen(64)
    return sock


def serve(workspace: str | Path, *, host: str = "127.0.0.1", port: int = 8787, announce=print) -> None:
    """Serve the view of ``workspace`` until interrupted.

    ``announce`` receives the URL (with ``?token=`` when bound beyond loopback) and the
    access token, once the socket listens.

    Raises:
        ViewError: the address cannot be bound.
        ProtocolError: ``workspace`` is not a workspace.
    """
    policy = AccessPolicy(host=host)
    app = create_app(workspace, policy=policy)
    sock = bind(host, port)
    actual = sock.getsockname()[1]
    shown = f"[{host}]" if ":" in host else host
    url = f"http://{shown}:{actual}/" + ("" if policy.loopback else f"?token={policy.token}")
    announce(url, policy.token)
    config = uvicorn.Config(app, log_level="warning", timeout_graceful_shutdown=1, lifespan="on")
    uvicorn.Server(config).run(sockets=[sock])
