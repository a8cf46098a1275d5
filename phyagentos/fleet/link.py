"""A zenoh session of one fleet peer, with the few operations the fleet uses.

Key expressions (``P`` is the fleet's prefix, ``paos`` by default)::

    P/edge/<edge>/alive               liveliness token of an edge (presence)
    P/agent/<agent>/alive             liveliness token of an agent
    P/edge/<edge>/session/<id>        publication: a session record changed (JSON, with revision)
    P/edge/<edge>/doc/<NAME>          publication: TARGETS, ENVIRONMENT or RUNTIME_SIGNAL changed
    P/edge/<edge>/catchup             queryable: every document and session the edge holds
    P/edge/<edge>/submit              queryable: submit a session (idempotent by session id)
    P/edge/<edge>/verdict             queryable: the agent's transitions of a session (verification)
    P/edge/<edge>/signal              queryable: e-stop, clear, cancel from the agent
    P/edge/<edge>/frames/<id>         queryable: a session's evidence frames, on demand
    P/agent/<agent>/session/<id>      publication: the agent's transitions (verification), best effort

Payloads are JSON (UTF-8). Nothing here logs a payload or the configuration.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from typing import Any, Literal

from phyagentos.errors import FleetError
from phyagentos.extras import import_extra
from phyagentos.untrusted import loads_json, redact_secrets
from phyagentos.yamlsource import clip

from .config import FleetConfig

__all__ = ["FleetLink", "Keys"]

log = logging.getLogger(__name__)

#: Largest fleet message decoded (bytes) and its deepest nesting: a peer's message is
#: bounded before it is parsed (a session record is a few kilobytes, 10 levels deep).
MAX_MESSAGE_BYTES = 64 * 1024 * 1024
MAX_MESSAGE_DEPTH = 200


def _decode(raw: bytes) -> Any:
    """A peer's JSON payload, bounded (:func:`phyagentos.untrusted.loads_json`); ValueError if refused."""
    return loads_json(raw, max_bytes=MAX_MESSAGE_BYTES, max_depth=MAX_MESSAGE_DEPTH)


class Keys:
    """Key expressions of one fleet (see the module docstring)."""

    def __init__(self, prefix: str = "paos") -> None:
        self.p = prefix

    def edge_alive(self, edge: str = "*") -> str:
        return f"{self.p}/edge/{edge}/alive"

    def agent_alive(self, agent: str = "*") -> str:
        return f"{self.p}/agent/{agent}/alive"

    def session(self, edge: str = "*", sid: str = "*") -> str:
        return f"{self.p}/edge/{edge}/session/{sid}"

    def doc(self, edge: str = "*", name: str = "*") -> str:
        return f"{self.p}/edge/{edge}/doc/{name}"

    def edge_q(self, edge: str, what: str) -> str:
        return f"{self.p}/edge/{edge}/{what}"

    def estop_all(self) -> str:
        return f"{self.p}/estop"


