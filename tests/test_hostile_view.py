"""Hostile input to ``phyagentos view`` (issue 33), over real HTTP against a real
``phyagentos view`` process: links out of the workspace inside evidence directories,
special files, over-long paths, deep JSON, oversized bodies."""

from __future__ import annotations

import concurrent.futures
import json
import os
import signal
import socket
import subprocess
import time

import pytest
from hostile_tally import counted, tally
from supervisor_util import submit
from test_view_browser import start_view
from test_view_security import request

from phyagentos.protocol import Workspace

SECRET = "SECRET-outside-4d1c"


def _stop(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()


def _rss_kib(pid: int) -> int:
    for line in open(f"/proc/{pid}/status", encoding="ascii"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile")
    outside = root / "outside"
    outside.mkdir()
    (outside / "tree.json").write_text(json.dumps({"secret": SECRET}), encoding="utf-8")
    (outside / "snap.yaml").write_text(f"entities: [{{name: {SECRET}}}]\nsim_time_s: 1\n", encoding="utf-8")
    (outside / "bundle.yaml").write_text(f"secret: {SECRET}\n", encoding="utf-8")
    (outside / "events.yaml").write_text(f"- {{code: x, message: {SECRET}}}\n", encoding="utf-8")
    (outside / f"{SECRET}.txt").write_text("x", encoding="utf-8")
    ws = Workspace.create(root / "ws")
    for sid in ("s-linkfile", "s-linkdir", "s-fifo", "s-deep"):
        submit(ws, sid)
    ev = ws.root / "evidence"
    # 1. files inside a real evidence directory that link outside the workspace
    d = ev / "s-linkfile"
    d.mkdir(parents=True)
    os.symlink(outside / "tree.json", d / "tree.json")
    os.symlink(outside / "snap.yaml", d / "terminal.yaml")
    os.symlink(outside / "bundle.yaml", d / "bundle.yaml")
    os.symlink(outside / "events.yaml", d / "events.yaml")
    # 2. the whole evidence directory is a link outside
    os.symlink(outside, ev / "s-linkdir")
    # 3. FIFOs where the runner writes regular files
    d = ev / "s-fifo"
    d.mkdir()
    for name in ("tree.json", "bundle.yaml", "events.yaml", "terminal.yaml", "trace.jsonl", "frames.npz"):
        os.mkfifo(d / name)
    # 4. deeply nested JSON where the runner writes JSON
    d = ev / "s-deep"
    d.mkdir()
    (d / "tree.json").write_text("[" * 100_000 + "]" * 100_000, encoding="utf-8")
    (d / "trace.jsonl").write_text('{"kind": "proprio", "stamp_s": 0.0}\n' + "[" * 100_000 + "]" * 100_000 + "\n",
                                   encoding="utf-8")
    proc, url, token = start_view(ws.root)
    try:
        yield {"url": url, "token": token, "ws": ws, "proc": proc}
    finally:
        _stop(proc)


@pytest.mark.parametrize("sid", ["s-linkfile", "s-linkdir"])
@pytest.mark.parametrize("route", ["/api/tree/{}", "/fragment/session/{}", "/fragment/tree/{}", "/api/signals/{}",
                                   "/api/frames/{}", "/session/{}", "/api/scene/{}.png?frame=0"])
@counted("view (HTTP): evidence links out")
def test_evidence_links_out_of_the_workspace_are_never_followed(hostile, route, sid):
    status, body = request(hostile["url"], "GET", route.format(sid))
    assert SECRET.encode() not in body, (route, sid, status, body[:300])
    assert status < 500 or route.startswith("/api/scene"), (route, sid, status, body[:300])


@counted("view (HTTP): evidence links out")
def test_a_refused_evidence_link_says_why(hostile):
    status, body = request(hostile["url"], "GET", "/api/tree/s-linkfile")
    assert status == 403 and b"outside" in body
    status, body = request(hostile["url"], "GET", "/api/tree/s-linkdir")
    assert status == 403 and b"outside the workspace" in body
    status, body = request(hostile["url"], "GET", "/fragment/session/s-linkdir")
    assert status == 200 and b"outside the workspace" in body  # the panel carries the refusal


def test_fifos_in_an_evidence_directory_never_block_the_server(hostile):
    routes = ["/api/tree/s-fifo", "/fragment/tree/s-fifo", "/fragment/session/s-fifo", "/api/signals/s-fifo",
              "/api/frames/s-fifo", "/files/evidence/s-fifo/tree.json"]

    def get(route):
        return route, request(hostile["url"], "GET", route)

    # More concurrent requests than the server's worker threads: a blocking open() would hang it.
    started = time.monotonic()
    with concurrent.futures.ThreadPoolExecutor(16) as pool:
        results = list(pool.map(get, routes * 12))
    assert time.monotonic() - started < 60
    for _route, (status, _body) in results:  # each request one case, counted before any assertion
        tally("view (HTTP): FIFOs in evidence", status < 500)
    for route, (status, body) in results:
        assert status < 500, (route, status, body[:200])
    tree_status = dict(results)["/api/tree/s-fifo"][0]
    assert tree_status == 422
    assert request(hostile["url"], "GET", "/")[0] == 200  # still answering


@pytest.mark.parametrize("path", ["/files/" + "a" * 5000, "/files/" + "a/" * 3000 + "x", "/files/evidence/" + "b" * 300,
                                  "/files/" + "%61" * 2000])
@counted("view (HTTP): long paths")
def test_a_very_long_path_is_refused_not_an_error(hostile, path):
    status, body = request(hostile["url"], "GET", path)
    assert status in (403, 404, 414), (status, body[:200])


@pytest.mark.parametrize("body", [b"[" * 200_000, b"{\"a\":" * 100_000 + b"1" + b"}" * 100_000, b"\xff\xfe", b"not json",
                                  b"[1, 2]", b"\"kind\""])
@counted("view (HTTP): signal bodies")
def test_a_malformed_or_deeply_nested_signal_body_is_a_400(hostile, body):
    try:
        status, answer = request(hostile["url"], "POST", "/api/signal", body=body,
                                 headers={"Content-Type": "application/json", "X-PhyAgentOS-Token": hostile["token"]})
    except (BrokenPipeError, ConnectionResetError):
        # over the body limit: the server answered 413 and closed while the body was still going out
        assert len(body) > 64 * 1024
        status, answer = 413, b""
    assert status in (400, 413), (status, answer[:200])
    assert request(hostile["url"], "GET", "/")[0] == 200
    assert hostile["ws"].read("RUNTIME_SIGNAL").data.signals == []


@counted("view (HTTP): oversized bodies")
def test_an_oversized_body_is_refused_before_it_is_buffered(hostile):
    host, port = hostile["url"].removeprefix("http://").split(":")
    before = _rss_kib(hostile["proc"].pid)
    # Content-Length announces 256 MB: refused at once, nothing read.
    with socket.create_connection((host, int(port)), timeout=30) as s:
        s.sendall(("POST /api/signal HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                   f"X-PhyAgentOS-Token: {hostile['token']}\r\nContent-Length: {256 * 1024 * 1024}\r\n\r\n").encode()
                  + b"[" * 1024)
        answer = s.recv(4096)
    assert answer.startswith(b"HTTP/1.1 413"), answer[:200]
    # Chunked, no length: refused as soon as the bytes received pass the limit; 32 MB sent.
    with socket.create_connection((host, int(port)), timeout=30) as s:
        s.sendall(("POST /api/signal HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                   f"X-PhyAgentOS-Token: {hostile['token']}\r\nTransfer-Encoding: chunked\r\n\r\n").encode())
        chunk = b"%x\r\n%s\r\n" % (1024 * 1024, b" " * (1024 * 1024))
        try:
            for _ in range(32):
                s.sendall(chunk)
        except (BrokenPipeError, ConnectionResetError):
            pass  # the server answered and closed
        s.settimeout(30)
        try:
            answer = s.recv(4096)
        except ConnectionResetError:
            answer = b"reset"
    assert answer.startswith(b"HTTP/1.1 413") or answer == b"reset", answer[:200]
    assert _rss_kib(hostile["proc"].pid) - before < 64 * 1024  # under 64 MiB more, not the body
    assert hostile["ws"].read("RUNTIME_SIGNAL").data.signals == []
    assert request(hostile["url"], "GET", "/")[0] == 200


@pytest.mark.parametrize("route", ["/api/tree/s-deep", "/fragment/tree/s-deep", "/api/signals/s-deep",
                                   "/fragment/session/s-deep"])
@counted("view (HTTP): nested evidence JSON")
def test_deeply_nested_evidence_json_is_refused_not_a_500(hostile, route):
    status, body = request(hostile["url"], "GET", route)
    assert status < 500, (route, status, body[:300])
    if route == "/api/tree/s-deep":
        assert status == 422 and b"nested" in body
