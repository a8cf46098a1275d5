"""The workspace machinery supervisors rely on: state hints, archive, fenced writes, signals, runs."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest

from phyagentos.errors import LeaseError, ProtocolError
from phyagentos.protocol import SessionRecord, SignalAck, Workspace, errorcodes, fold_signals, new_lease, utc_now_iso
from phyagentos.protocol.leases import is_expired, remaining_s, renewed
from phyagentos.protocol.lifecycle import SessionLifecycle
from phyagentos.protocol.schemas import RunRecord

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def ws(tmp_path) -> Workspace:
    return Workspace.create(tmp_path / "ws")


def submit(ws: Workspace, sid: str, *, run_id: str = "run-a", **fields) -> SessionRecord:
    now = utc_now_iso()
    return ws.submit_session(SessionRecord(session_id=sid, run_id=run_id, node=fields.pop("node", sid), skill="noop",
                                           target="franka_tabletop", created_at=now, updated_at=now, **fields))


def fire(ws: Workspace, sid: str, *events: str, lease=None) -> SessionRecord:
    def fn(rec):
        if lease is not None:
            rec.lease = lease
        lc = SessionLifecycle(rec)
        for event in events:
            lc.fire(event)

    return ws.update_session(sid, fn)


def hints(ws: Workspace) -> list[str]:
    return sorted(p.name for p in (ws.root / "sessions" / ".index").iterdir() if not p.name.startswith("."))


def test_state_hints_follow_every_transition_and_vanish_when_the_session_ends(ws):
    submit(ws, "s1")
    assert hints(ws) == ["s1~pending"]
    fire(ws, "s1", "claim", "preflight")
    assert hints(ws) == ["s1~preflight_checking"]
    assert [(sid, state) for sid, state, _ in ws.active_sessions()] == [("s1", "preflight_checking")]
    fire(ws, "s1", "reject")
    assert hints(ws) == [] and ws.active_sessions() == []


def test_terminal_sessions_move_to_the_dated_archive_and_stay_findable(ws):
    submit(ws, "s1")
    submit(ws, "s2", run_id="run-b")
    fire(ws, "s1", "cancel", "cancelled")
    path = ws.find_session_path("s1")
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", path.parent.name) and path.parent.parent.name == "archive"
    assert not (ws.root / "sessions" / "s1.md").exists()
    assert ws.load_session("s1").state == "cancelled"
    assert [r.session_id for r in ws.list_sessions(run_id="run-a")] == ["s1"]
    assert [r.session_id for r in ws.list_sessions(run_id="run-b")] == ["s2"]
    assert [r.session_id for r in ws.list_sessions(states=["cancelled"], run_id="run-a")] == ["s1"]
    assert [r.session_id for r in ws.list_sessions()] == ["s1", "s2"]
    with pytest.raises(ProtocolError, match="already exists"):
        submit(ws, "s1")  # an archived id is still taken


def test_active_sessions_come_oldest_first_with_their_identity(ws):
    for sid in ("c", "a", "b"):
        submit(ws, sid, depends_on=["x"], limits={"queue_timeout_s": 7.0})
    rows = ws.active_sessions("pending")
    assert [sid for sid, _, _ in rows] == ["c", "a", "b"]
    ident = rows[0][2]
    assert ident.depends_on == ("x",) and ident.queue_timeout_s == 7.0 and ident.run_id == "run-a"


def test_sessions_index_is_bounded_with_exact_counts(ws):
    for i in range(30):
        submit(ws, f"p{i:02d}")
    for i in range(25):
        submit(ws, f"t{i:02d}")
        fire(ws, f"t{i:02d}", "cancel", "cancelled")
    fire(ws, "p00", "claim", lease=new_lease("me", ttl_s=30))
    index = ws.read("SESSIONS").data
    assert index.counts == {"pending": 29, "claimed": 1}
    states = [e.state for e in index.sessions]
    assert states.count("claimed") == 1  # leased sessions are always listed
    assert 1 <= states.count("pending") <= ws.INDEX_MAX_WAITING
    assert states.count("cancelled") == ws.INDEX_MAX_TERMINAL
    assert len(states) <= 1 + ws.INDEX_MAX_WAITING + ws.INDEX_MAX_TERMINAL
    claimed = next(e for e in index.sessions if e.state == "claimed")
    assert claimed.owner == "me" and claimed.run_id == "run-a"


def test_fenced_update_refuses_a_stale_lease_token_and_writes_nothing(ws):
    submit(ws, "s1")
    old = new_lease("slow-supervisor", ttl_s=0.01)
    fire(ws, "s1", "claim", lease=old)
    new = new_lease("successor", ttl_s=30)
    ws.update_session("s1", lambda rec: setattr(rec, "lease", new))
    before = ws.find_session_path("s1").read_bytes()
    with pytest.raises(LeaseError, match="successor"):
        ws.update_session("s1", lambda rec: SessionLifecycle(rec).fire("preflight"), token=old.token)
    assert ws.find_session_path("s1").read_bytes() == before
    rec = ws.update_session("s1", lambda rec: SessionLifecycle(rec).fire("preflight"), token=new.token)
    assert rec.state == "preflight_checking"


def test_leases_expire_after_their_margin_and_renewal_keeps_the_token():
    lease = new_lease("a", ttl_s=10, now=100.0)
    assert not is_expired(lease, now=110.0) and is_expired(lease, now=110.5)
    assert is_expired(None) and remaining_s(lease, now=104.0) == pytest.approx(6.0)
    longer = renewed(lease, ttl_s=10, now=105.0)
    assert longer.token == lease.token and longer.expires_at == 115.0
    with pytest.raises(ValueError):
        new_lease("a", ttl_s=0)


def test_a_crash_between_session_file_and_hint_is_repaired_by_the_next_reader(ws):
    submit(ws, "s1")
    fire(ws, "s1", "claim", lease=new_lease("x", ttl_s=30))
    index = ws.root / "sessions" / ".index"
    (index / "s1~claimed").rename(index / "s1~pending")  # what a crash before the rename leaves
    rec = ws.update_session("s1", lambda r: r.state == "pending" or False)  # a claimer that finds it taken
    assert rec.state == "claimed" and hints(ws) == ["s1~claimed"]


def test_reconcile_archives_stranded_terminal_files_and_drops_orphan_hints(ws):
    submit(ws, "s1")
    submit(ws, "s2")
    fire(ws, "s2", "cancel")
    path = ws.root / "sessions" / "s2.md"
    text = path.read_text().replace("state: cancelling", "state: cancelled")
    path.write_text(text)  # a terminal file whose move to the archive was interrupted
    orphan = ws.root / "sessions" / ".index" / "ghost~pending"
    orphan.write_text("{}")
    stale = time.time() - 3600
    import os

    os.utime(orphan, (stale, stale))
    fixed = ws.reconcile()
    assert fixed == {"archived": 1, "orphan_hints": 1} or fixed == {"archived": 1, "hints": 0, "orphan_hints": 1}
    assert hints(ws) == ["s1~pending"] and ws.find_session_path("s2").parent.parent.name == "archive"


def test_archive_catalogue_skips_a_torn_line(ws):
    submit(ws, "s1")
    fire(ws, "s1", "cancel", "cancelled")
    catalogue = ws.root / "sessions" / "archive" / "runs" / "run-a.log"
    with catalogue.open("a") as fh:
        fh.write("\n2026-01-0")  # a power cut in the middle of the next line
    submit(ws, "s2")
    fire(ws, "s2", "cancel", "cancelled")
    assert [r.session_id for r in ws.list_sessions(run_id="run-a")] == ["s1", "s2"]


def test_signals_are_validated_and_folded_in_order(ws):
    submit(ws, "s1")
    with pytest.raises(ProtocolError, match="valid: 'cancel'"):
        ws.send_signal("stop")
    with pytest.raises(ProtocolError, match="needs a session id"):
        ws.send_signal("cancel")
    with pytest.raises(ProtocolError, match="unknown session"):
        ws.send_signal("cancel", session_id="nope")
    with pytest.raises(ProtocolError, match="takes no session id"):
        ws.send_signal("pause", session_id="s1")
    for kind in ("pause", "estop", "resume", "clear_estop", "estop"):
        ws.send_signal(kind, issued_by="op")
    cancel = ws.send_signal("cancel", session_id="s1", issued_by="op")
    state = fold_signals(ws.read("RUNTIME_SIGNAL").data.signals)
    assert not state.paused and state.estopped
    assert state.cancel_for("s1", utc_now_iso()) == cancel and state.cancel_for("s2", utc_now_iso()) is None
    everything = ws.send_signal("cancel", all_sessions=True, issued_by="op")
    state = fold_signals(ws.read("RUNTIME_SIGNAL").data.signals)
    assert state.cancel_for("s9", "2020-01-01T00:00:00Z") == everything
    assert state.cancel_for("s9", "2999-01-01T00:00:00Z") is None  # submitted after the signal


def test_signal_history_is_compacted_but_the_state_it_implies_is_kept(ws, tmp_path):
    ws.SIGNAL_MAX = 5
    submit(ws, "s1")
    first = ws.send_signal("estop", issued_by="op")
    pending_cancel = ws.send_signal("cancel", session_id="s1", issued_by="op")
    acked = []
    for _ in range(6):
        sig = ws.send_signal("pause", issued_by="op")
        acked.append(sig.id)
    ws.ack_signals([SignalAck(signal_id=i, by="sup", at=utc_now_iso(), result="paused") for i in acked])
    ws.send_signal("resume", issued_by="op")
    doc = ws.read("RUNTIME_SIGNAL").data
    ids = [s.id for s in doc.signals]
    assert len(ids) <= ws.SIGNAL_MAX + 1 and first.id in ids and pending_cancel.id in ids
    state = fold_signals(doc.signals)
    assert state.estopped and not state.paused
    archived = [json.loads(line) for f in (ws.root / "log").glob("signals-*.jsonl") for line in f.read_text().splitlines()]
    # only superseded pauses left the file, with whatever acknowledgements they had
    assert archived and all(a["signal"]["kind"] == "pause" for a in archived)
    assert any(a["handled"] for a in archived)


def test_runs_are_registered_listed_and_finished(ws):
    record = RunRecord(run_id="r1", goal_graph="g.yaml", graph_file="", seed=3, submitted_at=utc_now_iso())
    stored = ws.register_run(record, "version: 1\n")
    assert stored.graph_file == "runs/r1/goal_graph.yaml" and (ws.root / stored.graph_file).read_text() == "version: 1\n"
    assert ws.runs.active_ids() == ["r1"]
    with pytest.raises(ProtocolError, match="already exists"):
        ws.register_run(record, "")
    done = ws.runs.finish("r1", succeeded=True)
    assert done.state == "finished" and done.succeeded and ws.runs.active_ids() == []
    assert ws.runs.load("r1").finished_at is not None


def test_every_error_code_and_family_is_documented():
    doc = (ROOT / "docs" / "ERRORS.md").read_text(encoding="utf-8")
    for code in errorcodes.CODES:
        assert f"`{code}`" in doc, code
    for family in errorcodes.FAMILIES:
        assert f"`{family}.`" in doc or f"`{family}.*`" in doc, family
    assert errorcodes.category_of("ik.unreachable") == "execution"
    assert errorcodes.category_of("heartbeat.policy") == "heartbeat" and errorcodes.is_known("timeout.queue")
    assert errorcodes.category_of("bogus.thing") == "unknown" and not errorcodes.is_known("timeout")
