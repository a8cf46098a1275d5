"""The edge: the Runtime plane next to a robot, kept in step with the fleet over zenoh.

An edge runs the ordinary :class:`~phyagentos.runtime.supervisor.WatchdogSupervisor` on its
own workspace (the authority for its targets' sessions, TARGETS.md, ENVIRONMENT.md and
evidence) and, beside it, the replication: every session write is published, documents
are published when they change, and queryables answer catch-up, submits, verdicts,
signals and frame requests. The network never becomes a control bus: the supervisor
reads only local files, and a lost link changes nothing but what :mod:`.link_loss` says.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from pathlib import Path
from typing import Any

from phyagentos.errors import FleetError, ProtocolError
from phyagentos.protocol import SessionRecord, Workspace
from phyagentos.protocol.atomic import atomic_write_text
from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor

from .catchup import catchup_answer, submits_dir
from .config import FleetConfig
from .doc_revisions import EdgeDocRevisions
from .link import FleetLink
from .link_loss import LINK_LOST_REASON, STALE_REASON, SubmitTicket, submit_is_stale
from .ownership import AGENT_STATES, EDGE_DOCUMENTS
from .presence import Presence
from .replication import encode_session, frames_dir_files

__all__ = ["FleetEdge"]

log = logging.getLogger(__name__)

_SIGNALS = ("cancel", "pause", "resume", "estop", "clear_estop")
_STARTED = frozenset({"running", "finalizing"})


class FleetEdge:
    """One edge of the fleet.

    Args:
        workspace_dir: the edge's workspace (created if needed).
        config: the fleet configuration (``name`` and ``connect`` required).
        supervisor_config: tunables of the supervisor (its ``targets`` are set to the
            targets this edge owns).

    Raises:
        FleetError: no name or endpoint, a target in ``config.targets`` that TARGETS.md
            lacks, or the router refuses this edge.
    """

    def __init__(self, workspace_dir: str | Path, config: FleetConfig, *,
                 supervisor_config: SupervisorConfig | None = None) -> None:
        if not config.name or not config.connect:
            raise FleetError("an edge needs a name and a router endpoint (--name, --connect or fleet.yaml)")
        self.name = config.name
        self.config = config
        self._local = threading.local()
        self.workspace = Workspace.create(workspace_dir)
        listed = {t.name: t for t in self.workspace.read("TARGETS").data.targets}
        if config.targets is not None:
            unknown = [t for t in config.targets if t not in listed]
            if unknown:
                raise FleetError(f"edge {self.name}: targets {unknown} are not in {self.workspace.path('TARGETS')}; "
                                 f"listed: {', '.join(sorted(listed))}")
            self.targets = list(config.targets)
        else:
            self.targets = [n for n, t in listed.items() if t.enabled]
        base = supervisor_config or SupervisorConfig()
        self.supervisor = WatchdogSupervisor(
            self.workspace, owner=f"edge:{self.name}",
            config=SupervisorConfig(**{**base.__dict__, "targets": tuple(self.targets)}))
        self.supervisor.claim_gate = self._claim_gate
        self.agents = Presence(on_change=lambda name, alive: self.supervisor.watcher.notify())
        self._tickets: dict[str, SubmitTicket] = self._load_tickets()
        self._outbox: queue.Queue[SessionRecord | None] = queue.Queue()
        self._doc_stamp: dict[str, tuple] = {}
        self.doc_revisions = EdgeDocRevisions(self.workspace.root / "fleet" / "doc_revisions.json")
        self._lock = threading.Lock()
        self._halted: set[str] = set()
        self._stop = threading.Event()
        self.link = self._open_link(config)
        self.workspace.on_session_write = self._outbox.put
        k = self.link.keys
        self.link.queryable(k.edge_q(self.name, "catchup"), self._on_catchup)
        self.link.queryable(k.edge_q(self.name, "submit"), self._on_submit)
        self.link.queryable(k.edge_q(self.name, "verdict"), self._on_verdict)
        self.link.queryable(k.edge_q(self.name, "signal"), self._on_signal)
        self.link.queryable(k.edge_q(self.name, "frames") + "/*", self._on_frames)
        self.link.subscribe(k.estop_all(), self._on_estop_all)
        self.link.watch_alive(k.agent_alive("*"), self.agents.update)
        self.link.token(k.edge_alive(self.name))
        self._threads = [threading.Thread(target=self._publisher, name="fleet-publish", daemon=True),
                         threading.Thread(target=self._link_watch, name="fleet-link-loss", daemon=True)]
        for t in self._threads:
            t.start()
        log.info("edge %s up: targets %s", self.name, ", ".join(self.targets))

    @property
    def ws(self) -> Workspace:
        """This thread's Workspace object of the edge's workspace (the supervisor keeps its own:
        a Workspace's caches are not shared between threads)."""
        ws = getattr(self._local, "ws", None)
        if ws is None:
            ws = self._local.ws = Workspace.open(self.workspace.root)
        return ws

    def _open_link(self, config: FleetConfig) -> FleetLink:
        # An edge outlives its router: it waits for one (a robot must not need the network to boot).
        while True:
            try:
                return FleetLink(config, mode="client")
            except FleetError as exc:
                log.warning("edge %s: %s; retrying", self.name, exc)
                time.sleep(1.0)

    # -- tickets (ws/fleet/submits/<id>.json) -----------------------------------------

    def _load_tickets(self) -> dict[str, SubmitTicket]:
        out = {}
        directory = submits_dir(self.ws)
        for path in directory.glob("*.json") if directory.is_dir() else ():
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
                data.pop("run_id", None)
                out[path.stem] = SubmitTicket(**data)
            except (OSError, ValueError, TypeError) as exc:
                log.warning("edge %s: ticket %s unreadable (%s): its session is held", self.name, path, exc)
        return out

    def _save_ticket(self, ticket: SubmitTicket, run_id: str) -> None:
        directory = submits_dir(self.ws)
        directory.mkdir(parents=True, exist_ok=True)
        atomic_write_text(directory / f"{ticket.session_id}.json", json.dumps({**ticket.to_json(), "run_id": run_id}))

    # -- the supervisor's claim gate and the link-loss policy ---------------------------

    def _claim_gate(self, session_id: str, ident: Any) -> bool:
        ticket = self._tickets.get(session_id)
        if ticket is None:
            # a session with no fleet ticket was submitted at the edge itself: the edge's own
            # user is current by definition; one whose ticket file was lost is held
            return not (submits_dir(self.ws) / f"{session_id}.json").exists()
        if self.agents.alive(ticket.agent):
            return True
        gone = self.agents.gone_for(ticket.agent)
        if (gone is not None and gone > self.config.submit_ttl_s and session_id not in self._halted
                and self._signal("cancel", session_id=session_id, reason=STALE_REASON)):
            self._halted.add(session_id)
        return False

    def _link_watch(self) -> None:
        while not self._stop.wait(0.1):
            try:
                self._check_link_loss()
            except Exception:
                log.exception("edge %s: link-loss check failed", self.name)

    def _check_link_loss(self) -> None:
        for sid, state, _ in self.ws.active_sessions():
            ticket = self._tickets.get(sid)
            if ticket is None or sid in self._halted:
                continue
            gone = self.agents.gone_for(ticket.agent)
            if gone is None or gone < self.config.link_timeout_s:
                continue
            # not actuating yet: nothing starts without its agent; actuating: the declared policy
            halt = state in ("claimed", "preflight_checking") or (state in _STARTED
                                                                  and ticket.link_loss == "halt_and_hold")
            if not halt:
                continue
            why = LINK_LOST_REASON if state in _STARTED else STALE_REASON
            log.warning("edge %s: agent %s gone %.1f s; session %s (%s): %s", self.name, ticket.agent, gone, sid,
                        state, why)
            if self._signal("cancel", session_id=sid, reason=why):
                self._halted.add(sid)

    def _signal(self, kind: str, **kw: Any) -> bool:
        try:
            self.ws.send_signal(kind, issued_by=f"edge:{self.name}", **kw)
        except ProtocolError as exc:  # e.g. a session whose hint is there and its file not yet
            log.debug("edge %s: signal %s not sent: %s", self.name, kind, exc)
            return False
        finally:
            self.supervisor.watcher.notify()
        return True

    # -- queryables --------------------------------------------------------------------

    def _on_catchup(self, key: str, data: Any) -> dict:
        data = data if isinstance(data, dict) else {}
        return catchup_answer(self.ws, edge=self.name, targets=self.targets, run_ids=data.get("run_ids"),
                              session_ids=data.get("session_ids"), doc_revisions=self.doc_revisions)

    def _on_submit(self, key: str, data: Any) -> dict:
        """A submit: ``{agent, issued_at, link_loss, record, deps: [records]}``."""
        if not isinstance(data, dict) or "record" not in data:
            return {"status": "refused", "error": "a submit carries agent, issued_at, link_loss, record, deps"}
        if submit_is_stale(float(data.get("issued_at", 0.0)), self.config.submit_ttl_s):
            return {"status": "stale", "error": f"submit older than {self.config.submit_ttl_s} s: not started"}
        try:
            record = SessionRecord.model_validate(data["record"])
        except ValueError as exc:
            return {"status": "refused", "error": f"invalid session record: {exc}"}
        if record.target not in self.targets:
            return {"status": "refused", "error": f"edge {self.name} does not own target {record.target!r}; "
                                                  f"owned: {', '.join(self.targets)}"}
        policy = data.get("link_loss") or self.config.link_loss
        if policy not in ("finish", "halt_and_hold"):
            return {"status": "refused", "error": f"link_loss {policy!r}; valid: 'finish', 'halt_and_hold'"}
        with self._lock:
            if self.ws.find_session_path(record.session_id) is not None:
                stored = self.ws.load_session(record.session_id)
                return {"status": "duplicate", **encode_session(self.ws, stored, edge=self.name)}
            for dep in data.get("deps", []):
                self.ws.install_replica(SessionRecord.model_validate(dep))
            ticket = SubmitTicket(session_id=record.session_id, agent=str(data.get("agent", "")),
                                  issued_at=float(data["issued_at"]), accepted_at=time.time(), link_loss=policy)
            self._save_ticket(ticket, record.run_id)
            self._tickets[record.session_id] = ticket
            try:
                stored = self.ws.submit_session(record)  # the one validated submit path
            except ProtocolError as exc:
                return {"status": "refused", "error": str(exc)}
        self.supervisor.watcher.notify()
        return {"status": "accepted", **encode_session(self.ws, stored, edge=self.name)}

    def _on_verdict(self, key: str, data: Any) -> dict:
        """The agent's transitions of a session (verification and verdict)."""
        record = SessionRecord.model_validate(data["record"])
        if record.state not in AGENT_STATES:
            return {"status": "refused", "error": f"state {record.state!r} is the edge's to write"}
        written = self.ws.install_replica(record)
        stored = self.ws.load_session(record.session_id)
        return {"status": "installed" if written else "current", "rev": [len(stored.transitions), stored.updated_at]}

    def _on_signal(self, key: str, data: Any) -> dict:
        kind = (data or {}).get("kind")
        if kind not in _SIGNALS:
            return {"status": "refused", "error": f"signal {kind!r}; valid: {', '.join(_SIGNALS)}"}
        try:
            sig = self.ws.send_signal(kind, session_id=data.get("session_id"), reason=data.get("reason", ""),
                                             issued_by=f"fleet:{data.get('by', 'agent')}")
        except ProtocolError as exc:
            return {"status": "refused", "error": str(exc)}
        self.supervisor.watcher.notify()
        return {"status": "sent", "signal": sig.id}

    def _on_estop_all(self, key: str, data: Any) -> None:
        self._signal("estop", reason=f"fleet e-stop: {(data or {}).get('reason', '')}"[:200])

    def _on_frames(self, key: str, data: Any) -> dict:
        sid = key.rsplit("/", 1)[-1]
        return {"session_id": sid, "files": frames_dir_files(self.ws, sid)}

    # -- publications ------------------------------------------------------------------

    def _publisher(self) -> None:
        while not self._stop.is_set():
            try:
                record = self._outbox.get(timeout=0.5)
            except queue.Empty:
                record = None
            try:
                if record is not None:
                    self.link.put(self.link.keys.session(self.name, record.session_id),
                                  encode_session(self.ws, record, edge=self.name))
                self._publish_docs()
            except Exception:
                log.exception("edge %s: publication failed", self.name)

    def _publish_docs(self) -> None:
        for name in EDGE_DOCUMENTS:
            path = self.ws.path(name)
            try:
                st = path.stat()
            except FileNotFoundError:
                continue
            stamp = (st.st_mtime_ns, st.st_size, st.st_ino)
            if self._doc_stamp.get(name) == stamp:
                continue
            self._doc_stamp[name] = stamp
            text = path.read_text(encoding="utf-8")
            self.link.put(self.link.keys.doc(self.name, name),
                          {"edge": self.name, "name": name, "text": text, "targets": self.targets,
                           "rev": list(self.doc_revisions.revision(name, text, owned=self.targets if name == "TARGETS" else ()))})

    # -- running -----------------------------------------------------------------------

    def serve(self) -> None:
        """Supervise until :meth:`request_stop` (the supervisor's own loop)."""
        self.supervisor.serve()

    def request_stop(self, *, immediate: bool = False) -> None:
        self.supervisor.request_stop(immediate=immediate)

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2)
        self.link.close()
        self.supervisor.close()
