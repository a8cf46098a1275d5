"""Monotone revisions of the documents an edge owns (TARGETS, ENVIRONMENT, RUNTIME_SIGNAL).

Session records carry their own revision (:func:`.replication.revision`); the edge's
other documents do not, so the edge numbers them itself.

**Revision.** ``(incarnation, seq)``: ``incarnation`` is the time (ns since the epoch) at
which the edge's workspace first published, kept in ``fleet/doc_revisions.json`` of that
workspace; ``seq`` counts the distinct contents a document has had there (a new
SHA-256 of its text, and for TARGETS of the targets the edge owns, is the next ``seq``). Both only grow for one workspace, and a new
workspace (a replaced edge computer) starts a later incarnation, so tuples compare in
the order the contents were written.

**Rule.** A replica installs an edge document iff its revision is greater than the one it
holds (kept beside the replica in ``fleet/edges/<edge>/revisions.json``). A publication
and a catch-up answer may arrive in either order after a partition; the older one is
refused, so a late catch-up never overwrites a newer copy, and a repeated one changes
nothing.
"""

from __future__ import annotations

import hashlib
import json
import logging
import threading
import time
from pathlib import Path

from phyagentos.protocol.atomic import atomic_write_text

__all__ = ["DocRevision", "EdgeDocRevisions", "ReplicaDocRevisions"]

log = logging.getLogger(__name__)

#: ``(incarnation_ns, seq)``
DocRevision = tuple[int, int]

_MAX_STATE_BYTES = 64 * 1024


def _read_state(path: Path) -> dict:
    """The JSON state at ``path`` ({} when absent); a malformed file is reported and kept."""
    try:
        if path.stat().st_size > _MAX_STATE_BYTES:
            log.warning("%s: larger than %d bytes, ignored (kept as it is)", path, _MAX_STATE_BYTES)
            return {}
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        log.warning("%s: unreadable (%s), ignored (kept as it is)", path, exc)
        return {}
    return data if isinstance(data, dict) else {}


class EdgeDocRevisions:
    """The edge's numbering of its documents' contents (thread-safe).

    Args:
        state_file: ``<edge workspace>/fleet/doc_revisions.json``.
    """

    def __init__(self, state_file: Path) -> None:
        self._path = Path(state_file)
        self._lock = threading.Lock()
        state = _read_state(self._path)
        inc = state.get("incarnation")
        self._incarnation = inc if isinstance(inc, int) and inc > 0 else time.time_ns()
        docs = state.get("docs")
        self._docs: dict[str, dict] = {k: v for k, v in (docs or {}).items()
                                       if isinstance(v, dict) and isinstance(v.get("seq"), int)}

    def revision(self, name: str, text: str, *, owned: tuple[str, ...] | list[str] = ()) -> DocRevision:
        """The revision of document ``name`` with content ``text`` (and, for TARGETS, the
        targets the edge owns: a restart owning others is a new content): the stored one
        when the content is unchanged, else the next ``seq`` (persisted before it is
        returned)."""
        digest = hashlib.sha256("\x00".join([text, *owned]).encode("utf-8")).hexdigest()
        with self._lock:
            entry = self._docs.get(name)
            if entry is not None and entry.get("sha256") == digest:
                return self._incarnation, int(entry["seq"])
            seq = (int(entry["seq"]) if entry else 0) + 1
            self._docs[name] = {"seq": seq, "sha256": digest}
            self._path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self._path, json.dumps({"incarnation": self._incarnation, "docs": self._docs},
                                                     sort_keys=True) + "\n")
            return self._incarnation, seq


class ReplicaDocRevisions:
    """The agent's record of the edge-document revisions it installed (thread-safe).

    Args:
        edges_dir: ``<agent workspace>/fleet/edges`` (one folder per edge).
    """

    def __init__(self, edges_dir: Path) -> None:
        self._dir = Path(edges_dir)
        self._lock = threading.Lock()
        self._held: dict[str, dict[str, DocRevision]] = {}

    def _load(self, edge: str) -> dict[str, DocRevision]:
        held = self._held.get(edge)
        if held is None:
            raw = _read_state(self._dir / edge / "revisions.json")
            held = {k: (int(v[0]), int(v[1])) for k, v in raw.items()
                    if isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) for x in v)}
            self._held[edge] = held
        return held

    def held(self, edge: str, name: str) -> DocRevision | None:
        """The revision of ``edge``'s document ``name`` installed here (None: none yet)."""
        with self._lock:
            return self._load(edge).get(name)

    def offer(self, edge: str, name: str, rev: DocRevision | None, install) -> bool:
        """Install ``edge``'s document ``name`` at revision ``rev`` by calling ``install()``
        iff ``rev`` is greater than the one held; then record it. A publication without a
        revision (an edge of an older release) is installed only while none is held.
        Returns whether it was installed."""
        with self._lock:
            held = self._load(edge)
            have = held.get(name)
            if rev is None:
                if have is not None:
                    log.debug("edge %s: %s without a revision refused (holding %s)", edge, name, have)
                    return False
            elif have is not None and tuple(rev) <= have:
                log.debug("edge %s: %s revision %s refused (holding %s)", edge, name, rev, have)
                return False
            install()
            if rev is not None:
                held[name] = (int(rev[0]), int(rev[1]))
                (self._dir / edge).mkdir(parents=True, exist_ok=True)
                atomic_write_text(self._dir / edge / "revisions.json",
                                  json.dumps({k: list(v) for k, v in held.items()}, sort_keys=True) + "\n")
            return True
