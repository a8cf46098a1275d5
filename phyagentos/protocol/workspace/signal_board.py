"""RUNTIME_SIGNAL.md of a Workspace: operator signals sent, acknowledged by supervisors and
compacted (mixed into :class:`~phyagentos.protocol.Workspace`)."""

from __future__ import annotations

import getpass
import json
import logging
import socket
from collections.abc import Iterable

from phyagentos.errors import ProtocolError, format_choices

from ..atomic import append_lines_durably
from ..schemas import RuntimeSignalDoc, Signal, SignalAck, utc_now_iso
from ..signals import SIGNAL_KINDS, new_signal_id
from .parts import WorkspaceParts
from .states import ts_key

log = logging.getLogger(__name__)


class SignalBoard(WorkspaceParts):
    """RUNTIME_SIGNAL.md: send, acknowledge, compact. Mixed into :class:`~phyagentos.protocol.Workspace`."""

    def send_signal(self, kind: str, *, session_id: str | None = None, reason: str = "",
                    issued_by: str | None = None, all_sessions: bool = False) -> Signal:
        """Append a signal to RUNTIME_SIGNAL.md: the one validated way to signal the runtime.

        Args:
            kind: one of ``cancel``, ``pause``, ``resume``, ``estop``, ``clear_estop``.
            session_id: the session a ``cancel`` addresses (must exist).
            all_sessions: a ``cancel`` without ``session_id`` must say so explicitly;
                it cancels every session submitted before the signal.
            issued_by: who sends it (default ``user@host``).

        Raises:
            ProtocolError: unknown kind, a cancel without a known session (or
                ``all_sessions``), or a session id on a workspace-wide signal.
        """
        if kind not in SIGNAL_KINDS:
            raise ProtocolError(f"unknown signal kind {kind!r}; valid: {format_choices(SIGNAL_KINDS)}")
        if kind == "cancel":
            if session_id is None and not all_sessions:
                raise ProtocolError("a cancel signal needs a session id (or all_sessions=True to cancel everything)")
            if session_id is not None:
                if self.find_session_path(session_id) is None:
                    raise ProtocolError(f"cannot cancel unknown session {session_id!r}")
        elif session_id is not None or all_sessions:
            raise ProtocolError(f"a {kind!r} signal applies to the whole runtime; it takes no session id")
        if issued_by is None:
            issued_by = f"{getpass.getuser()}@{socket.gethostname()}"
        signal = Signal(id=new_signal_id(), kind=kind, session_id=session_id, issued_by=issued_by,
                        issued_at=utc_now_iso(), reason=reason)

        def apply(doc: RuntimeSignalDoc) -> None:
            doc.signals.append(signal)
            self._compact_signals(doc)

        self.update("RUNTIME_SIGNAL", apply)
        log.info("signal %s %s%s", signal.id, kind, f" session {session_id}" if session_id else "")
        return signal

    def ack_signals(self, acks: Iterable[SignalAck]) -> None:
        """Append supervisors' acknowledgements to RUNTIME_SIGNAL.md (one write)."""
        acks = list(acks)
        if not acks:
            return

        def apply(doc: RuntimeSignalDoc) -> None:
            doc.handled.extend(acks)
            self._compact_signals(doc)

        self.update("RUNTIME_SIGNAL", apply)

    def _compact_signals(self, doc: RuntimeSignalDoc) -> None:
        """Move old, handled signals (and their acks) to log/signals-YYYY-MM.jsonl.

        Never moved: the latest pause/resume and estop/clear_estop (they are the
        current state) and cancels nobody has acknowledged yet.
        """
        overflow = len(doc.signals) - self.SIGNAL_MAX
        if overflow <= 0:
            return
        keep: set[str] = set()
        for group in (("pause", "resume"), ("estop", "clear_estop")):
            latest = [s for s in doc.signals if s.kind in group]
            if latest:
                keep.add(latest[-1].id)
        acked = {a.signal_id for a in doc.handled}
        movable = [s for s in doc.signals
                   if s.id not in keep and (s.kind != "cancel" or s.id in acked)][:overflow]
        if not movable:
            return
        moved = {s.id for s in movable}
        lines_by_month: dict[str, list[str]] = {}
        for sig in movable:
            record = {"signal": sig.model_dump(mode="json"),
                      "handled": [a.model_dump(mode="json") for a in doc.handled if a.signal_id == sig.id]}
            month = ts_key(sig.issued_at).strftime("%Y-%m")
            lines_by_month.setdefault(month, []).append(json.dumps(record, ensure_ascii=False) + "\n")
        for month, lines in sorted(lines_by_month.items()):
            append_lines_durably(self.log_dir / f"signals-{month}.jsonl", lines)
        doc.signals = [s for s in doc.signals if s.id not in moved]
        doc.handled = [a for a in doc.handled if a.signal_id not in moved]

