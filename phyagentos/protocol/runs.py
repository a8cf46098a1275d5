"""The run registry: submitted goal graphs that an Agent process keeps driving.

Layout::

    runs/<run_id>/RUN.md            RunRecord (Markdown + YAML, like every protocol document)
    runs/<run_id>/goal_graph.yaml   the graph exactly as validated at submit
    runs/.active/<run_id>           empty marker while the run is active

Listing active runs scans ``runs/.active/`` only, so finished runs cost nothing.
The marker is created after RUN.md is written and removed after RUN.md records the
end, so a crash can leave a finished run listed (harmless: the agent sees it is done
and removes the marker) but never loses an active one.
"""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path

from phyagentos.errors import ProtocolError

from .atomic import atomic_write_text
from .codec import Document, read_document, write_document
from .schemas import SESSION_ID_PATTERN, RunRecord, utc_now_iso

__all__ = ["RunRegistry", "GRAPH_FILE", "RUN_FILE"]

log = logging.getLogger(__name__)

GRAPH_FILE = "goal_graph.yaml"
RUN_FILE = "RUN.md"
_RUN_ID = re.compile(SESSION_ID_PATTERN)

_PROSE = (
    "# Run {run_id}\n\n"
    "A goal graph submitted to this workspace. `goal_graph.yaml` next to this file is the\n"
    "graph as validated at submit; the Agent plane compiles its nodes into sessions and\n"
    "verifies them until every node is terminal. Text outside the YAML block is kept.\n\n"
)


class RunRegistry:
    """``runs/`` of one workspace.

    Args:
        root: the workspace root.
    """

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.dir = Path(root) / "runs"
        self.active_dir = self.dir / ".active"

    def run_dir(self, run_id: str) -> Path:
        """``runs/<run_id>/``.

        Raises:
            ProtocolError: ``run_id`` is not a file-name-safe id.
        """
        if not _RUN_ID.match(run_id or ""):
            raise ProtocolError(f"invalid run id {run_id!r}: expected letters, digits, '.', '_' or '-'")
        return self.dir / run_id

    def register(self, record: RunRecord, graph_text: str) -> RunRecord:
        """Record a new run and its graph; the run becomes active.

        Raises:
            ProtocolError: a run with this id exists, or the id is invalid.
        """
        directory = self.run_dir(record.run_id)
        try:
            directory.mkdir(parents=True)
        except FileExistsError:
            raise ProtocolError(f"run {record.run_id!r} already exists ({directory})") from None
        atomic_write_text(directory / GRAPH_FILE, graph_text)
        record = record.model_copy(update={"graph_file": f"runs/{record.run_id}/{GRAPH_FILE}", "state": "active"})
        write_document(Document(prefix=_PROSE.format(run_id=record.run_id), data=record, path=directory / RUN_FILE))
        self.active_dir.mkdir(parents=True, exist_ok=True)
        (self.active_dir / record.run_id).touch()
        log.info("registered run %s", record.run_id)
        return record

    def load(self, run_id: str) -> RunRecord:
        """The RunRecord of ``run_id``.

        Raises:
            ProtocolError: unknown run.
            DocumentError: RUN.md is malformed.
        """
        path = self.run_dir(run_id) / RUN_FILE
        try:
            return read_document(path, RunRecord).data
        except FileNotFoundError:
            raise ProtocolError(f"unknown run {run_id!r} (no {path})") from None

    def graph_path(self, run_id: str) -> Path:
        return self.run_dir(run_id) / GRAPH_FILE

    def active_ids(self) -> list[str]:
        """Ids of active runs, sorted (run ids sort by submit time)."""
        try:
            return sorted(n for n in os.listdir(self.active_dir) if not n.startswith("."))
        except FileNotFoundError:
            return []

    def finish(self, run_id: str, *, succeeded: bool) -> RunRecord:
        """Mark ``run_id`` finished and drop it from the active list (idempotent)."""
        path = self.run_dir(run_id) / RUN_FILE
        doc = read_document(path, RunRecord)
        if doc.data.state != "finished":
            doc.data = doc.data.model_copy(update={"state": "finished", "finished_at": utc_now_iso(),
                                                   "succeeded": succeeded})
            write_document(doc)
        (self.active_dir / run_id).unlink(missing_ok=True)
        return doc.data
