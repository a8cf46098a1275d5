"""Replicated session records and evidence, and the rule replicas converge by.

**Revision.** A session document's revision is ``(len(transitions), updated_at)``.
Transitions are append-only (``Workspace.save_session`` refuses anything else), and one
side writes a session at a time (:mod:`.ownership`), so the revision grows with every
write of either side.

**Convergence rule.** A replica installs an incoming record iff its transitions extend
the local ones (the local list is a prefix) and its revision is greater
(:meth:`Workspace.install_replica`). Publications may be lost, duplicated or reordered
by a partition: a stale or repeated one is refused, a lost one is made good by the next
publication or by the catch-up after a reconnect (:mod:`.catchup`). No transition is lost
(the authority keeps it and republishes), duplicated (a session id is submitted once;
repeated submits are idempotent) or reordered (a record is installed whole, never
merged). Evidence is installed before the record that refers to it.
"""

from __future__ import annotations

import base64
import logging
from pathlib import Path
from typing import Any

from phyagentos.protocol import SessionRecord, Workspace
from phyagentos.protocol.evidence_markers import PENDING_MARKER, WANTED_MARKER

__all__ = ["EVIDENCE_STATES", "encode_session", "evidence_files", "install_session", "revision"]

log = logging.getLogger(__name__)

#: States from which a session's evidence bundle is complete and travels with its record.
EVIDENCE_STATES = frozenset({"awaiting_verification", "verifying", "succeeded", "failed", "awaiting_replan",
                             "replanned", "cancelled", "timed_out", "rejected"})
#: Never replicated: frames travel on demand (the ``frames`` queryable), ground truth never
#: reaches the Agent plane, image markers are the local runner's business.
_SKIP_DIRS = ("frames",)
_SKIP_FILES = frozenset({"ground_truth.yaml", PENDING_MARKER, WANTED_MARKER})
_MAX_EVIDENCE_BYTES = 8 * 1024 * 1024


def revision(record: SessionRecord) -> tuple[int, str]:
    """The record's revision: (number of transitions, ``updated_at``)."""
    return len(record.transitions), record.updated_at


def evidence_files(workspace: Workspace, record: SessionRecord, *, frames: bool = False) -> dict[str, str]:
    """Files of ``record``'s evidence bundles (every attempt), path relative to the
    workspace -> base64 content; frames only with ``frames=True``; never ground truth."""
    out: dict[str, str] = {}
    total = 0
    for attempt in record.attempts:
        if not attempt.evidence:
            continue
        base = workspace.root / attempt.evidence
        if not base.is_dir():
            continue
        for path in sorted(base.rglob("*")):
            if not path.is_file() or path.name in _SKIP_FILES:
                continue
            if (path.relative_to(base).parts[0] in _SKIP_DIRS) != frames:
                continue
            data = path.read_bytes()
            total += len(data)
            if total > _MAX_EVIDENCE_BYTES:
                log.warning("evidence of %s over %d bytes: the rest is fetched on demand", record.session_id,
                            _MAX_EVIDENCE_BYTES)
                return out
            out[str(path.relative_to(workspace.root))] = base64.b64encode(data).decode()
    return out


def encode_session(workspace: Workspace, record: SessionRecord, *, edge: str, with_evidence: bool | None = None) -> dict:
    """The publication of ``record`` (JSON-able): edge, revision, record and, once the
    session reached :data:`EVIDENCE_STATES` (or ``with_evidence``), its evidence files."""
    if with_evidence is None:
        with_evidence = record.state in EVIDENCE_STATES
    n, at = revision(record)
    msg: dict[str, Any] = {"edge": edge, "rev": [n, at], "record": record.model_dump(mode="json", warnings=False)}
    if with_evidence:
        msg["evidence"] = evidence_files(workspace, record)
    return msg


def _write_evidence(workspace: Workspace, files: dict[str, str]) -> None:
    root = workspace.root.resolve()
    for rel, b64 in files.items():
        path = (workspace.root / rel).resolve()
        if root not in path.parents or not str(path.relative_to(root)).startswith("evidence/"):
            log.warning("replicated evidence path %r outside evidence/: ignored", rel)
            continue
        if path.is_file():
            continue  # evidence files are written once
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.replica")
        tmp.write_bytes(base64.b64decode(b64))
        tmp.replace(path)


def install_session(workspace: Workspace, msg: dict) -> bool:
    """Install a publication of :func:`encode_session` into ``workspace`` by the
    convergence rule (evidence first); True if the record was written.

    Raises:
        ProtocolError: the record is invalid.
    """
    record = SessionRecord.model_validate(msg["record"])
    if msg.get("evidence"):
        _write_evidence(workspace, msg["evidence"])
    # the steps between a claim and the hand-over are not fsynced here: the edge holds them
    # durably and a catch-up restores them; the hand-over and every end state are
    return workspace.install_replica(record, durable=record.state in EVIDENCE_STATES or record.state == "pending")


def frames_dir_files(workspace: Workspace, session_id: str) -> dict[str, str]:
    """The frames of ``session_id``'s evidence (for the on-demand ``frames`` queryable)."""
    record = workspace.load_session(session_id)
    return evidence_files(workspace, record, frames=True)


def write_frames(workspace: Workspace, files: dict[str, str]) -> int:
    """Install fetched frames; returns how many files were written."""
    before = sum(1 for rel in files if (Path(workspace.root) / rel).is_file())
    _write_evidence(workspace, files)
    return len(files) - before