class FleetLink:
    """An open zenoh session (``mode``: router, peer or client).

    Raises (constructor):
        FleetError: the session cannot be opened (router unreachable, authentication refused).
    """

    def __init__(self, config: FleetConfig, *, mode: Literal["router", "peer", "client"] = "client") -> None:
        zenoh = import_extra("zenoh", extra="fleet")  # only when a link opens

        self._zenoh = zenoh
        self.config = config
        self.keys = Keys(config.prefix)
        self.mode = mode
        try:
            self.session = zenoh.open(zenoh.Config.from_json5(config.zenoh_json(mode)))
        except zenoh.ZError as exc:
            where = ", ".join(config.listen if mode == "router" else config.connect) or "no endpoint"
            # zenoh's message names endpoints and source lines, never credentials
            raise FleetError(f"cannot open a zenoh {mode} session ({where}): {str(exc).split(' at ')[0]}; "
                             "check the router runs and this peer's auth in fleet.yaml") from None
        self._owned: list[Any] = []
        self._lock = threading.Lock()
        self._closed = False
        self.bytes_out = 0
        self.bytes_in = 0

    # -- publications and subscriptions ----------------------------------------

    def put(self, key: str, data: Any) -> int:
        """Publish ``data`` (JSON-able) on ``key``; returns the payload size in bytes."""
        payload = json.dumps(data, separators=(",", ":")).encode()
        # BLOCK, not zenoh's default DROP: a document change is never dropped under congestion
        self.session.put(key, payload, congestion_control=self._zenoh.CongestionControl.BLOCK)
        self.bytes_out += len(payload)
        return len(payload)

    def subscribe(self, key: str, handler: Callable[[str, Any], None]) -> None:
        """Call ``handler(key, data)`` for every publication on ``key`` (zenoh's thread)."""

        def on_sample(sample) -> None:
            try:
                raw = sample.payload.to_bytes()
                self.bytes_in += len(raw)
                handler(str(sample.key_expr), _decode(raw))
            except Exception:
                log.exception("fleet: sample on %s not handled", sample.key_expr)

        self._owned.append(self.session.declare_subscriber(key, on_sample))

    def queryable(self, key: str, handler: Callable[[str, Any], Any]) -> None:
        """Answer queries on ``key`` with ``handler(key, data) -> JSON-able`` (zenoh's thread)."""

        def on_query(query) -> None:
            try:
                raw = query.payload.to_bytes() if query.payload is not None else b""
                self.bytes_in += len(raw)
                answer = handler(str(query.key_expr), _decode(raw) if raw else None)
            except Exception as exc:
                log.exception("fleet: query on %s failed", query.key_expr)
                answer = {"status": "error", "error": clip(redact_secrets(f"{type(exc).__name__}: {exc}"), 2000)}
            payload = json.dumps(answer, separators=(",", ":")).encode()
            self.bytes_out += len(payload)
            query.reply(query.key_expr, payload)

        self._owned.append(self.session.declare_queryable(key, on_query))

    def query(self, key: str, data: Any = None, *, timeout_s: float = 3.0) -> list[Any]:
        """Send a query; returns the decoded replies (empty when nobody answered in time)."""
        payload = json.dumps(data, separators=(",", ":")).encode() if data is not None else None
        if payload:
            self.bytes_out += len(payload)
        out = []
        for reply in self.session.get(key, payload=payload, timeout=timeout_s):
            if reply.ok is None:
                continue
            raw = reply.ok.payload.to_bytes()
            self.bytes_in += len(raw)
            try:
                out.append(_decode(raw))
            except ValueError as exc:
                log.warning("fleet: reply on %s refused: %s", key, exc)
        return out

    def query_one(self, key: str, data: Any = None, *, timeout_s: float = 3.0) -> Any | None:
        """The first reply of :meth:`query`, or None."""
        replies = self.query(key, data, timeout_s=timeout_s)
        return replies[0] if replies else None

    # -- liveliness --------------------------------------------------------------

    def token(self, key: str) -> None:
        """Declare a liveliness token on ``key`` for as long as this session lives."""
        self._owned.append(self.session.liveliness().declare_token(key))

    def watch_alive(self, key: str, on_change: Callable[[str, bool], None]) -> None:
        """Call ``on_change(key, alive)`` as tokens matching ``key`` appear and vanish
        (tokens alive now are reported at once)."""

        def on_sample(sample) -> None:
            try:
                on_change(str(sample.key_expr), sample.kind == self._zenoh.SampleKind.PUT)
            except Exception:
                log.exception("fleet: liveliness change on %s not handled", sample.key_expr)

        self._owned.append(self.session.liveliness().declare_subscriber(key, on_sample, history=True))

    def alive(self, key: str, *, timeout_s: float = 2.0) -> list[str]:
        """Keys of the liveliness tokens matching ``key`` alive now."""
        return [str(r.ok.key_expr) for r in self.session.liveliness().get(key, timeout=timeout_s) if r.ok is not None]

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        for obj in reversed(self._owned):
            try:
                obj.undeclare()
            except Exception as exc:  # noqa: BLE001 - closing anyway
                log.debug("fleet: undeclare failed: %s", exc)
        try:
            self.session.close()
        except Exception as exc:  # noqa: BLE001
            log.debug("fleet: session close failed: %s", exc)
