"""What changed, per panel: cheap fingerprints that decide which fragments a page re-fetches.

The event stream (``/events``) wakes on any inotify event in the watched directories
(a running session rewrites its file several times a second). Re-rendering every panel
of every open page on each wake-up cost the index 31 % of a core with one run and a
whole core with 1,000 runs. Instead, each page names its fragments (``?f=URL``); on a
wake-up the stream computes a fingerprint per fragment from ``stat``/``scandir`` only
(never parsing a document) and sends the list of fragments whose fingerprint changed.

Also here: :data:`FINISHED_STATES`, the one set of session states after which a
session's recording is final (the page's 3D panel scrubs the recording instead of
following the live checkpoint).
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from phyagentos.protocol import TERMINAL_STATES, Workspace

__all__ = ["FINISHED_STATES", "Tracker", "fingerprint"]

#: Session states in which the runner no longer acts: the protocol's terminal states
#: (``succeeded``, ``failed``, ``replanned``, ``timed_out``, ``cancelled``, ``rejected``)
#: plus ``awaiting_replan`` (the attempt is over, its evidence final, the planner decides).
FINISHED_STATES: frozenset[str] = frozenset((*TERMINAL_STATES, "awaiting_replan"))

_ID = r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}"


def _stat(path: Path) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_mtime_ns, st.st_size)


def _names(path: Path) -> tuple[str, ...] | None:
    try:
        return tuple(sorted(os.listdir(path)))
    except OSError:
        return None


def _signals(ws: Workspace) -> Any:
    return _stat(ws.root / "RUNTIME_SIGNAL.md")


def _session_file(ws: Workspace, sid: str) -> Any:
    active = ws.root / "sessions" / f"{sid}.md"
    st = _stat(active)
    return ("active", st) if st is not None else ("gone",)  # archived: final until the next wake finds it


def _fp_overview(ws: Workspace, m: re.Match, q: dict) -> Any:
    return (_signals(ws), _names(ws.root / "sessions" / ".index"))


def _fp_runs(ws: Workspace, m: re.Match, q: dict) -> Any:
    # A run appears (runs/), starts or ends (runs/.active): that is when a row changes.
    return (_names(ws.root / "runs"), _names(ws.root / "runs" / ".active"))


def _fp_run(ws: Workspace, m: re.Match, q: dict) -> Any:
    return (_signals(ws), _names(ws.root / "sessions" / ".index"), _stat(ws.root / "runs" / m[1] / "RUN.md"))


def _fp_session(ws: Workspace, m: re.Match, q: dict) -> Any:
    ev = ws.root / "evidence" / m[1]
    return (_signals(ws), _session_file(ws, m[1]), _names(ev), _stat(ev / "bundle.yaml"), _stat(ev / "events.yaml"),
            _stat(ws.root / "ENVIRONMENT.md"))


def _fp_tree(ws: Workspace, m: re.Match, q: dict) -> Any:
    return _stat(ws.root / "evidence" / m[1] / "tree.json")


def _fp_memory(ws: Workspace, m: re.Match, q: dict) -> Any:
    return tuple(_stat(ws.root / f) for f in ("LESSONS.md", "KNOWLEDGE.md", "SKILL.md"))


_RULES: list[tuple[re.Pattern, Callable[[Workspace, re.Match, dict], Any]]] = [
    (re.compile(r"^/fragment/overview$"), _fp_overview),
    (re.compile(r"^/fragment/runs$"), _fp_runs),
    (re.compile(rf"^/fragment/run/({_ID})$"), _fp_run),
    (re.compile(rf"^/fragment/session/({_ID})$"), _fp_session),
    (re.compile(rf"^/fragment/(?:tree|signals)/({_ID})$"), _fp_tree),
    (re.compile(r"^/fragment/memory$"), _fp_memory),
]


class _Always:
    """A fingerprint that never equals anything: the fragment is re-fetched on every change."""

    def __eq__(self, other: object) -> bool:
        return False

    __hash__ = None  # type: ignore[assignment]


def fingerprint(ws: Workspace, url: str) -> Any:
    """A value that changes whenever fragment ``url`` may render differently (stat-only).

    Unknown fragments get a value that never compares equal (always re-fetched).
    """
    parts = urlsplit(url)
    for pattern, fn in _RULES:
        m = pattern.match(parts.path)
        if m:
            return fn(ws, m, parse_qs(parts.query))
    return _Always()


class Tracker:
    """Fingerprints of one page's fragments; :meth:`changed` returns those that changed since the last call.

    Args:
        ws: the workspace.
        urls: the page's fragment URLs (at most 16 kept; only ``/fragment/...`` ones).
    """

    MAX_URLS = 16

    def __init__(self, ws: Workspace, urls: list[str]) -> None:
        self.ws = ws
        self.urls = [u for u in dict.fromkeys(urls) if u.startswith("/fragment/")][: self.MAX_URLS]
        self._last = {u: fingerprint(ws, u) for u in self.urls}

    def changed(self) -> list[str]:
        out = []
        for u in self.urls:
            fp = fingerprint(self.ws, u)
            if fp != self._last[u]:
                out.append(u)
            self._last[u] = fp
        return out
