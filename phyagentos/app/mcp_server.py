"""The ToolRegistry as an MCP server (official ``mcp`` SDK): ``phyagentos mcp --workspace WS [--http]``.

A composition root: it builds the :class:`~phyagentos.agent.tools.ToolRegistry` with the
validated submit path (:func:`phyagentos.app.orchestrator.submit_goal_graph`) and the Goal
Planner (the model of ``llm.yaml``/environment, offline by default), and serves exactly
its tools -- names, descriptions and JSON input schemas as the registry declares them --
over stdio (default) or streamable HTTP on localhost (``--http``, path ``/mcp``).

A tool error (bad arguments, a policy rejection, an invalid goal graph) is returned as an
MCP tool result with ``isError`` and the message; results are JSON text.

What goes back is bounded and clean (issue 33): every answer passes through
:func:`phyagentos.untrusted.redact_secrets` (an endpoint URL with credentials, a key),
an error message is at most :data:`MAX_ERROR_CHARS` characters, arguments are checked
against the tools' ``maxLength`` and nesting bounds (:mod:`phyagentos.agent.tools`), and
over HTTP a request body is at most :data:`MAX_HTTP_BODY_BYTES` (413 before it is read).
See ``docs/security.md``.
"""

from __future__ import annotations

import json
import logging
import re
import tempfile
from pathlib import Path
from typing import Any

from phyagentos.agent.tools import ToolError, ToolRegistry
from phyagentos.extras import missing_extra
from phyagentos.protocol import Workspace
from phyagentos.untrusted import json_depth, redact_secrets
from phyagentos.yamlsource import clip

try:  # the `mcp` extra (anyio comes with it)
    import anyio
    import mcp.types as types
    from mcp.server.lowlevel import Server
    from mcp.server.stdio import stdio_server
except ImportError as exc:
    raise missing_extra(exc, extra="mcp") from exc

__all__ = ["build_registry", "build_server", "serve", "MAX_ERROR_CHARS", "MAX_HTTP_BODY_BYTES"]

#: Longest tool error message returned (characters).
MAX_ERROR_CHARS = 4000
#: Largest HTTP request body (bytes): a goal graph of ``MAX_GOAL_GRAPH_CHARS`` plus JSON framing.
MAX_HTTP_BODY_BYTES = 5 * 1024 * 1024

logger = logging.getLogger(__name__)


def build_registry(workspace: Workspace, *, with_planner: bool = True) -> ToolRegistry:
    """The registry over ``workspace`` with submit and (optionally) the Goal Planner wired in."""
    from phyagentos.app.orchestrator import submit_goal_graph  # noqa: PLC0415

    def submit(text: str) -> str:
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", dir=workspace.root, prefix=".submit-", delete=False) as f:
            f.write(text)
            path = Path(f.name)
        try:
            return submit_goal_graph(path, workspace.root, submitted_by="mcp").run_id
        finally:
            path.unlink(missing_ok=True)

    plan = None
    if with_planner:
        def plan(request: str, scene: dict | None) -> dict:
            from phyagentos.app.factories import default_scene, make_planner, perceived_entities  # noqa: PLC0415

            result = make_planner(workspace).plan(request, scene=scene or default_scene(),
                                                  environment=perceived_entities(workspace))
            out = result.to_dict()
            out["goal_graph_yaml"] = result.graph_yaml
            return out

    from functools import partial  # noqa: PLC0415

    from phyagentos.runtime.reach_query import answer_reach_query  # noqa: PLC0415

    return ToolRegistry(workspace, submit=submit, plan=plan, issued_by="mcp",
                        reach=partial(answer_reach_query, root=workspace.root))


def build_server(registry: ToolRegistry) -> Server:
    """A low-level MCP server exposing ``registry``'s tools unchanged."""

    async def list_tools(ctx, params) -> types.ListToolsResult:
        return types.ListToolsResult(tools=[types.Tool(name=t["name"], description=t["description"],
                                                       input_schema=t["input_schema"]) for t in registry.describe()])

    async def call_tool(ctx, params: types.CallToolRequestParams) -> types.CallToolResult:
        try:
            result: Any = await anyio.to_thread.run_sync(registry.call, params.name, dict(params.arguments or {}))
        except ToolError as exc:
            message = clip(redact_secrets(str(exc)), MAX_ERROR_CHARS)
            logger.info("tool %s failed: %s", params.name, message)
            return types.CallToolResult(content=[types.TextContent(type="text", text=message)], is_error=True)
        except Exception as exc:  # noqa: BLE001 - a bug must not send a traceback (or a secret) to the client
            logger.exception("tool %s crashed", params.name)
            message = clip(redact_secrets(f"{params.name}: internal error ({type(exc).__name__}: {exc})"),
                           MAX_ERROR_CHARS)
            return types.CallToolResult(content=[types.TextContent(type="text", text=message)], is_error=True)
        text = redact_secrets(json.dumps(result, ensure_ascii=False, default=str))
        return types.CallToolResult(content=[types.TextContent(type="text", text=text)], is_error=False)

    return Server("phyagentos", version="0.1.0",
                  instructions="PhyAgentOS ToolRegistry: read the workspace, plan, submit goal graphs, signal.",
                  on_list_tools=list_tools, on_call_tool=call_tool)


