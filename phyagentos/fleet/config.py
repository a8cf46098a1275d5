"""The deploy-time fleet file (``fleet.yaml``): where the router is, who this peer is,
how it authenticates, and what an edge does when it loses its link.

It is read by ``phyagentos router``, ``edge`` and ``run --fleet``; it is never a protocol
document and is never replicated. Secrets stay out of it too: the password lives in a
file of its own (``password_file``), read when the zenoh session opens, and no message or
log line of the fleet quotes it.

Example (an edge)::

    name: arm1
    connect: [tcp/10.0.0.2:7447]
    auth: {user: arm1, password_file: /etc/phyagentos/arm1.pw}
    link_loss: halt_and_hold
    targets: [franka_tabletop]

and a router::

    listen: [tcp/0.0.0.0:7447]
    auth: {user: router, password_file: router.pw, users_file: users.txt}

``users_file`` (router only) holds ``user:password`` lines, one per peer allowed in.
TLS instead of (or as well as) passwords: ``tls: {root_ca: ca.pem, cert: me.pem, key: me.key}``
with ``tls/`` endpoints.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any, Literal

from pydantic import ConfigDict, Field, ValidationError, field_validator

from phyagentos.errors import FleetError
from phyagentos.protocol.schemas import StrictNumbers
from phyagentos.yamlsource import line_at, read_yaml

__all__ = ["LINK_LOSS_POLICIES", "AuthConfig", "FleetConfig", "TlsConfig", "find_fleet_config", "load_fleet_config"]

#: What a running session does when its edge loses the agent (docs/fleet.md).
LINK_LOSS_POLICIES = ("finish", "halt_and_hold")
_NAME = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$"
_ENDPOINT = r"^(tcp|tls|quic|udp)/[^\s]+:\d+$"


class _Strict(StrictNumbers):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class AuthConfig(_Strict):
    """Zenoh user/password authentication; the password is read from ``password_file``."""

    user: str = Field(min_length=1, max_length=128, pattern=r"^[^:\s]+$")
    password_file: Path
    users_file: Path | None = Field(None, description="router only: 'user:password' lines of the peers let in")

    def password(self) -> str:
        """The password (first line of ``password_file``).

        Raises:
            FleetError: the file is missing, unreadable or empty.
        """
        try:
            text = self.password_file.read_text(encoding="utf-8").strip()
        except OSError as exc:
            raise FleetError(f"password file {self.password_file} unreadable: {exc.strerror}") from None
        if not text:
            raise FleetError(f"password file {self.password_file} is empty")
        return text.splitlines()[0]


class TlsConfig(_Strict):
    """TLS with certificates (``tls/`` endpoints); ``key``/``cert`` are this peer's."""

    root_ca: Path
    cert: Path
    key: Path


