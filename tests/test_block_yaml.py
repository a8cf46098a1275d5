"""The fast block-YAML emitter writes exactly what the codec's PyYAML dumper writes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from soak import scaled

from phyagentos.protocol import dump_yaml
from phyagentos.protocol.block_yaml import emit_block_yaml
from phyagentos.protocol.codec import _RESOLVERS, _Dumper, _Loader
from phyagentos.resources import goal_graphs_dir

ROOT = Path(__file__).resolve().parents[1]


def pyyaml(data) -> str:
    """The codec's dumper, as dump_yaml called it before the fast emitter."""
    return yaml.dump(data, Dumper=_Dumper, allow_unicode=True, sort_keys=False, default_flow_style=False,
                     width=2**30, indent=2)


class _PurePythonDumper(yaml.SafeDumper):
    """The codec's dumper on PyYAML's own emitter (what a PyYAML without libyaml uses)."""

    yaml_implicit_resolvers = _RESOLVERS


for _kind, _representer in _Dumper.yaml_representers.items():
    _PurePythonDumper.add_representer(_kind, _representer)


def pure(data) -> str:
    return yaml.dump(data, Dumper=_PurePythonDumper, allow_unicode=True, sort_keys=False, default_flow_style=False,
                     width=2**30, indent=2)


def same_as_both(text: str, data) -> bool:
    """``text`` is what the codec's dumper writes and what PyYAML's own emitter writes."""
    return text == pyyaml(data) and text == pure(data)


def emitted(data) -> str | None:
    return emit_block_yaml(data, _RESOLVERS)


# Strings of the kinds protocol documents hold, and the ones YAML treats specially.
WORDS = ["pick_cube", "franka_tabletop", "2026-11-23T08:49:01.859870Z", "/tmp/ws/evidence/a.png", "by sup-1:4242",
         "preflight passed", "ERR_X field: expected 1, found 2", "a, b", "a#b", "a #b", "x:", ":x", "?x", "? x", "-x",
         "- x", "-", "?", ":", "---x", "...", "..x", "yes", "No", "on", "OFF", "null", "Null", "~", "", "true", "1.0",
         "1", "-5", "+3", "0x1F", "0o17", "1_000", "1e3", "1.0e+3", ".inf", "-.Inf", ".NaN", "1:30", "2024-01-01",
         "=", "<<", "!", "&", "*", "!tag", "&a", "*a", "'q'", 'say "hi"', "it's", "[x]", "{x}", "a[0]", "|", ">", "%x",
         "@x", "`x`", "#x", " lead", "trail ", "two  spaces", "tab\there", "line\nbreak", "é", "\x85", "\u2028"]
texts = st.one_of(st.sampled_from(WORDS),
                  st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=12),
                  st.text(max_size=6))
scalars = st.one_of(texts, st.integers(), st.floats(), st.booleans(), st.none())
numbers = st.lists(st.one_of(st.integers(-10**6, 10**6), st.floats()), max_size=10)
keys = st.one_of(st.sampled_from(WORDS), st.from_regex(r"[a-z_]{1,12}", fullmatch=True))
values = st.recursive(
    st.one_of(scalars, numbers),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(keys, inner, max_size=4)),
    max_leaves=20,
)
documents = st.dictionaries(keys, values, min_size=1, max_size=6)
# Protocol-shaped data: identifiers, sentences and numbers, all inside the fast subset.
plain_texts = st.one_of(st.sampled_from([w for w in WORDS if w.isascii() and w.isprintable()]),
                        st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=20))
protocol_values = st.recursive(
    st.one_of(plain_texts, st.integers(), st.floats(), st.booleans(), st.none(), numbers),
    lambda inner: st.one_of(st.lists(inner, max_size=4),
                            st.dictionaries(st.from_regex(r"[a-z_]{1,12}", fullmatch=True), inner, max_size=4)),
    max_leaves=20,
)
protocol_documents = st.dictionaries(st.from_regex(r"[a-z_]{1,12}", fullmatch=True), protocol_values,
                                     min_size=1, max_size=6)


# ~11 ms an example (two PyYAML dumps and a load): 600 examples under make soak, 200 in make test.
@pytest.mark.soak
@settings(max_examples=scaled(200, 600), suppress_health_check=[HealthCheck.too_slow])
@given(data=documents)
def test_the_emitter_writes_what_pyyaml_writes_or_declines(data):
    text = emitted(data)
    assert text is None or same_as_both(text, data)
    assert dump_yaml(data) == pyyaml(data)


@pytest.mark.soak
@settings(max_examples=scaled(150, 400), suppress_health_check=[HealthCheck.too_slow])
@given(data=protocol_documents)
def test_protocol_shaped_data_is_emitted_fast_and_equal_and_loads_back(data):
    text = emitted(data)
    assert text is not None
    assert same_as_both(text, data)
    loader = _Loader(text)
    try:
        loaded = loader.get_single_data()
    finally:
        loader.dispose()
    assert yaml.dump(loaded, Dumper=_Dumper, allow_unicode=True, sort_keys=False, width=2**30) == \
        yaml.dump(data, Dumper=_Dumper, allow_unicode=True, sort_keys=False, width=2**30)  # nan != nan


