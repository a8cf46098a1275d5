"""A policy server that speaks openpi's websocket protocol.

Any object with ``metadata`` (a dict) and ``infer(obs) -> dict`` can be served. The
protocol is openpi's: on connect the server sends the metadata; then every binary
message is an observation and is answered with the policy's action map plus
``server_timing`` (``infer_ms``); control messages ``{"__ctrl__": "episode_start" |
"episode_end"}`` are acknowledged; an exception in the policy is sent back as a text
frame (the traceback) and the connection is closed with code 1011. ``GET /healthz``
answers 200 without a websocket. One connection is served at a time per policy
instance (inference runs in a worker thread, so pings are still answered while the
model computes).

``stall_after`` injects a fault for testing the runtime: after that many inferences
the server stops answering observations (pings still work), like a model that hangs.
"""

from __future__ import annotations

import asyncio
import http
import logging
import threading
import time
import traceback
from typing import Any, Protocol

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.frames import CloseCode
from websockets.http11 import Request, Response

from .wire import packb, unpackb

__all__ = ["Policy", "PolicyServer"]

logger = logging.getLogger(__name__)


class Policy(Protocol):
    """What :class:`PolicyServer` serves."""

    metadata: dict[str, Any]

    def infer(self, obs: dict[str, Any]) -> dict[str, Any]: ...


def _health(connection: ServerConnection, request: Request) -> Response | None:
    if request.path == "/healthz":
        return connection.respond(http.HTTPStatus.OK, "OK\n")
    return None


class PolicyServer:
    """Serve ``policy`` on ``host:port`` (port 0: the OS picks a free one).

    Args:
        policy: the model or controller.
        host, port: bind address.
        stall_after: stop answering after this many inferences (fault injection).
        on_request: called with each inference count (e.g. to log progress).
    """

    def __init__(self, policy: Policy, *, host: str = "127.0.0.1", port: int = 0, stall_after: int | None = None,
                 on_request=None):
        self.policy = policy
        self.host, self.port = host, port
        self.stall_after = stall_after
        self.on_request = on_request
        self.requests = 0
        #: ``time.monotonic()`` when the injected stall began (None: not stalled)
        self.stalled_at: float | None = None
        self._server: Server | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._lock = asyncio.Lock()

    async def _handler(self, ws: ServerConnection) -> None:
        async with self._lock:  # one client at a time, like openpi's server
            await ws.send(packb(self.policy.metadata))
            while True:
                try:
                    raw = await ws.recv()
                except ConnectionClosed:
                    return
                try:
                    obs = unpackb(raw) if isinstance(raw, bytes) else None
                    if not isinstance(obs, dict):
                        raise ValueError("an observation must be a binary msgpack map")
                    if "__ctrl__" in obs:
                        await ws.send(packb({"__ack__": str(obs["__ctrl__"])}))
                        continue
                    self.requests += 1
                    if self.stall_after is not None and self.requests > self.stall_after:
                        self.stalled_at = time.monotonic()
                        logger.warning("policy server: stalling (fault injection after %d inferences)", self.stall_after)
                        await ws.wait_closed()  # never answers (pings still do) until the peer leaves
                        return
                    t0 = time.perf_counter()
                    action = await asyncio.to_thread(self.policy.infer, obs)
                    action = dict(action)
                    action["server_timing"] = {"infer_ms": (time.perf_counter() - t0) * 1e3}
                    await ws.send(packb(action))
                    if self.on_request is not None:
                        self.on_request(self.requests)
                except ConnectionClosed:
                    return
                except Exception:
                    logger.exception("policy server: inference failed")
                    try:
                        await ws.send(traceback.format_exc())
                        await ws.close(CloseCode.INTERNAL_ERROR, "policy error; traceback in the previous frame")
                    except ConnectionClosed:
                        pass
                    return

    async def _run(self) -> None:
        async with serve(self._handler, self.host, self.port, compression=None, max_size=None,
                         process_request=_health) as server:
            self._server = server
            self._loop = asyncio.get_running_loop()
            self.port = int(server.sockets[0].getsockname()[1])
            self._ready.set()
            await server.serve_forever()

    def serve_forever(self) -> None:
        """Run in the calling thread until :meth:`stop` (or KeyboardInterrupt)."""
        asyncio.run(self._run())

    def start(self, *, timeout_s: float = 10.0) -> "PolicyServer":
        """Run in a daemon thread; returns once the socket is bound (:attr:`port` set)."""
        thread = threading.Thread(target=self.serve_forever, name="policy-server", daemon=True)
        thread.start()
        if not self._ready.wait(timeout_s):
            raise RuntimeError(f"policy server did not start within {timeout_s} s")
        self._thread = thread
        return self

    def wait_ready(self, timeout_s: float | None = None) -> bool:
        """Block until the socket is bound (:attr:`port` is then the real port)."""
        return self._ready.wait(timeout_s)

    @property
    def uri(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def stop(self) -> None:
        """Close the server and its connections (thread mode)."""
        if self._server is not None and self._loop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._server.close)
        thread = getattr(self, "_thread", None)
        if thread is not None:
            thread.join(timeout=5)
