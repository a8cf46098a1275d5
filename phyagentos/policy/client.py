"""A client for openpi-style policy servers over websockets.

Protocol (openpi's ``WebsocketPolicyServer`` / ``openpi_client.WebsocketClientPolicy``):
the client opens a websocket; the server first sends its *metadata* (a msgpack map);
then each binary message the client sends is an observation map and the server
answers with an action map holding ``"actions"``, an ``(H, D)`` array (one row per
future control step). A server that fails sends a *text* frame with the traceback
and closes the connection. Frames use :mod:`phyagentos.policy.wire`.

Health monitoring: every call is bounded by a timeout. A response that does not come
in time means the policy *stalled* (``policy.stalled``); a closed or refused connection
means it *disconnected* (``policy.disconnected``). :meth:`PolicyClient.heartbeat`
sends a websocket ping and waits for the pong. Latencies of inferences and pings are
kept in :attr:`PolicyClient.latencies_s` for the evidence.
"""

from __future__ import annotations

import inspect
import logging
import time
from typing import Any, Mapping

from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import ClientConnection, connect

from phyagentos.errors import PolicyError

from .wire import WireError, packb, unpackb

__all__ = ["PolicyClient", "probe_endpoint"]

logger = logging.getLogger(__name__)

# websockets >= 17 deprecates calling connect() outside a with-block unless asked for
# a plain connection; this client owns the connection's lifetime itself.
_DIRECT = {"legacy": True} if "legacy" in inspect.signature(connect).parameters else {}


class PolicyClient:
    """A connection to one policy server.

    Args:
        uri: ``ws://host:port`` (a bare ``host:port`` gets ``ws://``).
        open_timeout_s: bound on connecting plus receiving the metadata, s.

    Raises:
        PolicyError: ``policy.unreachable`` when the handshake or the metadata does
            not arrive in time, ``policy.malformed`` when the metadata is not a map.
    """

    def __init__(self, uri: str, *, open_timeout_s: float = 2.0):
        self.uri = uri if uri.startswith(("ws://", "wss://")) else f"ws://{uri}"
        self.latencies_s: list[float] = []
        self.ping_rtts_s: list[float] = []
        self.last_seen = 0.0
        started = time.perf_counter()
        try:
            # Pings are sent by heartbeat() so that their timing is ours to check.
            self._ws: ClientConnection = connect(self.uri, open_timeout=open_timeout_s, compression=None, max_size=None,
                                                 proxy=None, ping_interval=None, close_timeout=1.0, **_DIRECT)
        except (OSError, TimeoutError, InvalidHandshake, InvalidURI) as exc:
            raise PolicyError(f"policy server at {self.uri} did not accept a websocket within {open_timeout_s} s: "
                              f"{type(exc).__name__}: {exc}", code="policy.unreachable") from None
        try:
            raw = self._ws.recv(timeout=max(0.05, open_timeout_s - (time.perf_counter() - started)))
        except (TimeoutError, ConnectionClosed, OSError) as exc:
            self.close()
            raise PolicyError(f"policy server at {self.uri} sent no metadata within {open_timeout_s} s "
                              f"({type(exc).__name__})", code="policy.unreachable") from None
        try:
            meta = unpackb(raw) if isinstance(raw, bytes) else None
        except WireError:
            meta = None
        if not isinstance(meta, dict):
            self.close()
            raise PolicyError(f"policy server at {self.uri} sent metadata that is not a msgpack map", code="policy.malformed")
        self.metadata: dict[str, Any] = meta
        self.handshake_s = time.perf_counter() - started
        self.last_seen = time.monotonic()

    def infer(self, obs: Mapping[str, Any], *, timeout_s: float) -> dict[str, Any]:
        """Send one observation and wait at most ``timeout_s`` for the action map.

        Raises:
            PolicyError: ``policy.stalled`` (no answer in time), ``policy.disconnected``
                (connection closed), ``policy.error`` (the server reported an error) or
                ``policy.malformed`` (not a msgpack map).
        """
        t0 = time.perf_counter()
        try:
            self._ws.send(packb(dict(obs)))
            raw = self._ws.recv(timeout=timeout_s)
        except TimeoutError:
            raise PolicyError(f"policy server at {self.uri} did not answer within {timeout_s} s",
                              code="policy.stalled") from None
        except (ConnectionClosed, OSError) as exc:
            raise PolicyError(f"policy server at {self.uri} disconnected: {exc}", code="policy.disconnected") from None
        except WireError as exc:
            raise PolicyError(f"observation cannot be encoded: {exc}", code="policy.malformed") from None
        if isinstance(raw, str):
            raise PolicyError(f"policy server at {self.uri} reported an error:\n{raw}", code="policy.error")
        try:
            out = unpackb(raw)
        except WireError as exc:
            raise PolicyError(f"policy server at {self.uri} sent an undecodable message: {exc}", code="policy.malformed") from None
        if not isinstance(out, dict):
            raise PolicyError(f"policy server at {self.uri} answered a {type(out).__name__}, not a map",
                              code="policy.malformed")
        self.latencies_s.append(time.perf_counter() - t0)
        self.last_seen = time.monotonic()
        return out

    def heartbeat(self, *, timeout_s: float) -> float:
        """Ping the server; returns the round trip in s.

        Raises:
            PolicyError: ``policy.stalled`` (no pong within ``timeout_s``) or
                ``policy.disconnected``.
        """
        t0 = time.perf_counter()
        try:
            pong = self._ws.ping()
        except (ConnectionClosed, OSError) as exc:
            raise PolicyError(f"policy server at {self.uri} disconnected: {exc}", code="policy.disconnected") from None
        if not pong.wait(timeout_s):
            if self._ws.close_code is not None:
                raise PolicyError(f"policy server at {self.uri} disconnected (close code {self._ws.close_code})",
                                  code="policy.disconnected")
            raise PolicyError(f"policy server at {self.uri} missed its heartbeat (no pong within {timeout_s} s)",
                              code="policy.stalled")
        if self._ws.close_code is not None:
            raise PolicyError(f"policy server at {self.uri} disconnected (close code {self._ws.close_code})",
                              code="policy.disconnected")
        rtt = time.perf_counter() - t0
        self.ping_rtts_s.append(rtt)
        self.last_seen = time.monotonic()
        return rtt

    def close(self) -> None:
        try:
            self._ws.close()
        except Exception:  # closing a dead connection must not mask the real error
            pass

    def __enter__(self) -> "PolicyClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def probe_endpoint(uri: str, *, timeout_s: float) -> dict[str, Any]:
    """Contact ``uri`` (handshake + metadata) and hang up; returns the metadata.

    Raises:
        PolicyError: ``policy.unreachable`` / ``policy.malformed`` (see :class:`PolicyClient`).
    """
    with PolicyClient(uri, open_timeout_s=timeout_s) as client:
        return client.metadata
