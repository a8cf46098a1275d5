"""What ``phyagentos view`` refuses: paths outside the workspace, signals without the token,
foreign Host headers. Over real HTTP against a real ``phyagentos view`` process."""

from __future__ import annotations

import http.client
import json
import os
import signal
import subprocess

import pytest
from test_view_browser import start_view

from phyagentos.errors import ViewError
from phyagentos.protocol import Workspace
from phyagentos.view import AccessPolicy, safe_path


def request(url: str, method: str, path: str, *, body: bytes | None = None, headers: dict | None = None):
    """One raw HTTP request (the path goes on the wire exactly as given: no normalisation)."""
    host, port = url.removeprefix("http://").split(":")
    conn = http.client.HTTPConnection(host, int(port), timeout=30)
    try:
        conn.putrequest(method, path, skip_host=bool(headers and "Host" in headers), skip_accept_encoding=True)
        for k, v in (headers or {}).items():
            conn.putheader(k, v)
        if body is not None:
            conn.putheader("Content-Length", str(len(body)))
        conn.endheaders(body)
        resp = conn.getresponse()
        return resp.status, resp.read()
    finally:
        conn.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewsec")
    ws = Workspace.create(root / "ws")
    (root / "secret.txt").write_text("SECRET-7f3a", encoding="utf-8")
    evidence = ws.root / "evidence" / "s1"
    evidence.mkdir(parents=True)
    (evidence / "note.txt").write_text("inside", encoding="utf-8")
    os.symlink(root / "secret.txt", evidence / "link.txt")
    os.symlink(root, ws.root / "evidence" / "escape")
    proc, url, token = start_view(ws.root)
    try:
        yield {"url": url, "token": token, "ws": ws}
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


def test_files_inside_the_workspace_are_served(server):
    status, body = request(server["url"], "GET", "/files/evidence/s1/note.txt")
    assert (status, body) == (200, b"inside")


@pytest.mark.parametrize("path", [
    "/files/../secret.txt",
    "/files/evidence/../../secret.txt",
    "/files/%2e%2e/secret.txt",
    "/files/evidence/%2e%2e/%2e%2e/secret.txt",
    "/files/evidence/s1/link.txt",          # a symlink to a file outside
    "/files/evidence/escape/secret.txt",    # a symlinked directory outside
    "/files//etc/passwd",
    "/files/.locks/SESSIONS.lock",
])
def test_path_traversal_is_refused(server, path):
    status, body = request(server["url"], "GET", path)
    assert status in (403, 404), (path, status)
    assert b"SECRET-7f3a" not in body and b"root:" not in body


def test_a_signal_needs_the_token_and_goes_through_send_signal(server):
    ws = server["ws"]
    payload = json.dumps({"kind": "pause", "reason": "maintenance"}).encode()
    h = {"Content-Type": "application/json"}
    assert request(server["url"], "POST", "/api/signal", body=payload, headers=h)[0] == 403
    assert request(server["url"], "POST", "/api/signal", body=payload,
                   headers={**h, "X-PhyAgentOS-Token": "wrong"})[0] == 403
    assert ws.read("RUNTIME_SIGNAL").data.signals == []
    status, body = request(server["url"], "POST", "/api/signal", body=payload,
                           headers={**h, "X-PhyAgentOS-Token": server["token"]})
    assert status == 200 and json.loads(body)["kind"] == "pause"
    assert [(s.kind, s.reason) for s in ws.read("RUNTIME_SIGNAL").data.signals] == [("pause", "maintenance")]
    # The same validation as `phyagentos signal`: a cancel of an unknown session is refused.
    bad = json.dumps({"kind": "cancel", "session_id": "nope"}).encode()
    status, body = request(server["url"], "POST", "/api/signal", body=bad,
                           headers={**h, "X-PhyAgentOS-Token": server["token"]})
    assert status == 400 and b"unknown session" in body
    assert len(ws.read("RUNTIME_SIGNAL").data.signals) == 1


def test_a_foreign_host_header_is_refused_on_loopback(server):
    status, _ = request(server["url"], "GET", "/", headers={"Host": "evil.example:8787"})
    assert status == 421
    status, body = request(server["url"], "GET", "/")
    assert status == 200 and server["token"].encode() in body  # loopback pages carry the token


def test_beyond_loopback_the_page_never_carries_the_token():
    policy = AccessPolicy(host="0.0.0.0")
    assert not policy.loopback and policy.token_in_page() == ""
    assert policy.host_allowed("robot-lab.local:8787")
    assert policy.token_ok(policy.token) and not policy.token_ok("") and not policy.token_ok(None)


def test_safe_path_refuses_absolute_hidden_and_escaping_paths(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "f.txt").write_text("x")
    assert safe_path(tmp_path, "a/f.txt") == (tmp_path / "a" / "f.txt").resolve()
    for bad in ("/etc/passwd", "../x", "a/../../x", ".hidden/f", "a\\f.txt", "", "a/f.txt\x00"):
        with pytest.raises(ViewError):
            safe_path(tmp_path, bad)
