"""What ``phyagentos view`` serves and who may change anything.

- Files: only regular files inside the workspace, resolved with symlinks followed, never
  through ``..``, a hidden component (``.locks``, ``.index``) or an absolute path; the same
  holds for every evidence file a page or an API reads (``tree.json``, snapshots, the
  trace, the recording): a link out of the workspace is refused, a FIFO is never opened
  for reading in a way that blocks.
- Sizes: a path is at most :data:`~phyagentos.untrusted.MAX_PATH_CHARS` characters, a
  request body at most :data:`MAX_BODY_BYTES` (:class:`BodyLimit`, checked before the
  route reads it), JSON at most :data:`~phyagentos.untrusted.MAX_JSON_DEPTH` levels deep.
- Hosts: 127.0.0.1 by default. Binding any other address needs ``--host`` explicitly; then
  every state-changing request (a signal) must carry the access token printed at start
  (header ``X-PhyAgentOS-Token``). On loopback the page itself carries the token, and
  requests whose ``Host`` header is not a loopback name are refused (DNS rebinding).
"""

from __future__ import annotations

import hmac
import secrets
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from phyagentos.errors import ViewError
from phyagentos.untrusted import MAX_PATH_CHARS, NotConfined, confined, quote

__all__ = ["LOOPBACK_HOSTS", "AccessPolicy", "safe_path", "evidence_dir", "BodyLimit", "MAX_BODY_BYTES"]

#: Host names and addresses that only this machine can reach.
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
TOKEN_HEADER = "X-PhyAgentOS-Token"


def safe_path(root: Path, relative: str) -> Path:
    """The regular file ``relative`` inside workspace ``root``.

    Raises:
        ViewError: an empty, absolute, hidden or over-long path (more than
            :data:`~phyagentos.untrusted.MAX_PATH_CHARS` characters, or a component over
            255 bytes), a ``..`` component, a path that resolves (symlinks followed)
            outside ``root``, or no such regular file (a FIFO or a device is "no file").
    """
    if not relative or "\x00" in relative or "\\" in relative:
        raise ViewError(f"refused path {quote(relative)}")
    if len(relative) > MAX_PATH_CHARS:
        raise ViewError(f"refused path of {len(relative)} characters: longer than {MAX_PATH_CHARS}")
    parts = PurePosixPath(relative).parts
    if PurePosixPath(relative).is_absolute() or any(p == ".." or p.startswith(".") for p in parts):
        raise ViewError(f"refused path {quote(relative)}: absolute, '..' or hidden component")
    try:
        resolved = confined(root, root / relative)
    except NotConfined:
        raise ViewError(f"refused path {quote(relative)}: resolves outside the workspace") from None
    if not resolved.is_file():
        raise ViewError(f"no file {quote(relative)} in the workspace")
    return resolved


def evidence_dir(root: Path, session_id: str) -> Path:
    """``root/evidence/<session_id>`` as the view may read it: the directory itself may be
    a link, but it must resolve inside the workspace (files in it are read with
    ``root=`` so that each one is checked the same way).

    Raises:
        ViewError: the evidence directory resolves outside the workspace.
    """
    path = Path(root) / "evidence" / session_id
    try:
        confined(root, path)
    except NotConfined:
        raise ViewError(f"refused evidence/{session_id}: it resolves outside the workspace") from None
    return path


@dataclass(frozen=True)
class AccessPolicy:
    """The token and host rules of one server.

    Attributes:
        host: the address the server binds.
        token: the access token for state-changing requests.
    """

    host: str = "127.0.0.1"
    token: str = field(default_factory=lambda: secrets.token_urlsafe(18))

    @property
    def loopback(self) -> bool:
        return self.host in LOOPBACK_HOSTS

    def token_in_page(self) -> str:
        """The token embedded in served pages: on loopback only (remote users paste it)."""
        return self.token if self.loopback else ""

    def host_allowed(self, host_header: str | None) -> bool:
        """On loopback, the ``Host`` header must name a loopback host (else DNS rebinding)."""
        if not self.loopback:
            return True
        if not host_header:
            return False
        name = host_header.rsplit(":", 1)[0] if not host_header.startswith("[") else host_header[1:].split("]")[0]
        return name in LOOPBACK_HOSTS

    def token_ok(self, presented: str | None) -> bool:
        return bool(presented) and hmac.compare_digest(presented.encode(), self.token.encode())


#: Largest request body (bytes) the view accepts: a signal is ``{kind, session_id, reason}``.
MAX_BODY_BYTES = 64 * 1024


class BodyTooLarge(Exception):
    """Raised inside :class:`BodyLimit` when a streamed body passes its limit."""


class BodyLimit:
    """ASGI middleware: refuse a request body over ``limit`` bytes with 413, before the
    route reads it: by its ``Content-Length``, or (chunked) as soon as the bytes received
    pass the limit; nothing over the limit is ever buffered."""

    def __init__(self, app, *, limit: int = MAX_BODY_BYTES) -> None:
        self.app = app
        self.limit = int(limit)

    async def _refuse(self, send) -> None:
        body = f"request body larger than {self.limit} bytes".encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                                (b"content-length", str(len(body)).encode()), (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = dict(scope.get("headers") or []).get(b"content-length")
        if length is not None:
            try:
                too_large = int(length) > self.limit
            except ValueError:
                too_large = True
            if too_large:
                await self._refuse(send)
                return
        received = 0
        started = False

        async def limited_receive():
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit:
                    raise BodyTooLarge()
            return message

        async def tracking_send(message):
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except BodyTooLarge:
            if not started:
                await self._refuse(send)
