"""The run registry: submitted goal graphs that an Agent process keeps driving.

Layout::

    runs/<run_id>/RUN.md            RunRecord (Markdown + YAML, like every protocol document)
    runs/<run_id>/goal_graph.yaml   the graph exactly as validated at submit
    runs/.active/<run_id>           empty marker while the run is active
    runs/.failed/<run_id>           why a run was set aside (its stored documents no longer
                                    validate); written instead of RUN.md when RUN.md is the bad file
    runs/.targets/<target>          the run whose world the target holds (one run at a time)

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

__all__ = ["RunRegistry", "GRAPH_FILE", "RUN_FILE", "inside_workspace"]

log = logging.getLogger(__name__)

GRAPH_FILE = "goal_graph.yaml"
RUN_FILE = "RUN.md"
_RUN_ID = re.compile(SESSION_ID_PATTERN)
#: Longest error text kept for a run set aside (characters).
_MAX_ERROR_CHARS = 2000


def inside_workspace(path: Path, root: Path) -> Path:
    """``path`` if it (after following symlinks) stays inside ``root``.

    Raises:
        ProtocolError: a symlink (or ``..``) leads out of the workspace; the message names
            the link, never the content of what it points to.
    """
    resolved = Path(os.path.realpath(path))
    if not resolved.is_relative_to(Path(os.path.realpath(root))):
        raise ProtocolError(f"{path} leads out of the workspace (a symlink to a file outside {root}); "
                            "refusing to read it")
    return path

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
        self.root = Path(root)
        self.dir = Path(root) / "runs"
        self.active_dir = self.dir / ".active"
        self.failed_dir = self.dir / ".failed"
        self.owners_dir = self.dir / ".targets"

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
            return read_document(inside_workspace(path, self.root), RunRecord).data
        except FileNotFoundError:
            raise ProtocolError(f"unknown run {run_id!r} (no {path})") from None

    def graph_path(self, run_id: str) -> Path:
        """``runs/<run_id>/goal_graph.yaml``.

        Raises:
            ProtocolError: invalid run id, or the file is a symlink out of the workspace.
        """
        return inside_workspace(self.run_dir(run_id) / GRAPH_FILE, self.root)

    def exists(self, run_id: str) -> bool:
        """Whether ``run_id`` was ever registered here."""
        try:
            return self.run_dir(run_id).is_dir()
        except ProtocolError:
            return False

    def set_aside(self, run_id: str, error: str) -> None:
        """End ``run_id`` as failed because its stored documents no longer validate.

        The error goes into RUN.md when RUN.md itself still validates (a malformed file
        is never overwritten), and always into ``runs/.failed/<run_id>``; the run leaves
        the active list so every other run goes on. Idempotent.
        """
        error = error if len(error) <= _MAX_ERROR_CHARS else error[:_MAX_ERROR_CHARS] + " ..."
        self.failed_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.failed_dir / run_id, error + "\n")
        try:
            path = inside_workspace(self.run_dir(run_id) / RUN_FILE, self.root)
            doc = read_document(path, RunRecord)
            if doc.data.state != "finished":
                doc.data = doc.data.model_copy(update={"state": "finished", "finished_at": utc_now_iso(),
                                                       "succeeded": False, "error": error})
                write_document(doc)
        except (ProtocolError, OSError) as exc:
            log.debug("run %s: RUN.md left as it is (%s)", run_id, exc)
        (self.active_dir / run_id).unlink(missing_ok=True)
        log.warning("run %s set aside: %s", run_id, error)

    def failure(self, run_id: str) -> str | None:
        """Why ``run_id`` was set aside, or ``None``."""
        try:
            return (self.failed_dir / run_id).read_text(encoding="utf-8", errors="replace").strip() or None
        except (FileNotFoundError, NotADirectoryError):
            return None

    def recent_ids(self, limit: int = 10) -> list[str]:
        """Ids of the most recent runs that are no longer active, newest first."""
        active = set(self.active_ids())
        try:
            names = [n for n in os.listdir(self.dir) if not n.startswith(".") and n not in active and _RUN_ID.match(n)]
        except FileNotFoundError:
            return []
        return sorted(names, reverse=True)[:limit]

    # -- a target's world belongs to one run at a time ----------------------

    def world_owner(self, target: str) -> str | None:
        """The active run holding ``target``'s world, or ``None`` (a finished owner lapses)."""
        try:
            owner = (self.owners_dir / target).read_text(encoding="utf-8").strip()
        except (FileNotFoundError, NotADirectoryError):
            return None
        return owner if owner and (self.active_dir / owner).exists() else None

    def take_world(self, target: str, run_id: str) -> str | None:
        """Give ``target``'s world to ``run_id`` unless another active run holds it.

        Returns ``None`` when ``run_id`` holds it now, else the id of the run holding it
        (the caller queues ``run_id``'s sessions on that target until it finishes).
        Callers serialise calls per target (the supervisor holds the target's lock).
        """
        owner = self.world_owner(target)
        if owner is not None and owner != run_id:
            return owner
        if owner != run_id:
            self.owners_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.owners_dir / target, run_id + "\n")
        return None

    def active_ids(self) -> list[str]:
        """Ids of active runs, sorted (run ids sort by submit time)."""
        try:
            return sorted(n for n in os.listdir(self.active_dir) if not n.startswith("."))
        except FileNotFoundError:
            return []

    def finish(self, run_id: str, *, succeeded: bool) -> RunRecord:
        """Mark ``run_id`` finished and drop it from the active list (idempotent)."""
        path = inside_workspace(self.run_dir(run_id) / RUN_FILE, self.root)
        doc = read_document(path, RunRecord)
        if doc.data.state != "finished":
            doc.data = doc.data.model_copy(update={"state": "finished", "finished_at": utc_now_iso(),
                                                   "succeeded": succeeded})
            write_document(doc)
        (self.active_dir / run_id).unlink(missing_ok=True)
        return doc.data
