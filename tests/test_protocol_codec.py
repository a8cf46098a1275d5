"""Markdown + YAML codec: lossless round trips and errors with file line numbers."""

from __future__ import annotations

import textwrap
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import Field

from phyagentos.errors import DocumentError
from phyagentos.protocol import (
    Document,
    LessonsDoc,
    SessionsIndex,
    VersionedModel,
    dump_yaml,
    parse_document,
    parse_yaml,
    read_document,
    render_document,
    write_document,
)
from phyagentos.protocol.codec import _Loader  # the loader the codec uses, for raw checks


class Sample(VersionedModel):
    """A test model with the kinds of values protocol documents hold."""

    title: str
    notes: list[str] = Field(default_factory=list)
    mapping: dict[str, str] = Field(default_factory=dict)
    number: float = 0.0
    count: int = 0
    extra: dict[str, Any] = Field(default_factory=dict)


# Characters YAML treats specially (line breaks, BOM, indicators, quotes).
TRICKY_CHARS = list(" \n\t\r#:-|>\"'`{}[],&*!%@?~\\") + ["\x85", "\u2028", "\u2029", "\ufeff", "\x00", "\x1b", "é", "日本", "🤖", "\u00a0"]
YAML_WORDS = ["yes", "no", "on", "off", "null", "Null", "~", "true", "1.0", "1", "0x1F", "1e3", ".inf", "-.inf",
              ".nan", "2024-01-01", "2024-01-01T00:00:00Z", "12:30:00", "=", "<<", "- a", "key: value", "```",
              "```yaml", "...", "---", "", " ", "\n", "|", ">", "#comment", "'", '"']

texts = st.one_of(
    st.text(alphabet=st.characters(codec="utf-8"), max_size=40),
    st.lists(st.sampled_from(TRICKY_CHARS + ["a", "b", "```"]), max_size=30).map("".join),
    st.sampled_from(YAML_WORDS),
    st.lists(st.sampled_from(YAML_WORDS + ["line", "  indented", "trailing  "]), max_size=5).map("\n".join),
)
samples = st.builds(
    Sample,
    title=texts,
    notes=st.lists(texts, max_size=4),
    mapping=st.dictionaries(texts, texts, max_size=3),
    number=st.floats(allow_nan=False),
    count=st.integers(),
    extra=st.dictionaries(
        texts,
        st.one_of(texts, st.integers(), st.floats(allow_nan=False), st.booleans(), st.none(), st.lists(texts, max_size=3)),
        max_size=3,
    ),
)
# Prose may hold anything except a ``` fence (that would be a second code block).
prose = (
    st.lists(
        st.one_of(
            st.text(alphabet=st.characters(codec="utf-8"), max_size=10),
            st.sampled_from(["\n", "\r\n", "<!-- note -->", "~~~", "# Heading", "  ", "``", "\u2028", "\x0c"]),
        ),
        max_size=12,
    )
    .map("".join)
    .filter(lambda s: "```" not in s)
)


@settings(max_examples=400, suppress_health_check=[HealthCheck.too_slow])
@given(data=samples, prefix=prose, suffix=prose)
def test_render_then_parse_is_lossless_for_data_and_prose(data, prefix, suffix):
    if prefix and not prefix.endswith("\n"):
        prefix += "\n"
    doc = Document(prefix=prefix, data=data, suffix=suffix)

    text = render_document(doc)
    parsed = parse_document(text, Sample)

    assert parsed.data == data
    assert parsed.prefix == prefix
    assert parsed.suffix == suffix
    assert render_document(parsed) == text


@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])
@given(cause=texts, correction=texts, evidence=st.lists(texts, max_size=3))
def test_real_document_model_round_trips_arbitrary_strings(cause, correction, evidence):
    lessons = LessonsDoc.model_validate(
        {"version": 1, "lessons": [{"id": "L1", "objective": "pick", "evidence": evidence, "cause": cause, "correction": correction}]}
    )
    assert parse_document(render_document(Document(data=lessons)), LessonsDoc).data == lessons


@settings(max_examples=300)
@given(value=texts)
def test_dump_yaml_values_load_back_exactly(value):
    loader = _Loader(dump_yaml({"k": value, value: [value]}))
    try:
        assert loader.get_single_data() == {"k": value, value: [value]}
    finally:
        loader.dispose()


def test_multiline_strings_use_literal_block_style():
    doc = Document(prefix="# T\n", data=Sample(title="line one\nline two\n"))
    assert "title: |\n  line one\n  line two\n" in render_document(doc)


