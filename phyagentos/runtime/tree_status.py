"""Live behaviour-tree status of a running session: ``evidence/<session>/tree.json``.

The BuiltinSkillRuntime calls a :class:`TreeStatusPublisher` after every tick (and once
more when the tree stops). The publisher writes at most ``max_rate_hz`` times per second
of wall time (default 10 Hz): every node of the tree (name, behaviour class, kind,
status ``running``/``success``/``failure``/``invalid``, feedback message, blackboard
keys it reads and writes) and the current values of those blackboard keys, made
JSON-safe (small arrays as rounded lists, large ones as their shape). The write is
atomic (temporary file + rename) without fsync: the file is a view for people
(``phyagentos view``), never a source of truth, so it never pays for durability.

Nodes are a flat list in depth-first order with the index of their parent, so a tree
of any size serialises without recursion limits and a reader can rebuild it.

The publisher also keeps the tree's history: on every tick whose statuses differ from the
previous tick's, ``[tick, simulated time (s, from ``sim_clock``), one letter per node]``
(``R`` running, ``S`` success, ``F`` failure, ``I`` invalid, nodes in the same depth-first
order). It is bounded (:data:`MAX_HISTORY` entries; beyond, every other entry is dropped,
the first and the last kept, and ``decimated`` counts it) and written once, with the final
state, to ``tree_history.json``: the view replays it under its timeline cursor.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import threading
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import py_trees

from phyagentos.protocol.atomic import atomic_write_bytes

__all__ = ["TreeStatusPublisher", "tree_status", "json_safe", "HISTORY_FILE", "MAX_HISTORY"]

logger = logging.getLogger(__name__)

_STATUS = {
    py_trees.common.Status.RUNNING: "running",
    py_trees.common.Status.SUCCESS: "success",
    py_trees.common.Status.FAILURE: "failure",
    py_trees.common.Status.INVALID: "invalid",
}
#: One letter per status in the tree history.
_CODE_NAMES = {"running": "R", "success": "S", "failure": "F", "invalid": "I"}
_CODE = {status: _CODE_NAMES[name] for status, name in _STATUS.items()}
#: The tree history file, next to tree.json.
HISTORY_FILE = "tree_history.json"
#: Most status changes kept in the history (beyond: every other one is dropped, first and last kept).
MAX_HISTORY = 5000
#: Arrays with more elements than this are summarised by shape and dtype.
_MAX_ARRAY = 32
#: Containers longer than this are cut (with a count of what was left out).
_MAX_ITEMS = 32


def json_safe(value: Any, *, depth: int = 0) -> Any:
    """A JSON-serialisable summary of a blackboard value.

    Numbers are rounded to 5 significant decimals; numpy arrays of at most 32
    elements become nested lists, larger ones ``{"shape", "dtype"}``; mappings and
    sequences are cut at 32 items; anything else becomes a short ``repr``.
    """
    if value is None or isinstance(value, (bool, str)):
        return value if not isinstance(value, str) else value[:200]
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        f = float(value)
        return round(f, 5) if math.isfinite(f) else str(f)
    if isinstance(value, np.ndarray):
        if value.size <= _MAX_ARRAY and value.dtype.kind in "biu":
            return value.tolist()
        if value.size <= _MAX_ARRAY and value.dtype.kind == "f":
            if not np.all(np.isfinite(value)):
                return json_safe(value.tolist(), depth=depth + 1)
            return np.round(value, 5).tolist()
        return {"shape": list(value.shape), "dtype": str(value.dtype)}
    if depth > 3:
        return repr(value)[:80]
    if isinstance(value, dict):
        items = list(value.items())
        out = {str(k): json_safe(v, depth=depth + 1) for k, v in items[:_MAX_ITEMS]}
        if len(items) > _MAX_ITEMS:
            out["..."] = f"{len(items) - _MAX_ITEMS} more"
        return out
    if isinstance(value, (list, tuple)):
        out = [json_safe(v, depth=depth + 1) for v in value[:_MAX_ITEMS]]
        if len(value) > _MAX_ITEMS:
            out.append(f"... {len(value) - _MAX_ITEMS} more")
        return out
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {"type": type(value).__name__,
                **{f.name: json_safe(getattr(value, f.name), depth=depth + 1) for f in dataclasses.fields(value)[:12]}}
    return repr(value)[:200]


def _kind(node: py_trees.behaviour.Behaviour) -> str:
    if isinstance(node, py_trees.composites.Composite):
        return "composite"
    if isinstance(node, py_trees.decorators.Decorator):
        return "decorator"
    return "leaf"


def _keys(node: py_trees.behaviour.Behaviour) -> tuple[list[str], list[str]]:
    reads: set[str] = set()
    writes: set[str] = set()
    for client in getattr(node, "blackboards", []):
        reads |= set(client.read) | set(client.exclusive)
        writes |= set(client.write) | set(client.exclusive)
    return sorted(reads), sorted(writes)


def tree_status(root: py_trees.behaviour.Behaviour) -> dict[str, Any]:
    """The tree under ``root`` as plain data: ``{"nodes": [...], "blackboard": {...}}``.

    Each node is ``{id, parent, name, type, kind, status, message, reads, writes}``
    (depth-first order; ``parent`` is the index of the parent node, ``None`` for the root).
    ``blackboard`` maps every key a node reads or writes to its JSON-safe value
    (keys not yet written are absent).
    """
    nodes: list[dict[str, Any]] = []
    used: set[str] = set()
    stack: list[tuple[py_trees.behaviour.Behaviour, int | None]] = [(root, None)]
    while stack:
        node, parent = stack.pop()
        reads, writes = _keys(node)
        used.update(reads)
        used.update(writes)
        nodes.append({"id": len(nodes), "parent": parent, "name": node.name, "type": type(node).__name__,
                      "kind": _kind(node), "status": _STATUS.get(node.status, str(node.status)),
                      "message": (node.feedback_message or "")[:200], "reads": reads, "writes": writes})
        me = len(nodes) - 1
        stack.extend((child, me) for child in reversed(list(node.children)))
    storage = py_trees.blackboard.Blackboard.storage
    board = {key: json_safe(storage[key]) for key in sorted(used) if key in storage}
    return {"nodes": nodes, "blackboard": board}


class TreeStatusPublisher:
    """Writes ``tree.json`` for one session, at most ``max_rate_hz`` times per second.

    Call it with the tree's root after every tick; ``final=True`` always writes (the
    tree's last state) and waits until it is on disk. In between, the caller only builds
    the document (the nodes' statuses must be read at that tick); serialising and the
    atomic write happen on a writer thread that always writes the newest pending
    document, so file-system latency never reaches the control loop. ``cost_s``,
    ``calls`` and ``writes`` let a benchmark report the cost per tick.

    Args:
        path: the JSON file (its directory must exist).
        session_id: written into the file.
        max_rate_hz: upper bound on writes per second of wall time (default 10).
        clock: monotonic clock in seconds (tests inject one).
    """

    def __init__(self, path: str | Path, *, session_id: str, max_rate_hz: float = 10.0,
                 clock: Callable[[], float] = time.monotonic, sim_clock: Callable[[], float | None] | None = None,
                 max_history: int = MAX_HISTORY) -> None:
        if max_rate_hz <= 0:
            raise ValueError(f"max_rate_hz must be positive, got {max_rate_hz}")
        self.path = Path(path)
        self.session_id = session_id
        self.period_s = 1.0 / max_rate_hz
        self._clock = clock
        self._last: float | None = None
        self.ticks = 0
        self.writes = 0
        self.published = 0
        self.calls = 0
        self.cost_s = 0.0
        self._pending: dict[str, Any] | None = None
        self._wake = threading.Condition()
        self._thread: threading.Thread | None = None
        self._sim_clock = sim_clock
        self.max_history = max(2, int(max_history))
        self.history: list[list[Any]] = []  # [tick, simulated time s or None, statuses (one letter per node)]
        self.history_decimated = 0
        self._last_codes: str | None = None

    def _write(self, doc: dict[str, Any]) -> bool:
        try:
            atomic_write_bytes(self.path, json.dumps(doc, separators=(",", ":")).encode(), durable=False)
        except (OSError, TypeError, ValueError) as exc:
            logger.warning("tree status %s not written: %s", self.path, exc)
            return False
        self.writes += 1
        return True

    def _run(self) -> None:
        while True:
            with self._wake:
                while self._pending is None:
                    self._wake.wait()
                doc, self._pending = self._pending, None
            if doc.get("final"):
                return
            self._write(doc)

    def __call__(self, root: py_trees.behaviour.Behaviour, *, final: bool = False) -> bool:
        """Record a tick; publish ``tree.json`` if due (or ``final``). Returns True if published.

        Never raises for an I/O problem (logged): the view must not be able to fail a session.
        """
        started = time.perf_counter()
        self.calls += 1
        if not final:
            self.ticks += 1
        self._remember(root, final)
        now = self._clock()
        if not final and self._last is not None and now - self._last < self.period_s:
            self.cost_s += time.perf_counter() - started
            return False
        self._last = now
        doc = {"session_id": self.session_id, "tick": self.ticks, "final": final,
               "published_at": time.time(), **tree_status(root)}
        self.published += 1
        if final:
            self._stop()
            written = self._write(doc)
            self._write_history(doc)
        else:
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=f"tree-{self.session_id}", daemon=True)
                self._thread.start()
            with self._wake:
                self._pending = doc
                self._wake.notify()
            written = True
        self.cost_s += time.perf_counter() - started
        return written

    def _remember(self, root: py_trees.behaviour.Behaviour, final: bool) -> None:
        """Append this tick's statuses to the history when they differ from the previous tick's."""
        codes = []  # depth-first, children in order: the order of tree_status()'s nodes
        stack = [root]
        while stack:
            node = stack.pop()
            codes.append(_CODE.get(node.status, "?"))
            stack.extend(reversed(node.children))
        codes = "".join(codes)
        if codes == self._last_codes and not final:
            return
        self._last_codes = codes
        sim = None
        if self._sim_clock is not None:
            try:
                value = self._sim_clock()
                sim = round(float(value), 4) if value is not None else None
            except (TypeError, ValueError, AttributeError):
                sim = None
        self.history.append([self.ticks, sim, codes])
        if len(self.history) > self.max_history:  # keep it bounded: every other change, first and last kept
            last = self.history[-1]
            self.history = self.history[:-1:2] + [last]
            self.history_decimated += 1

    def _write_history(self, doc: dict[str, Any]) -> None:
        """``tree_history.json`` next to ``tree.json``: the node list and every change of status."""
        hist = {"session_id": self.session_id, "ticks": self.ticks, "codes": {v: k for k, v in _CODE_NAMES.items()},
                "nodes": [{"id": n["id"], "parent": n["parent"], "name": n["name"], "kind": n["kind"]}
                          for n in doc["nodes"]],
                "decimated": self.history_decimated, "max_entries": self.max_history, "entries": self.history}
        try:
            atomic_write_bytes(self.path.with_name(HISTORY_FILE), json.dumps(hist, separators=(",", ":")).encode(),
                               durable=False)
        except (OSError, TypeError, ValueError) as exc:
            logger.warning("tree history %s not written: %s", self.path.with_name(HISTORY_FILE), exc)

    def _stop(self) -> None:
        if self._thread is not None:
            with self._wake:
                self._pending = {"final": True}
                self._wake.notify()
            self._thread.join()
            self._thread = None
