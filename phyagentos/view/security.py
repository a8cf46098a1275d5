"""What ``phyagentos view`` serves and who may change anything.

- Files: only regular files inside the workspace, resolved with symlinks followed, never
  through ``..``, a hidden component (``.locks``, ``.index``) or an absolute path.
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

__all__ = ["LOOPBACK_HOSTS", "AccessPolicy", "safe_path"]

#: Host names and addresses that only this machine can reach.
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
TOKEN_HEADER = "X-PhyAgentOS-Token"


def safe_path(root: Path, relative: str) -> Path:
    """The regular file ``relative`` inside workspace ``root``.

    Raises:
        ViewError: an empty, absolute or hidden path, a ``..`` component, a path that
            resolves (symlinks followed) outside ``root``, or no such regular file.
    """
    if not relative or "\x00" in relative or "\\" in relative:
        raise ViewError(f"refused path {relative!r}")
    parts = PurePosixPath(relative).parts
    if PurePosixPath(relative).is_absolute() or any(p == ".." or p.startswith(".") for p in parts):
        raise ViewError(f"refused path {relative!r}: absolute, '..' or hidden component")
    base = root.resolve()
    resolved = (base / relative).resolve()
    if not resolved.is_relative_to(base):
        raise ViewError(f"refused path {relative!r}: resolves outside the workspace")
    if not resolved.is_file():
        raise ViewError(f"no file {relative!r} in the workspace")
    return resolved


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