def test_multiline_string_with_trailing_spaces_round_trips_quoted():
    value = "line one  \nline two "
    text = render_document(Document(data=Sample(title=value)))
    assert parse_document(text, Sample).data.title == value


def test_yaml_words_stay_strings():
    sample = Sample(title="yes", notes=["null", "1.0", "2024-01-01", "~", ""])
    assert parse_document(render_document(Document(data=sample)), Sample).data == sample


def test_unquoted_timestamps_load_as_strings():
    text = "```yaml\nversion: 1\ntitle: 2024-05-01T12:00:00Z\n```\n"
    assert parse_document(text, Sample).data.title == "2024-05-01T12:00:00Z"


def test_yaml_line_that_looks_like_a_fence_gets_a_longer_fence():
    sample = Sample(title="```\ncode\n```\n", notes=["```"])
    text = render_document(Document(prefix="x\n", data=sample, suffix="after\n"))
    assert text.splitlines()[1].startswith("````yaml")
    parsed = parse_document(text, Sample)
    assert parsed.data == sample and parsed.suffix == "after\n"


def test_keys_keep_model_order_and_unicode_is_written_verbatim():
    text = render_document(Document(data=Sample(title="Grüße 日本", count=2)))
    body = text.split("\n")
    assert body[1:4] == ["version: 1", "title: Grüße 日本", "notes: []"]


def test_prose_with_other_code_fences_and_html_comments_is_preserved():
    prefix = "# Doc\n\n<!-- keep me -->\n```python\nprint('```yaml')\n```\n\n"
    suffix = "\nMore prose.\n\n```text\nhello\n```\n"
    text = prefix + "```yaml\nversion: 1\ntitle: t\n```\n" + suffix
    doc = parse_document(text, Sample)
    assert (doc.prefix, doc.suffix) == (prefix, suffix)
    assert render_document(doc) == render_document(Document(prefix=prefix, data=doc.data, suffix=suffix))


def test_crlf_prose_is_preserved_byte_for_byte():
    text = "# Doc\r\n\r\n```yaml\r\nversion: 1\r\ntitle: t\r\n```\r\nend\r\n"
    doc = parse_document(text, Sample)
    assert doc.prefix == "# Doc\r\n\r\n"
    assert doc.suffix == "end\r\n"
    assert doc.data.title == "t"


def test_write_then_read_document_round_trips_through_the_file(tmp_path):
    path = tmp_path / "doc.md"
    doc = Document(prefix="# Title\n\nprose ✓\n\n", data=Sample(title="a\nb"), suffix="\ntail\n")
    write_document(doc, path)
    back = read_document(path, Sample)
    assert (back.prefix, back.data, back.suffix, back.path) == (doc.prefix, doc.data, doc.suffix, path)


def test_write_document_refuses_invalid_data_and_leaves_file(tmp_path):
    path = tmp_path / "doc.md"
    write_document(Document(data=Sample(title="ok")), path)
    before = path.read_bytes()
    doc = read_document(path, Sample)
    doc.data.count = "not a number"  # pydantic does not validate assignment

    with pytest.raises(DocumentError, match="count"):
        write_document(doc)
    assert path.read_bytes() == before


# ---------------------------------------------------------------------------
# Errors: 1-based file line, message naming the problem, file unchanged.


def _error_for(tmp_path, text: str, model=Sample) -> DocumentError:
    path = tmp_path / "doc.md"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(DocumentError) as info:
        read_document(path, model)
    assert path.read_text(encoding="utf-8") == text  # never modified
    assert info.value.path == path
    return info.value


def doc_text(body: str) -> str:
    """Three lines of prose, then the yaml fence on line 4; ``body`` starts on line 5."""
    return "# Title\n\nSome prose.\n```yaml\n" + textwrap.dedent(body) + "```\ntrailing prose\n"


def test_missing_fence_is_reported_at_line_1(tmp_path):
    err = _error_for(tmp_path, "# Title\n\nversion: 1\n")
    assert err.line == 1
    assert "no ```yaml block" in str(err)


def test_second_yaml_block_is_reported_at_its_fence_line(tmp_path):
    text = doc_text("version: 1\ntitle: t\n") + "\n```yaml\nversion: 1\n```\n"
    err = _error_for(tmp_path, text)
    assert err.line == 10
    assert "second ```yaml block" in str(err) and "line 4" in str(err)


def test_unclosed_yaml_fence_is_reported_at_its_opening_line(tmp_path):
    err = _error_for(tmp_path, "# Title\n\n```yaml\nversion: 1\ntitle: t\n")
    assert err.line == 3
    assert "never closed" in str(err)


