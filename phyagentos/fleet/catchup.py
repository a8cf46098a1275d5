"""Catch-up after a (re)connect: the edge's ``catchup`` queryable answers with its
documents and every session submitted through the fleet; the agent installs them by the
convergence rule (:mod:`.replication`), so whatever publications a partition swallowed
are made good in one query."""

from __future__ import annotations

import json
import logging
from pathlib import Path

from phyagentos.errors import ProtocolError
from phyagentos.protocol import Workspace

from .doc_revisions import EdgeDocRevisions
from .ownership import EDGE_DOCUMENTS
from .replication import encode_session, install_session

__all__ = ["apply_catchup", "catchup_answer", "submits_dir"]

log = logging.getLogger(__name__)


def submits_dir(workspace: Workspace) -> Path:
    """``ws/fleet/submits/``: one JSON ticket per session submitted through the fleet."""
    return workspace.root / "fleet" / "submits"


def catchup_answer(workspace: Workspace, *, edge: str, targets: list[str], run_ids: list[str] | None = None,
                   session_ids: list[str] | None = None, doc_revisions: EdgeDocRevisions | None = None) -> dict:
    """The edge's answer: owned targets, documents (text, with their revisions when
    ``doc_revisions`` numbers them: :mod:`.doc_revisions`) and fleet sessions (encoded),
    those of ``run_ids`` and/or ``session_ids`` when given."""
    docs, revs = {}, {}
    for name in EDGE_DOCUMENTS:
        try:
            docs[name] = workspace.path(name).read_text(encoding="utf-8")
        except OSError:
            continue
        if doc_revisions is not None:
            revs[name] = list(doc_revisions.revision(name, docs[name], owned=targets if name == "TARGETS" else ()))
    sessions = []
    directory = submits_dir(workspace)
    tickets = sorted(directory.glob("*.json")) if directory.is_dir() else []
    if session_ids is not None:
        tickets = [directory / f"{sid}.json" for sid in session_ids if (directory / f"{sid}.json").is_file()]
    for ticket in tickets:
        try:
            info = json.loads(ticket.read_text(encoding="utf-8"))
            if run_ids is not None and info.get("run_id") not in run_ids:
                continue
            record = workspace.load_session(ticket.stem)
        except (ProtocolError, OSError, ValueError) as exc:
            log.debug("catch-up: %s skipped (%s)", ticket.stem, exc)
            continue
        sessions.append(encode_session(workspace, record, edge=edge))
    return {"edge": edge, "targets": targets, "docs": docs, "doc_revisions": revs, "sessions": sessions}


def apply_catchup(workspace: Workspace, answer: dict) -> int:
    """Install every session of an edge's answer; returns how many were written."""
    written = 0
    for msg in answer.get("sessions", []):
        try:
            written += install_session(workspace, msg)
        except ProtocolError as exc:
            log.warning("catch-up from %s: a session not installed: %s", answer.get("edge"), exc)
    return written
