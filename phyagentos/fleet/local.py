"""A fleet on this machine as real processes (tests, ``bench/fleet.py``, demos): a router
and edges started with the ``phyagentos`` CLI, users and passwords written to a folder,
every process killed (with its children) on :meth:`LocalFleet.close`."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import yaml

from phyagentos.errors import FleetError

__all__ = ["LocalFleet", "free_port"]


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LocalFleet:
    """Processes of one local fleet under ``root``.

    Args:
        root: folder for fleet files, logs and workspaces.
        auth: write users and passwords and make every peer authenticate.
        extra: more fleet-file fields for every edge (e.g. ``{"link_timeout_s": 1}``).
        peers: names of the edges (and agents besides ``agent``) the router lets in (its
            users file is read when it starts).
    """

    def __init__(self, root: str | Path, *, auth: bool = True, extra: dict | None = None,
                 port: int | None = None, peers: tuple[str, ...] | list[str] = ()) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.port = port or free_port()
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.auth = auth
        self.extra = extra or {}
        self.procs: dict[str, subprocess.Popen] = {}
        self._log_start: dict[str, int] = {}
        self._users: list[str] = []
        if auth:
            for name in ("router", "agent", *peers):
                self._user(name)

    def _user(self, name: str) -> None:
        pw = f"{name}-{os.urandom(8).hex()}"
        (self.root / f"{name}.pw").write_text(pw + "\n", encoding="utf-8")
        os.chmod(self.root / f"{name}.pw", 0o600)
        self._users.append(f"{name}:{pw}")
        users = self.root / "users.txt"
        users.write_text("\n".join(self._users) + "\n", encoding="utf-8")
        os.chmod(users, 0o600)

    def config_file(self, name: str, **fields) -> Path:
        """Write ``<root>/<name>.yaml`` (auth of user ``name`` plus ``fields``); returns it."""
        data = dict(fields)
        if self.auth:
            if not (self.root / f"{name}.pw").exists():
                self._user(name)
            data["auth"] = {"user": name, "password_file": f"{name}.pw"}
            if name == "router":
                data["auth"]["users_file"] = "users.txt"
        path = self.root / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data), encoding="utf-8")
        return path

    def _spawn(self, key: str, args: list[str], *, ready: str, timeout_s: float) -> subprocess.Popen:
        logfile = self.root / f"{key}.log"
        self._log_start[key] = logfile.stat().st_size if logfile.exists() else 0  # a restart appends
        log = open(logfile, "ab")  # noqa: SIM115 - kept open by the child
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen([sys.executable, "-m", "phyagentos.cli", *args], stdout=log, stderr=subprocess.STDOUT,
                                env=env, start_new_session=True)
        log.close()
        self.procs[key] = proc
        if ready:
            self._spawn_wait(key, ready, timeout_s)
        return proc

    def _spawn_wait(self, key: str, ready: str, timeout_s: float) -> subprocess.Popen:
        """Wait until the log of ``key`` shows ``ready``.

        Raises:
            FleetError: the process exited, or ``timeout_s`` passed.
        """
        proc = self.procs[key]
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with open(self.root / f"{key}.log", "rb") as fh:
                fh.seek(self._log_start.get(key, 0))
                text = fh.read().decode("utf-8", errors="replace")
            if ready in text:
                return proc
            if proc.poll() is not None:
                raise FleetError(f"{key} exited with {proc.returncode}: {text[-2000:]}")
            time.sleep(0.05)
        raise FleetError(f"{key} not ready after {timeout_s} s")

    def start_router(self, *, timeout_s: float = 30.0) -> subprocess.Popen:
        cfg = self.config_file("router")
        return self._spawn("router", ["router", "--listen", self.endpoint, "--config", str(cfg)],
                           ready="router listening", timeout_s=timeout_s)

    def start_edge(self, name: str, targets: list[str], *, link_loss: str | None = None, workspace: Path | None = None,
                   timeout_s: float = 60.0, wait_ready: bool = True, more: tuple[str, ...] = ()) -> subprocess.Popen:
        cfg = self.config_file(name, **self.extra)
        ws = workspace or self.root / f"ws_{name}"
        args = ["edge", "--workspace", str(ws), "--connect", self.endpoint, "--name", name, "--config", str(cfg),
                "--targets", ",".join(targets)]
        if link_loss:
            args += ["--link-loss", link_loss]
        args += list(more)
        return self._spawn(name, args, ready=f"edge {name} serving" if wait_ready else "",
                           timeout_s=timeout_s)

    def workspace(self, name: str) -> Path:
        return self.root / f"ws_{name}"

    def run_args(self, graph: str | Path, workspace: Path, *more: str) -> list[str]:
        """The argv of ``phyagentos run GRAPH --fleet ... --json`` as the agent."""
        cfg = self.config_file("agent") if self.auth else None
        return [sys.executable, "-m", "phyagentos.cli", "run", str(graph), "--fleet", self.endpoint, "--workspace",
                str(workspace), "--name", "agent", "--json", *(["--config", str(cfg)] if cfg else []), *more]

    def kill(self, key: str, sig: int = signal.SIGKILL) -> None:
        """Send ``sig`` to the process group of ``key`` (the process and its runner)."""
        proc = self.procs.get(key)
        if proc is not None and proc.poll() is None:
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                pass
            if sig in (signal.SIGKILL, signal.SIGTERM):
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait(timeout=10)

    def close(self) -> None:
        for key in list(self.procs):
            proc = self.procs[key]
            if proc.poll() is None:
                try:
                    os.killpg(proc.pid, signal.SIGCONT)
                except ProcessLookupError:
                    pass
            self.kill(key, signal.SIGKILL)
        self.procs.clear()