def test_unclosed_prose_fence_is_reported_at_its_opening_line(tmp_path):
    err = _error_for(tmp_path, "# T\n```yaml\nversion: 1\ntitle: t\n```\n\n```python\nx = 1\n")
    assert err.line == 7


def test_yaml_syntax_error_line_is_offset_by_the_block_start(tmp_path):
    err = _error_for(tmp_path, doc_text("version: 1\ntitle: t\nnotes: a: b\n"))
    assert err.line == 7
    assert "YAML syntax error" in str(err)
    assert str(err).startswith(f"{tmp_path / 'doc.md'}:7: ")


def test_bad_indentation_is_reported_on_its_line(tmp_path):
    err = _error_for(tmp_path, doc_text("version: 1\ntitle: t\nmapping:\n  a: x\n   b: y\n"))
    assert err.line == 9


def test_unknown_field_is_reported_on_its_line_with_valid_fields(tmp_path):
    err = _error_for(tmp_path, doc_text("version: 1\ntitle: t\ntitel: typo\ncount: 1\n"))
    assert err.line == 7
    assert "unknown field 'titel'" in str(err)
    assert "'title'" in str(err) and "'count'" in str(err)


def test_wrong_type_names_field_and_found_value(tmp_path):
    err = _error_for(tmp_path, doc_text("version: 1\ntitle: t\nnotes: []\ncount: lots\n"))
    assert err.line == 8
    assert "'count'" in str(err) and "'lots'" in str(err) and "integer" in str(err)


def test_unsupported_version_names_supported_versions(tmp_path):
    err = _error_for(tmp_path, doc_text("title: t\nversion: 2\n"))
    assert err.line == 6
    assert "unsupported version 2" in str(err) and "supported: 1" in str(err)


def test_non_integer_version_is_rejected(tmp_path):
    err = _error_for(tmp_path, doc_text("version: '1'\ntitle: t\n"))
    assert err.line == 5 and "'version'" in str(err)


def test_missing_version_is_reported_at_block_start(tmp_path):
    err = _error_for(tmp_path, doc_text("title: t\n"))
    assert err.line == 5
    assert "version" in str(err)


def test_missing_required_field_is_reported(tmp_path):
    err = _error_for(tmp_path, doc_text("version: 1\ncount: 3\n"))
    assert err.line == 5
    assert "missing required field 'title'" in str(err)


def test_invalid_choice_in_nested_list_item_points_at_the_item_line(tmp_path):
    body = """\
        version: 1
        sessions:
        - session_id: s1
          node: n
          skill: pick
          target: franka_tabletop
          state: pending
          updated_at: '2024-05-01T12:00:00Z'
        - session_id: s2
          node: n
          skill: pick
          target: franka_tabletop
          state: runing
          updated_at: '2024-05-01T12:00:00Z'
        """
    err = _error_for(tmp_path, doc_text(body), SessionsIndex)
    assert err.line == 17
    assert "sessions[1].state" in str(err)
    assert "'runing'" in str(err) and "'running'" in str(err) and "'pending'" in str(err)


def test_duplicate_key_is_reported_at_the_second_occurrence(tmp_path):
    err = _error_for(tmp_path, doc_text("version: 1\ntitle: a\ncount: 1\ntitle: b\n"))
    assert err.line == 8
    assert "duplicate key 'title'" in str(err) and "line 6" in str(err)


def test_yaml_that_is_not_a_mapping_is_rejected(tmp_path):
    err = _error_for(tmp_path, doc_text("- version: 1\n"))
    assert err.line == 5
    assert "mapping" in str(err)


def test_empty_yaml_block_is_rejected(tmp_path):
    err = _error_for(tmp_path, "# T\n```yaml\n```\n")
    assert err.line == 2


def test_invalid_utf8_is_reported_with_line(tmp_path):
    path = tmp_path / "doc.md"
    path.write_bytes(b"# T\n\xff\n```yaml\nversion: 1\ntitle: t\n```\n")
    with pytest.raises(DocumentError) as info:
        read_document(path, Sample)
    assert info.value.line == 2


def test_several_errors_are_all_listed_first_by_line(tmp_path):
    err = _error_for(tmp_path, doc_text("version: 1\ntitle: t\ncount: x\nnumber: y\n"))
    assert err.line == 7
    assert "also line 8" in str(err)


def test_parse_yaml_reports_lines_of_a_plain_yaml_file():
    with pytest.raises(DocumentError) as info:
        parse_yaml("version: 1\ntitle: t\nbogus: 1\n", Sample, path="x.yaml")
    assert info.value.line == 3
    assert str(info.value).startswith("x.yaml:3: ")