#: Deepest JSON-RPC message handed to the SDK's parser: deeper ones (the SDK drops a message
#: its parser refuses without answering, and the client would wait) are answered with an error.
MAX_RPC_DEPTH = 100
#: Longest JSON-RPC line read (characters): a goal graph of 1 MiB plus framing.
MAX_RPC_LINE_CHARS = 4 * 1024 * 1024
_RPC_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}:,]')
_RPC_ID_VALUE = re.compile(r'\s*(-?\d+|"(?:[^"\\]|\\.)*")')


def _top_level_id(line: str) -> Any:
    """The ``id`` of a JSON-RPC message, found without parsing the whole (possibly very deep) text."""
    depth = 0
    previous = None
    for m in _RPC_TOKEN.finditer(line):
        token = m.group(0)
        if token in "[{":
            depth += 1
        elif token in "]}":
            depth -= 1
        elif token == ":" and depth == 1 and previous == '"id"':
            value = _RPC_ID_VALUE.match(line, m.end())
            return json.loads(value.group(1)) if value else None
        previous = token
    return None


def refuse_oversized_rpc(line: str) -> str:
    """``line`` unchanged, or -- when it is longer than :data:`MAX_RPC_LINE_CHARS` or nested
    deeper than :data:`MAX_RPC_DEPTH` -- a request for a method no server has, with the same
    ``id``, so that the SDK answers the client with an error instead of dropping the message."""
    if len(line) <= MAX_RPC_LINE_CHARS and json_depth(line) <= MAX_RPC_DEPTH:
        return line
    ident = _top_level_id(line[:MAX_RPC_LINE_CHARS])
    logger.info("refused a JSON-RPC message of %d characters (too long or nested deeper than %d)", len(line),
                MAX_RPC_DEPTH)
    if ident is None:
        return "{}\n"  # a notification: nothing to answer; the SDK logs the malformed message
    return json.dumps({"jsonrpc": "2.0", "id": ident, "method": "phyagentos/refused: message too long or too deep",
                       "params": {}}) + "\n"


class _BoundedLines:
    """An async line source that passes :func:`refuse_oversized_rpc` over every line."""

    def __init__(self, inner) -> None:
        self._inner = inner

    def __aiter__(self):
        return self._lines()

    async def _lines(self):
        async for line in self._inner:
            yield refuse_oversized_rpc(line)


def _bounded_stdin() -> _BoundedLines:
    """The process's stdin as UTF-8 lines through :func:`refuse_oversized_rpc`; fd 0 then points
    at the null device (as the SDK does), so tools and their children read EOF."""
    import io  # noqa: PLC0415
    import os  # noqa: PLC0415

    stream = io.TextIOWrapper(os.fdopen(os.dup(0), "rb"), encoding="utf-8", errors="replace")
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.close(null)
    return _BoundedLines(anyio.wrap_file(stream))


def serve(workspace_dir: str | Path, *, http: bool = False, host: str = "127.0.0.1", port: int = 8765,
          with_planner: bool = True) -> None:
    """Serve the workspace's ToolRegistry until stopped (stdio, or HTTP on ``host:port``)."""
    workspace = Workspace.create(workspace_dir)
    server = build_server(build_registry(workspace, with_planner=with_planner))
    if not http:
        async def run_stdio() -> None:
            async with stdio_server(stdin=_bounded_stdin()) as (read, write):
                await server.run(read, write, server.create_initialization_options())

        anyio.run(run_stdio)
        return
    if host not in ("127.0.0.1", "localhost", "::1"):
        raise ValueError(f"the MCP HTTP server binds to localhost only, not {host!r}")
    import uvicorn  # noqa: PLC0415 - installed with mcp

    from phyagentos.view.security import BodyLimit  # noqa: PLC0415

    app = BodyLimit(server.streamable_http_app(host=host), limit=MAX_HTTP_BODY_BYTES)
    print(f"serving MCP on http://{host}:{port}/mcp", flush=True)
    uvicorn.run(app, host=host, port=port, log_level="warning")