# List items that are flat mappings (a TASK.md node, a session's transition): their texts
# are kept and written again for equal items. Values that compare equal but are written
# differently (0.0 and -0.0, 1 and True and 1.0) must never share a text.
look_alikes = st.sampled_from([0, 0.0, -0.0, 1, 1.0, True, False, None, "1", "true", "", 1e16, -1e-05, 2**64])
flat_items = st.dictionaries(st.sampled_from(["id", "state", "at", "n"]),
                             st.one_of(look_alikes, scalars, st.lists(st.one_of(look_alikes, scalars), max_size=3)),
                             min_size=1, max_size=4)


@settings(max_examples=400, suppress_health_check=[HealthCheck.too_slow])
@given(items=st.lists(flat_items, min_size=1, max_size=6), depth=st.integers(0, 2))
def test_list_items_written_again_from_their_kept_text_are_what_pyyaml_writes(items, depth):
    data: dict = {"nodes": items}
    for _ in range(depth):  # the same items at another column
        data = {"run": data}
    for _ in range(2):  # the second rendering takes each item's text from the first
        text = emitted(data)
        assert text is None or same_as_both(text, data)
    shuffled = {"nodes": items[::-1] + [dict(item) for item in items]}  # equal items, other objects
    text = emitted(shuffled)
    assert text is None or same_as_both(text, shuffled)


def test_an_item_reached_twice_is_declined_even_when_its_text_is_kept():
    item = {"id": "pick", "state": "running", "session_ids": ["r-pick-1"]}
    flat = {"event": "claim", "at": "2026-11-23T08:49:01.859870Z"}
    assert emitted({"nodes": [item], "transitions": [flat]}) is not None  # their texts are kept now
    assert emitted({"nodes": [item, item]}) is None  # PyYAML would write an anchor and an alias
    assert emitted({"transitions": [flat, flat]}) is None
    assert emitted({"transitions": [flat], "last": flat}) is None
    assert emitted({"a": [item], "b": item["session_ids"]}) is None
    assert emitted({"nodes": [item, dict(item, session_ids=["r-pick-1"])]}) == pyyaml(
        {"nodes": [item, dict(item, session_ids=["r-pick-1"])]})


@pytest.mark.parametrize("word", [w for w in WORDS if w.isascii() and w.isprintable()])
def test_each_special_string_is_quoted_as_pyyaml_quotes_it_as_key_value_and_item(word):
    data = {"k": word, "seq": [[word, word], [], {"n": word}], "e": {}}
    if word:
        data[word] = [word, {"n": word}]
    text = emitted(data)
    assert text is not None and same_as_both(text, data)


@pytest.mark.parametrize("number", [0.0, -0.0, 1.0, 600.0, 1e16, 1e-5, 5e-324, 1.7976931348623157e308, 0.1 + 0.2,
                                    float("nan"), float("inf"), float("-inf"), 0, -7, 10**30, True, False, None])
def test_numbers_and_constants_are_written_as_pyyaml_writes_them(number):
    data = {"v": number, "vec": [number, 1, 2.5], "long": [number] * 9}
    if isinstance(number, bool) or number is None:
        data["vec"] = [1, 2.5]
    text = emitted(data)
    assert text is not None and same_as_both(text, data)


@pytest.mark.parametrize("length", [121, 122, 123, 127, 128, 129])
def test_keys_near_the_simple_key_limit_are_emitted_or_declined_never_written_differently(length):
    data = {"k" * length: 1}
    text = emitted(data)
    assert text is None or same_as_both(text, data)
    assert (text is not None) == (length <= 122)  # PyYAML's own emitter counts the "!!str" tag


def test_data_outside_the_subset_is_declined():
    shared = [1, "a", {"x": 1}]
    assert emitted({"a": shared, "b": shared}) is None  # PyYAML writes an anchor and an alias
    assert emitted({"a": {}, "b": [{}]}) is not None
    empty = {}
    assert emitted({"a": empty, "b": empty}) is None
    assert emitted({"text": "two\nlines"}) is None
    assert emitted({"text": "café"}) is None
    assert emitted({1: "int key"}) is None
    assert emitted({"": "empty key"}) is None  # "? ''" to PyYAML's own emitter
    assert emitted({"t": (1, 2)}) is None
    assert emitted({"s": type("S", (str,), {})("sub")}) is None
    assert emitted([1, 2]) is None
    assert emitted({}) is None


def _documents_of(root: Path):
    for path in sorted(root.rglob("*")):
        if path.suffix not in (".md", ".yaml") or not path.is_file():
            continue
        text = path.read_text(encoding="utf-8")
        if path.suffix == ".md":
            start = text.find("```yaml\n")
            if start < 0:
                continue
            text = text[start + 8: text.index("\n```", start + 8) + 1]
        loader = _Loader(text)
        try:
            data = loader.get_single_data()
        finally:
            loader.dispose()
        if isinstance(data, dict) and data:
            yield path, data


def test_every_document_of_a_real_run_and_of_the_repository_is_emitted_as_pyyaml_writes_it(tmp_path):
    ws = tmp_path / "ws"
    done = subprocess.run([sys.executable, "-m", "phyagentos.cli", "run", str(goal_graphs_dir() / "pick_and_place.yaml"),
                           "--workspace", str(ws), "--json"], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    checked = fast = 0
    for root in (ws, ROOT / "phyagentos"):  # phyagentos/data/ holds the shipped goal graphs
        for path, data in _documents_of(root):
            checked += 1
            text = emitted(data)
            if text is not None:
                fast += 1
                assert same_as_both(text, data), path
    sessions = [p for p, _ in _documents_of(ws / "sessions")]
    assert len(sessions) == 2 and checked > 30
    assert fast >= 0.9 * checked, (fast, checked)
