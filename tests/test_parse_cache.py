"""The codec's parse cache (issue 12, round 5): a text parses once per process.

Every hand-off re-reads protocol files this process has just written or read unchanged
(a session file before its next transition, LOG.md before an append, TARGETS.md and
safety.yaml at every preflight). ``PARSE_CACHE`` keys validated values by the exact
text; these tests pin that what it returns is what parsing returns, as a new copy, and
that any change to the text is parsed afresh.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_protocol_codec import Sample, prose, samples

from phyagentos.errors import DocumentError
from phyagentos.protocol import Document, Workspace, parse_document, read_document, write_document
from phyagentos.protocol.codec import PARSE_CACHE, _ParseCache


@pytest.fixture(autouse=True)
def _empty_cache():
    PARSE_CACHE.clear()
    yield
    PARSE_CACHE.clear()


def _fresh_parse(path: Path, model):
    PARSE_CACHE.clear()
    return read_document(path, model)


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=samples, prefix=prose, suffix=prose)
def test_reading_back_a_written_document_gives_what_parsing_its_file_gives(tmp_path, data, prefix, suffix):
    path = tmp_path / "doc.md"
    write_document(Document(prefix=prefix, data=data, suffix=suffix), path)
    hits = PARSE_CACHE.hits
    cached = read_document(path, Sample)
    assert PARSE_CACHE.hits == hits + 1  # the read did not parse
    fresh = _fresh_parse(path, Sample)

    assert cached.data == fresh.data
    assert cached.data.model_dump() == fresh.data.model_dump()
    assert [type(v) for v in cached.data.extra.values()] == [type(v) for v in fresh.data.extra.values()]
    assert (cached.prefix, cached.suffix) == (fresh.prefix, fresh.suffix)


def test_a_value_that_does_not_load_back_as_itself_is_not_cached_on_write(tmp_path):
    # A tuple and a numpy array are written as YAML lists: parsing gives lists, so the
    # written model (which holds the tuple and the array) must not stand in for a parse.
    path = tmp_path / "doc.md"
    write_document(Document(data=Sample(title="t", extra={"pair": (1, 2), "q": np.zeros(2)})), path)
    misses = PARSE_CACHE.misses
    doc = read_document(path, Sample)
    assert PARSE_CACHE.misses == misses + 1
    assert doc.data.extra == {"pair": [1, 2], "q": [0.0, 0.0]}


def test_a_cached_read_is_a_new_copy_the_caller_may_mutate(tmp_path):
    path = tmp_path / "doc.md"
    write_document(Document(data=Sample(title="t", notes=["a"], extra={"k": [1]})), path)
    first = read_document(path, Sample)
    first.data.notes.append("changed")
    first.data.extra["k"].append(2)
    second = read_document(path, Sample)
    assert second.data.notes == ["a"] and second.data.extra == {"k": [1]}


def test_mutating_a_written_document_afterwards_does_not_change_what_reading_its_file_gives(tmp_path):
    path = tmp_path / "doc.md"
    for validated in (False, True):
        doc = Document(data=Sample(title="t", notes=["a"], extra={"k": [1]}))
        write_document(doc, path, validated=validated)
        doc.data.notes.append("changed")
        doc.data.extra["k"].append(2)
        hits = PARSE_CACHE.hits
        read = read_document(path, Sample)
        assert PARSE_CACHE.hits == hits + 1
        assert read.data.notes == ["a"] and read.data.extra == {"k": [1]}
        assert read.data == _fresh_parse(path, Sample).data


def test_a_file_changed_behind_the_cache_is_parsed_afresh_even_at_the_same_size(tmp_path):
    path = tmp_path / "doc.md"
    write_document(Document(data=Sample(title="aaaa")), path)
    assert read_document(path, Sample).data.title == "aaaa"
    text = path.read_text()
    path.write_text(text.replace("aaaa", "bbbb"))  # same length, same directory entry
    assert read_document(path, Sample).data.title == "bbbb"


def test_a_malformed_file_raises_every_time_and_is_never_cached(tmp_path):
    path = tmp_path / "doc.md"
    path.write_text("# prose\n```yaml\nversion: 1\ntitle: [unclosed\n```\n")
    for _ in range(2):
        with pytest.raises(DocumentError, match=r"doc.md:5: YAML syntax error"):
            read_document(path, Sample)
    assert PARSE_CACHE.hits == 0


def test_the_same_text_read_as_another_model_is_validated_as_that_model(tmp_path):
    from phyagentos.protocol import LessonsDoc

    path = tmp_path / "doc.md"
    write_document(Document(data=Sample(title="t")), path)
    with pytest.raises(DocumentError, match="LessonsDoc"):
        read_document(path, LessonsDoc)


def test_the_cache_is_bounded_by_entries_and_by_characters():
    cache = _ParseCache(max_entries=3, max_chars=1000)
    for i in range(5):
        cache.put("document", Sample, f"text {i}", i)
    assert [cache.get("document", Sample, f"text {i}") for i in range(5)] == [None, None, 2, 3, 4]
    big = "x" * 120
    for i in range(3):
        cache.put("yaml", Sample, big + str(i), i)
    cache.put("yaml", Sample, "y" * 200, "too big for an eighth of the limit")
    assert cache.get("yaml", Sample, "y" * 200) is None


def test_a_changed_safety_file_is_checked_for_completeness_again(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    assert ws.read_safety() == ws.read_safety()
    path = ws.root / "safety.yaml"
    lines = path.read_text().splitlines(keepends=True)
    key = next(i for i, line in enumerate(lines) if line.startswith("max_joint_velocity"))
    path.write_text("".join(lines[:key] + lines[key + 1:]))
    with pytest.raises(DocumentError, match="incomplete"):
        ws.read_safety()


def test_parse_document_of_a_cached_text_keeps_the_path_it_was_given(tmp_path):
    text = "```yaml\nversion: 1\ntitle: t\n```\n"
    assert parse_document(text, Sample, path=tmp_path / "a.md").path == tmp_path / "a.md"
    assert parse_document(text, Sample, path=tmp_path / "b.md").path == tmp_path / "b.md"


# -- LOG.md appends edit the text instead of rendering every entry again -------------------

from hypothesis import example  # noqa: E402
from test_protocol_codec import texts  # noqa: E402

from phyagentos.protocol import LogEntry, render_document  # noqa: E402
from phyagentos.protocol.schemas import LogDoc  # noqa: E402

log_entries = st.builds(
    LogEntry,
    at=st.sampled_from(["2024-05-01T12:00:00Z", "2024-06-30T23:59:59.123456Z"]),
    session_id=st.one_of(st.none(), st.sampled_from(["r1-a-1", "r1-b-2"])),
    node=st.one_of(st.none(), texts),
    event=texts,
    state=st.one_of(st.none(), st.sampled_from(["claimed", "succeeded"])),
    message=texts,
)


def _blank_entry(at: str) -> LogEntry:
    return LogEntry(at=at, session_id=None, node=None, event="", state=None, message="")


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(entries=st.lists(log_entries, min_size=1, max_size=9))
@example(entries=[_blank_entry("2024-05-01T12:00:00Z"), _blank_entry("2024-06-30T23:59:59.123456Z")]
         + [_blank_entry("2024-05-01T12:00:00Z")] * 6)  # equal entries age out into two months
def test_an_appended_log_is_byte_for_byte_the_rendering_of_its_entries(tmp_path_factory, monkeypatch, entries):
    ws = Workspace.create(tmp_path_factory.mktemp("ws"))
    monkeypatch.setattr(Workspace, "LOG_MAX_ENTRIES", 5)
    spliced = []
    splice = Workspace._append_log_spliced

    def spy(self, *args):
        spliced.append(splice(self, *args))
        return spliced[-1]

    monkeypatch.setattr(Workspace, "_append_log_spliced", spy)
    path = ws.path("LOG")
    original = read_document(path, LogDoc)
    for n, entry in enumerate(entries, start=1):
        ws.append_log(entry)
        expected = original.data.model_copy(update={"entries": entries[max(0, n - 5):n]})
        text = path.read_text(encoding="utf-8")
        assert text == render_document(Document(prefix=original.prefix, data=expected, suffix=original.suffix))
        assert ws.read("LOG").data == expected  # through the cache
        assert _fresh_parse(path, LogDoc).data == expected
    archive = sorted((ws.root / "log").glob("archive-*.jsonl")) if (ws.root / "log").exists() else []
    archived = {f.name: [LogEntry.model_validate(json.loads(line))
                         for line in f.read_text(encoding="utf-8").split("\n") if line]
                for f in archive}  # one file per month, entries in the order they aged out
    aged_out = entries[:max(0, len(entries) - 5)]
    by_month = {}
    for entry in aged_out:
        by_month.setdefault(f"archive-{entry.at[:7]}.jsonl", []).append(entry)
    assert archived == by_month


def test_ordinary_log_appends_edit_the_text_after_the_first(tmp_path, monkeypatch):
    ws = Workspace.create(tmp_path / "ws")
    monkeypatch.setattr(Workspace, "LOG_MAX_ENTRIES", 5)
    calls = []
    splice = Workspace._append_log_spliced
    monkeypatch.setattr(Workspace, "_append_log_spliced", lambda self, *a: calls.append(splice(self, *a)) or calls[-1])
    for i in range(8):
        ws.append_log(LogEntry(at="2024-05-01T12:00:00Z", session_id="r1-a-1", event="claim", state="claimed",
                               message=f"by supervisor {i}: a line with `ticks`"))
    assert calls == [False] + [True] * 7  # the template's empty list is rendered once
    assert [e.message[-14:] for e in _fresh_parse(ws.path("LOG"), LogDoc).data.entries] == \
        [f"{i}: a line with `ticks`"[-14:] for i in range(3, 8)]


def test_a_log_written_by_another_process_is_rendered_whole_once(tmp_path, monkeypatch):
    ws = Workspace.create(tmp_path / "ws")
    ws.append_log(LogEntry(at="2024-05-01T12:00:00Z", event="one"))
    path = ws.path("LOG")
    path.write_text(path.read_text().replace("event: one", "event: uno"))  # another writer
    calls = []
    splice = Workspace._append_log_spliced
    monkeypatch.setattr(Workspace, "_append_log_spliced", lambda self, *a: calls.append(splice(self, *a)) or calls[-1])
    ws.append_log(LogEntry(at="2024-05-01T12:00:01Z", event="two"))
    ws.append_log(LogEntry(at="2024-05-01T12:00:02Z", event="three"))
    assert calls == [False, True]
    assert [e.event for e in _fresh_parse(path, LogDoc).data.entries] == ["uno", "two", "three"]
