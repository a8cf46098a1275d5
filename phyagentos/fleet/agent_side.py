"""The Agent plane's side of the fleet: replicas of every edge's documents and sessions in
the agent's workspace, and the forwarding of the agent's submits and verdicts.

The agent runs unchanged on its own workspace (:class:`~phyagentos.agent.agent_loop.AgentLoop`):
its compile step submits sessions through :meth:`Workspace.submit_session`; this bridge
sends each pending session to the edge that owns its target (the edge submits it through
the same validated path, idempotently by session id), installs the edge's publications
(claim, start, evidence, ``awaiting_verification``) by the convergence rule, and sends the
agent's verification transitions back. TARGETS.md of the agent's workspace is the union of
the edges' (the selector and the graph check see the whole fleet); each edge's documents
are kept as they are under ``ws/fleet/edges/<edge>/``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from phyagentos.errors import FleetError, ProtocolError
from phyagentos.protocol import SessionRecord, Workspace, WorkspaceWatcher
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.protocol.codec import parse_document
from phyagentos.protocol.schemas import TargetsDoc, TargetSpec

from .catchup import apply_catchup
from .doc_revisions import ReplicaDocRevisions
from .link import FleetLink
from .ownership import AGENT_STATES, TargetMap
from .presence import Presence
from .replication import install_session, revision, write_frames

__all__ = ["FleetAgentBridge"]

log = logging.getLogger(__name__)


class FleetAgentBridge:
    """Replication and forwarding between the agent's workspace and the fleet's edges.

    Args:
        workspace: the agent's workspace.
        link: an open :class:`FleetLink` (client).
        name: this agent's name (its liveliness token; edges hold its sessions to it).
        link_loss: the declared link-loss policy sent with every submit (``finish`` or
            ``halt_and_hold``).
        poll_s: longest sleep of the forwarder between checks.
        resync_s: a session the edge holds whose replica has not changed this long is asked
            for again (anti-entropy: a publication lost without a partition is made good).
    """

    def __init__(self, workspace: Workspace, link: FleetLink, *, name: str, link_loss: str = "finish",
                 poll_s: float = 0.2, resync_s: float = 2.0) -> None:
        self._root = workspace.root
        self._local = threading.local()
        self._local.ws = workspace
        self.link = link
        self.name = name
        self.link_loss = link_loss
        self.poll_s = poll_s
        self.resync_s = resync_s
        self._seen_at: dict[str, float] = {}  # session id -> when the edge last told us of it
        self._next_resync = time.monotonic() + resync_s
        self.targets = TargetMap()
        self.edges = Presence(on_change=self._edge_changed)
        self._edge_targets: dict[str, list[dict]] = {}
        self.doc_revisions = ReplicaDocRevisions(workspace.root / "fleet" / "edges")
        self._confirmed: dict[str, tuple[int, str]] = {}  # session id -> revision the edge is known to hold
        self._catchup_due: set[str] = set()
        self._finished: set[str] = set()  # terminal on both sides: nothing left to forward
        self._refused: set[str] = set()
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._watcher = WorkspaceWatcher(workspace.root, dirs=("sessions", "sessions/.index"))
        self._kicked: list[SessionRecord] = []
        #: called after a replica was installed (the agent loop's wake-up)
        self.on_installed: Callable[[], None] | None = None
        self.stats = {"submits": 0, "verdicts": 0, "installed": 0, "catchups": 0, "refused": 0}
        self.last_catchup_s: dict[str, float] = {}
        k = link.keys
        link.subscribe(k.session("*", "*"), self._on_session)
        link.subscribe(k.doc("*", "*"), self._on_doc)
        link.token(k.agent_alive(name))
        link.watch_alive(k.edge_alive("*"), self.edges.update)
        self._thread = threading.Thread(target=self._forwarder, name="fleet-forward", daemon=True)
        self._thread.start()

    @property
    def workspace(self) -> Workspace:
        """This thread's Workspace object of the agent's workspace (its caches are per thread)."""
        ws = getattr(self._local, "ws", None)
        if ws is None:
            ws = self._local.ws = Workspace.open(self._root)
        return ws

    # -- edges and their documents -------------------------------------------------------

    def _edge_changed(self, edge: str, alive: bool) -> None:
        with self._lock:
            if alive:
                self._catchup_due.add(edge)
        self._watcher.notify()

    def wait_for_targets(self, targets: set[str], timeout_s: float) -> None:
        """Block until every target in ``targets`` is owned by an edge present now.

        Raises:
            FleetError: not within ``timeout_s`` (the message names the missing targets).
        """
        deadline = time.monotonic() + timeout_s
        while True:
            with self._lock:
                owned = {t for t, e in self.targets.as_dict().items() if self.edges.alive(e)}
                due = bool(self._catchup_due)
            if targets <= owned and not due:
                return
            if time.monotonic() > deadline:
                raise FleetError(f"no edge present owns target(s) {sorted(targets - owned)} after {timeout_s:.0f} s; "
                                 f"edges present: {sorted(self.edges.names()) or 'none'}; owned: "
                                 f"{sorted(owned) or 'none'}")
            self._watcher.notify()
            time.sleep(0.05)

    def _install_targets(self, edge: str, text: str, owned: list[str]) -> None:
        doc = parse_document(text, TargetsDoc, path=f"<{edge}>/TARGETS.md")
        specs = [t.model_dump(mode="json") for t in doc.data.targets if t.name in owned]
        edge_dir = self.workspace.root / "fleet" / "edges" / edge
        edge_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(edge_dir / "TARGETS.md", text)
        with self._lock:
            self.targets.drop(edge)
            self.targets.add(edge, owned)
            self._edge_targets[edge] = specs
            union = [s for e in sorted(self._edge_targets) for s in self._edge_targets[e]]

        def apply(targets_doc: TargetsDoc) -> None:
            targets_doc.targets = [TargetSpec.model_validate(s) for s in union]

        self.workspace.update("TARGETS", apply)

    def _on_doc(self, key: str, data: Any) -> None:
        """Install an edge document (a publication or a catch-up answer's) by the rule of
        :mod:`.doc_revisions`: only a revision newer than the one held."""
        edge, name = data["edge"], data["name"]
        rev = data.get("rev")
        rev = (int(rev[0]), int(rev[1])) if isinstance(rev, (list, tuple)) and len(rev) == 2 else None

        def install() -> None:
            if name == "TARGETS":
                self._install_targets(edge, data["text"], list(data.get("targets", [])))
            else:
                edge_dir = self.workspace.root / "fleet" / "edges" / edge
                edge_dir.mkdir(parents=True, exist_ok=True)
                atomic_write_text(edge_dir / f"{name}.md", data["text"])

        self.doc_revisions.offer(edge, name, rev, install)

    def catch_up(self, edge: str) -> int:
        """Query ``edge``'s catch-up and install it; returns the sessions written.

        Raises:
            FleetError: the edge did not answer.
        """
        t0 = time.perf_counter()
        # the sessions of the runs this workspace drives (none before the first submit)
        answer = self.link.query_one(self.link.keys.edge_q(edge, "catchup"),
                                     {"run_ids": self.workspace.runs.active_ids()}, timeout_s=5.0)
        if answer is None:
            raise FleetError(f"edge {edge} did not answer its catch-up query")
        revs = answer.get("doc_revisions") or {}
        for name, text in answer.get("docs", {}).items():
            self._on_doc("", {"edge": edge, "name": name, "text": text, "targets": answer.get("targets", []),
                              "rev": revs.get(name)})
        with self._lock:
            written = apply_catchup(self.workspace, answer)
            for msg in answer.get("sessions", []):
                self._note_edge_rev(msg)
        self.stats["catchups"] += 1
        self.stats["installed"] += written
        self.last_catchup_s[edge] = time.perf_counter() - t0
        if written:
            log.info("catch-up from %s: %d session(s) converged", edge, written)
        return written

    # -- sessions ----------------------------------------------------------------------

    def _note_edge_rev(self, msg: dict) -> None:
        sid = msg["record"]["session_id"]
        if sid in self._finished:
            return
        rev = tuple(msg["rev"])
        self._seen_at[sid] = time.monotonic()
        if sid not in self._confirmed or rev > self._confirmed[sid]:
            self._confirmed[sid] = rev  # type: ignore[assignment]

    def kick(self, record: SessionRecord) -> None:
        """The agent wrote ``record`` (its workspace's ``on_session_write``): forward it now,
        without waiting for the workspace watcher."""
        if record.state == "pending" or record.state in AGENT_STATES:
            with self._lock:
                self._kicked.append(record)
            self._watcher.notify()

    def _on_session(self, key: str, msg: Any) -> None:
        with self._lock:
            self._note_edge_rev(msg)
            try:
                written = install_session(self.workspace, msg)
            except ProtocolError as exc:
                log.warning("replica of %s refused: %s", msg.get("record", {}).get("session_id"), exc)
                return
        if written:
            self.stats["installed"] += 1
            if self.on_installed is not None:
                self.on_installed()

    def _deps_of(self, record: SessionRecord) -> list[dict]:
        if not record.depends_on:
            return []
        done = self.workspace.list_sessions(states=["succeeded"], run_id=record.run_id)
        return [r.model_dump(mode="json", warnings=False) for r in done if r.node in record.depends_on]

    def _submit(self, record: SessionRecord) -> None:
        edge = self.targets.get(record.target)
        if edge is None or not self.edges.alive(edge):
            return  # waits: no edge owns the target now
        reply = self.link.query_one(self.link.keys.edge_q(edge, "submit"), {
            "agent": self.name, "issued_at": time.time(), "link_loss": self.link_loss,
            "record": record.model_dump(mode="json", warnings=False), "deps": self._deps_of(record)}, timeout_s=3.0)
        if reply is None:
            return  # retried on the next pass (idempotent by session id)
        status = reply.get("status")
        if status in ("accepted", "duplicate"):
            self.stats["submits"] += status == "accepted"
            self._on_session("", reply)
        elif status != "stale":  # a stale submit is sent again, fresh, while the agent still wants it
            self._refused.add(record.session_id)
            self.stats["refused"] += 1
            log.warning("edge %s refused session %s: %s", edge, record.session_id, reply.get("error", status))

    def _send_verdict(self, record: SessionRecord) -> None:
        edge = self.targets.get(record.target)
        if edge is None or not self.edges.alive(edge):
            return
        reply = self.link.query_one(self.link.keys.edge_q(edge, "verdict"),
                                    {"record": record.model_dump(mode="json", warnings=False)}, timeout_s=3.0)
        if reply is not None and reply.get("status") in ("installed", "current"):
            with self._lock:
                if record.is_terminal:
                    self._confirmed.pop(record.session_id, None)
                    self._finished.add(record.session_id)
                else:
                    self._confirmed[record.session_id] = revision(record)
            self.stats["verdicts"] += reply.get("status") == "installed"

    def _forward_once(self) -> None:
        with self._lock:
            due, self._catchup_due = self._catchup_due, set()
        for edge in due:
            try:
                self.catch_up(edge)
            except FleetError as exc:
                log.warning("%s", exc)
                with self._lock:
                    self._catchup_due.add(edge)
        with self._lock:
            kicked, self._kicked = self._kicked, []
        # the agent's own writes, first and without a scan: submits before verdicts (a submit
        # carries the verdicts of its dependencies), and only the latest write of a session
        latest = {r.session_id: r for r in kicked}
        for record in latest.values():
            if record.state == "pending" and record.session_id not in self._confirmed:
                self._submit(record)
        for record in latest.values():
            if record.state in AGENT_STATES and record.session_id in self._confirmed \
                    and revision(record) > self._confirmed[record.session_id]:
                self._send_verdict(record)
        ws = self.workspace
        for sid, state, ident in ws.active_sessions():
            if self.targets.get(ident.target) is None:
                continue
            if state == "pending" and sid not in self._confirmed and sid not in self._refused:
                try:
                    record = ws.load_session(sid)
                except ProtocolError:
                    continue  # its hint is written before its file: the next pass sends it
                self._submit(record)
        # the agent's verification transitions (and verdicts, archived at once) go back
        for rec in self._unconfirmed_agent_writes():
            self._send_verdict(rec)
        if time.monotonic() >= self._next_resync:
            self._next_resync = time.monotonic() + self.resync_s
            self._resync()

    def _resync(self) -> None:
        """Ask each edge again for the sessions it holds (edge-phase states) that have not
        changed here for ``resync_s``: the convergence rule makes a repeat harmless."""
        now = time.monotonic()
        quiet: dict[str, list[str]] = {}
        for sid, state, ident in self.workspace.active_sessions():
            edge = self.targets.get(ident.target)
            if edge is None or state in AGENT_STATES or sid not in self._confirmed:
                continue
            if now - self._seen_at.get(sid, 0.0) >= self.resync_s and self.edges.alive(edge):
                quiet.setdefault(edge, []).append(sid)
        for edge, sids in quiet.items():
            answer = self.link.query_one(self.link.keys.edge_q(edge, "catchup"), {"session_ids": sids}, timeout_s=3.0)
            if answer is None:
                continue
            with self._lock:
                written = apply_catchup(self.workspace, answer)
                for msg in answer.get("sessions", []):
                    self._note_edge_rev(msg)
                for sid in sids:
                    self._seen_at[sid] = now
            if written:
                self.stats["installed"] += written
                self.stats["resynced"] = self.stats.get("resynced", 0) + written
                log.info("resync from %s: %d session(s) converged", edge, written)
                if self.on_installed is not None:
                    self.on_installed()

    def _unconfirmed_agent_writes(self) -> list[SessionRecord]:
        out = []
        for sid, rev in list(self._confirmed.items()):
            try:
                rec = self.workspace.load_session(sid)
            except ProtocolError:
                continue
            if rec.state in AGENT_STATES and revision(rec) > rev:
                out.append(rec)
        return out

    def _forwarder(self) -> None:
        while not self._stop.is_set():
            self._watcher.wait(self.poll_s)
            self._watcher.clear()
            if self._stop.is_set():
                return
            try:
                self._forward_once()
            except Exception:
                log.exception("fleet forwarder pass failed")

    # -- e-stop and frames -------------------------------------------------------------

    def estop(self, reason: str = "") -> list[str]:
        """E-stop every edge present (remote; each edge also keeps its local e-stop).
        Returns the edges that confirmed."""
        self.link.put(self.link.keys.estop_all(), {"reason": reason, "by": self.name})
        confirmed = []
        for edge in sorted(self.edges.names()):
            reply = self.link.query_one(self.link.keys.edge_q(edge, "signal"),
                                        {"kind": "estop", "reason": reason, "by": self.name}, timeout_s=2.0)
            if reply is not None and reply.get("status") == "sent":
                confirmed.append(edge)
        return confirmed

    def fetch_frames(self, session_id: str) -> int:
        """Fetch a session's evidence frames from its edge (on demand); returns files written.

        Raises:
            FleetError: the session's target has no edge present, or it did not answer.
        """
        rec = self.workspace.load_session(session_id)
        edge = self.targets.edge_of(rec.target)
        reply = self.link.query_one(self.link.keys.edge_q(edge, "frames") + f"/{session_id}", None, timeout_s=10.0)
        if reply is None:
            raise FleetError(f"edge {edge} did not send the frames of {session_id}")
        return write_frames(self.workspace, reply.get("files", {}))

    def close(self) -> None:
        self._stop.set()
        self._watcher.notify()
        self._thread.join(timeout=5)
        self._watcher.close()