class FleetConfig(_Strict):
    """One peer's fleet settings (all times in seconds)."""

    name: str | None = Field(None, pattern=_NAME, description="edge or agent name (unique in the fleet)")
    connect: list[str] = Field(default_factory=list, max_length=64, description="router endpoints, e.g. tcp/HOST:7447")
    listen: list[str] = Field(default_factory=list, max_length=64, description="router only: endpoints to listen on")
    auth: AuthConfig | None = None
    tls: TlsConfig | None = None
    link_loss: Literal["finish", "halt_and_hold"] = "finish"
    targets: list[str] | None = Field(None, description="edge only: the targets it owns (default: every enabled "
                                                         "target of its TARGETS.md)")
    submit_ttl_s: float = Field(30.0, le=86_400.0, gt=0, description="a submit older than this is stale and never started")
    link_timeout_s: float = Field(3.0, le=3600.0, gt=0, description="the agent is lost this long after its last sign of life")
    connect_timeout_s: float = Field(10.0, le=3600.0, gt=0, description="how long opening a session waits for the router "
                                                             "(once open, a lost router is retried for ever)")
    reconnect_max_s: float = Field(0.5, le=3600.0, gt=0, description="longest pause between tries to reach a lost router")
    prefix: str = Field("paos", pattern=r"^[A-Za-z0-9_-]{1,32}$", description="key-expression prefix of the fleet")

    @field_validator("connect", "listen")
    @classmethod
    def _endpoints(cls, value: list[str]) -> list[str]:
        for ep in value:
            if not re.match(_ENDPOINT, ep):
                raise ValueError(f"endpoint {ep!r} is not PROTO/HOST:PORT (PROTO one of tcp, tls, quic, udp)")
        return value

    def with_overrides(self, **kw: Any) -> FleetConfig:
        """A copy with the given (non-None) fields replaced (command-line flags win)."""
        data = self.model_dump()
        data.update({k: v for k, v in kw.items() if v is not None})
        return FleetConfig.model_validate(data)

    def secured(self) -> bool:
        """True if peers authenticate (password or TLS)."""
        return self.auth is not None or self.tls is not None

    def zenoh_json(self, mode: Literal["router", "peer", "client"]) -> str:
        """The zenoh configuration (JSON5 text) of this peer in ``mode``.

        The password is in the returned text: hand it to ``zenoh.Config.from_json5`` and
        never log it.

        Raises:
            FleetError: a password file cannot be read.
        """
        cfg: dict[str, Any] = {"mode": mode,
                               "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": mode != "client"}}}
        if self.connect and mode != "router":
            cfg["connect"] = {"endpoints": list(self.connect)}
        if self.listen and mode == "router":
            cfg["listen"] = {"endpoints": list(self.listen)}
        if mode == "client":
            # the first connection waits this long (a refused login is then an error, not a hang); once
            # connected, zenoh reconnects to a router that went away for as long as it takes
            cfg.setdefault("connect", {})["timeout_ms"] = int(self.connect_timeout_s * 1000)
            # retry a lost router every 0.1 s at first, at most every reconnect_max_s (zenoh's default: 4 s)
            cfg["connect"]["retry"] = {"period_init_ms": 100, "period_max_ms": int(self.reconnect_max_s * 1000),
                                       "period_increase_factor": 2}
        transport: dict[str, Any] = {}
        if self.auth is not None:
            usrpwd: dict[str, Any] = {"user": self.auth.user, "password": self.auth.password()}
            if mode == "router" and self.auth.users_file is not None:
                usrpwd["dictionary_file"] = str(self.auth.users_file)
            transport["auth"] = {"usrpwd": usrpwd}
        if self.tls is not None:
            transport["link"] = {"tls": {"root_ca_certificate": str(self.tls.root_ca),
                                         "listen_certificate": str(self.tls.cert),
                                         "listen_private_key": str(self.tls.key),
                                         "connect_certificate": str(self.tls.cert),
                                         "connect_private_key": str(self.tls.key),
                                         "enable_mtls": True}}
        if transport:
            cfg["transport"] = transport
        return json.dumps(cfg)


def load_fleet_config(path: str | os.PathLike[str]) -> FleetConfig:
    """Read and validate ``fleet.yaml``; relative file paths are taken from its folder.

    Raises:
        FleetError: missing file, YAML syntax error or invalid field, with ``path:line``
            and the valid choices.
    """
    path = Path(path)
    try:  # bounded, and a FIFO or a device is refused instead of waited on
        data = read_yaml(path, error=FleetError, plain=False)
    except OSError as exc:
        raise FleetError(f"cannot read fleet file: {exc.strerror or exc}", path=path) from None
    if not isinstance(data, dict):
        raise FleetError("a fleet file is a mapping (name, connect, auth, ...)", path=path, line=1)
    try:
        config = FleetConfig.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = first["loc"]
        line = line_at(data, tuple(loc))  # the offending key's (or item's) own line, nested ones too
        where = ".".join(str(p) for p in loc)
        allowed = ", ".join(sorted(FleetConfig.model_fields)) if first["type"] == "extra_forbidden" else None
        msg = f"{where}: {first['msg']}" + (f"; valid fields: {allowed}" if allowed else "")
        if where == "link_loss":
            msg += f"; valid: {', '.join(LINK_LOSS_POLICIES)}"
        raise FleetError(msg, path=path, line=line) from None

    def rel(p: Path | None) -> Path | None:
        return None if p is None or p.is_absolute() else path.parent / p

    updates: dict[str, Any] = {}
    if config.auth is not None:
        updates["auth"] = config.auth.model_copy(update={k: rel(v) for k, v in
                                                         (("password_file", config.auth.password_file),
                                                          ("users_file", config.auth.users_file)) if rel(v)})
    if config.tls is not None:
        updates["tls"] = config.tls.model_copy(update={k: rel(getattr(config.tls, k)) for k in ("root_ca", "cert", "key")
                                                       if rel(getattr(config.tls, k))})
    return config.model_copy(update=updates)


def find_fleet_config(explicit: str | os.PathLike[str] | None, workspace: str | os.PathLike[str] | None) -> FleetConfig:
    """The fleet file to use: ``explicit``, else ``$PHYAGENTOS_FLEET``, else
    ``<workspace>/fleet.yaml``, else an empty (unauthenticated) configuration.

    Raises:
        FleetError: as :func:`load_fleet_config`.
    """
    for candidate in (explicit, os.environ.get("PHYAGENTOS_FLEET"),
                      Path(workspace) / "fleet.yaml" if workspace is not None else None):
        if candidate and Path(candidate).is_file():
            return load_fleet_config(candidate)
        if candidate and candidate == explicit:
            raise FleetError("fleet file not found", path=Path(candidate))
    return FleetConfig.model_validate({})
