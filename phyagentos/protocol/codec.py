"""Markdown + YAML protocol document codec.

A protocol document is Markdown prose with exactly one fenced ```` ```yaml ````
block. The prose before and after the block belongs to humans and is kept
byte-for-byte; the block is re-emitted from validated pydantic data on every
write. Every error names the file and the 1-based line *in the file*, so a
YAML mark or a pydantic error location is translated through the block's
position and the composed YAML node tree.

The YAML dialect is YAML 1.1 as PyYAML implements it, minus implicit timestamps
(protocol timestamps are ISO-8601 strings, so an unquoted ``2024-01-01T00:00:00Z``
must load as a string, not a ``datetime``).

Parsing is cached per process by the exact text (:data:`PARSE_CACHE`): re-reading a file
that has not changed since this process read or wrote it returns a copy of the value
parsed before, without YAML or validation.
"""

from __future__ import annotations

import enum
import logging
import os
import pickle
import re
import threading
import types
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Generic, TypeVar, Union, get_args, get_origin

import yaml
from pydantic import BaseModel, ValidationError
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from phyagentos.errors import DocumentError, format_choices
from phyagentos.yamlsource import MAX_YAML_CHARS, check_bounds, clip

from .atomic import atomic_write_text
from .block_yaml import emit_block_yaml

__all__ = [
    "Document",
    "parse_document",
    "render_document",
    "read_document",
    "write_document",
    "parse_yaml",
    "read_yaml",
    "dump_yaml",
    "PARSE_CACHE",
]

log = logging.getLogger(__name__)

M = TypeVar("M", bound=BaseModel)

# ---------------------------------------------------------------------------
# YAML dialect: one resolver shared by loader and dumper, so the dumper quotes
# exactly the strings the loader would otherwise turn into something else.

_DROPPED_TAGS = {"tag:yaml.org,2002:timestamp", "tag:yaml.org,2002:value"}


_RESOLVERS = {
    first: [(tag, rx) for tag, rx in resolvers if tag not in _DROPPED_TAGS]
    for first, resolvers in yaml.resolver.Resolver.yaml_implicit_resolvers.items()
}


class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe loader (libyaml when available); node marks give line numbers."""

    yaml_implicit_resolvers = _RESOLVERS


class _Dumper(getattr(yaml, "CSafeDumper", yaml.SafeDumper)):  # type: ignore[misc]
    """Safe dumper (libyaml's emitter when available, ~5x faster); the lossless
    round-trip property tests pin its output for both emitters."""

    yaml_implicit_resolvers = _RESOLVERS


# YAML 1.1 treats these as line breaks (or, for the BOM, strips it), so they
# only survive inside double quotes, where the emitter escapes them.
_QUOTE_ONLY_CHARS = frozenset("\r\x85\u2028\u2029\ufeff")


def _represent_str(dumper: _Dumper, value: str) -> ScalarNode:
    if any(ch in _QUOTE_ONLY_CHARS for ch in value):
        style: str | None = '"'
    elif "\n" in value:
        # Literal block when the emitter allows it (no trailing spaces, no
        # special characters); otherwise it falls back to double quotes.
        style = "|"
    else:
        style = None
    return dumper.represent_scalar("tag:yaml.org,2002:str", value, style=style)


def _represent_list(dumper: _Dumper, value: list) -> Node:
    # Short lists of numbers (positions, quaternions, joint vectors) read best on
    # one line: ``position: [0.5, -0.2, 0.02]``. Everything else stays block style.
    flow = 0 < len(value) <= 8 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flow)


def _represent_other(dumper: _Dumper, value: Any) -> Node:
    # Values under dict[str, Any] fields may be numpy scalars/arrays, tuples,
    # enums or str/int/float subclasses; write them as their plain equivalents.
    if isinstance(value, enum.Enum):
        return dumper.represent_data(value.value)
    if isinstance(value, bool):
        return dumper.represent_bool(bool(value))
    if isinstance(value, str):
        return _represent_str(dumper, str(value))
    if isinstance(value, int):
        return dumper.represent_int(int(value))
    if isinstance(value, float):
        return dumper.represent_float(float(value))
    if isinstance(value, BaseModel):
        return dumper.represent_data(value.model_dump(mode="python"))
    if isinstance(value, Mapping):
        return dumper.represent_dict(dict(value))
    if isinstance(value, tuple):
        return _represent_list(dumper, list(value))
    if isinstance(value, os.PathLike):
        return _represent_str(dumper, os.fspath(value))
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return dumper.represent_data(value.tolist())
    raise yaml.representer.RepresenterError(
        f"cannot write a {type(value).__name__} into a protocol document: {value!r}"
    )


_Dumper.add_representer(str, _represent_str)
_Dumper.add_representer(list, _represent_list)
_Dumper.add_representer(tuple, _represent_other)
_Dumper.add_representer(None, _represent_other)


def dump_yaml(data: Any) -> str:
    """Return ``data`` (a pydantic model or plain data) as block-style YAML text.

    Keys keep their order, unicode is written as is, multi-line strings use a
    literal ``|`` block when PyYAML allows it and double quotes otherwise; in
    either case loading the text gives back exactly the same values. Data of the common
    protocol shape is written by :func:`~phyagentos.protocol.block_yaml.emit_block_yaml`
    (the same text, about 8x faster), everything else by PyYAML.

    Raises:
        yaml.representer.RepresenterError: a value has no YAML representation.
    """
    if isinstance(data, BaseModel):
        data = data.model_dump(mode="python")
    fast = emit_block_yaml(data, _RESOLVERS)  # the same text, without PyYAML's representer
    if fast is not None:
        return fast
    return yaml.dump(
        data,
        Dumper=_Dumper,
        allow_unicode=True,
        sort_keys=False,
        default_flow_style=False,
        width=2**30,  # never fold long lines: diffs stay one line per value
        indent=2,
    )


# ---------------------------------------------------------------------------
# Loading and validation with file line numbers.


def _load(text: str, path: Path | None, first_line: int) -> tuple[Node | None, Any]:
    """Compose and construct ``text``; ``first_line`` is the 1-based file line of its line 0."""
    if len(text) > MAX_YAML_CHARS:
        raise DocumentError(f"YAML block of {len(text)} characters is longer than the limit of {MAX_YAML_CHARS}",
                            path=path, line=first_line)
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is not None:
            if "&" in text:  # without an anchor there is no alias to expand
                check_bounds(node, path=path, error=DocumentError, first_line=first_line)
            _check_duplicate_keys(node, path, first_line)
        data = loader.construct_document(node) if node is not None else None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = first_line + mark.line if mark is not None else first_line
        problem = " ".join(p for p in (exc.context, exc.problem) if p)
        raise DocumentError(f"YAML syntax error: {clip(problem)}", path=path, line=line) from None
    except yaml.YAMLError as exc:
        raise DocumentError(f"YAML error: {clip(str(exc))}", path=path, line=first_line) from None
    finally:
        loader.dispose()
    return node, data


def _check_duplicate_keys(node: Node, path: Path | None, first_line: int) -> None:
    # PyYAML silently keeps the last duplicate; in a protocol file that hides edits.
    stack, seen_nodes = [node], set()
    while stack:
        current = stack.pop()
        if id(current) in seen_nodes:  # anchors/aliases make the node graph a DAG (or cyclic)
            continue
        seen_nodes.add(id(current))
        if isinstance(current, MappingNode):
            seen: dict[str, int] = {}
            for key, value in current.value:
                if isinstance(key, ScalarNode) and key.value != "<<":
                    line = first_line + key.start_mark.line
                    if key.value in seen:
                        raise DocumentError(
                            f"duplicate key {key.value!r} (first defined at line {seen[key.value]})",
                            path=path,
                            line=line,
                        )
                    seen[key.value] = line
                stack.extend((key, value))
        elif isinstance(current, SequenceNode):
            stack.extend(current.value)


def _locate(root: Node | None, loc: tuple[Any, ...]) -> int:
    """0-based line of the deepest YAML node reachable along a pydantic ``loc``.

    A mapping key reports the key's line (a nested value may start below it);
    a sequence index reports the item's line. Unreachable tails (missing keys,
    union branch names) stop the walk at the nearest existing node.
    """
    if root is None:
        return 0
    node, line = root, root.start_mark.line
    for part in loc:
        if isinstance(node, MappingNode):
            for key, value in node.value:
                if isinstance(key, ScalarNode) and key.value == str(part):
                    node, line = value, key.start_mark.line
                    break
            else:
                break
        elif isinstance(node, SequenceNode) and isinstance(part, int) and 0 <= part < len(node.value):
            node = node.value[part]
            line = node.start_mark.line
        else:
            break
    return line


def _unwrap(tp: Any) -> Any:
    """Strip Optional/Annotated so ``_model_at`` can follow field types."""
    while True:
        origin = get_origin(tp)
        if origin is None:
            return tp
        if origin in (Union, types.UnionType):
            options = [a for a in get_args(tp) if a is not type(None)]
            if len(options) != 1:
                return tp
            tp = options[0]
        elif origin is Annotated:
            tp = get_args(tp)[0]
        else:
            return tp


def _model_at(model: type[BaseModel], loc: tuple[Any, ...]) -> type[BaseModel] | None:
    """The pydantic model class that validates the value at ``loc``, if any."""
    tp: Any = model
    for part in loc:
        tp = _unwrap(tp)
        origin = get_origin(tp)
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            field = tp.model_fields.get(str(part))
            if field is None:
                return None
            tp = field.annotation
        elif origin in (list, tuple) and isinstance(part, int):
            tp = get_args(tp)[0]
        elif origin is dict:
            tp = get_args(tp)[1]
        else:
            return None
    tp = _unwrap(tp)
    return tp if isinstance(tp, type) and issubclass(tp, BaseModel) else None


def _dotted(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<document>"


def _short(value: Any, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _describe(error: Mapping[str, Any], model: type[BaseModel]) -> str:
    loc = tuple(error["loc"])
    kind = error["type"]
    if kind == "missing":
        return f"missing required field {_dotted(loc)!r}"
    if kind == "extra_forbidden":
        parent = _model_at(model, loc[:-1])
        valid = f" (valid fields: {format_choices(parent.model_fields)})" if parent else ""
        return f"unknown field {_dotted(loc)!r}{valid}"
    found = _short(error.get("input"))
    if kind == "literal_error":
        expected = error.get("ctx", {}).get("expected", "")
        return f"field {_dotted(loc)!r}: found {found}, expected one of {expected}"
    msg = error["msg"]
    if kind == "value_error" and msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    return f"field {_dotted(loc)!r}: {msg}; found {found}"


def _validate(
    node: Node | None, data: Any, model: type[M], path: Path | None, first_line: int
) -> M:
    if not isinstance(data, dict):
        kind = "nothing" if data is None else type(data).__name__
        raise DocumentError(
            f"the YAML must be a mapping of {model.__name__} fields, found {kind}",
            path=path,
            # An empty block has no node: point at its opening fence.
            line=first_line + node.start_mark.line if node is not None else max(first_line - 1, 1),
        )
    if "version" in model.model_fields and "version" not in data:
        raise DocumentError(
            "missing required field 'version' (the protocol version of this document)",
            path=path,
            line=first_line + _locate(node, ()),
        )
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        errors = sorted(exc.errors(), key=lambda e: _locate(node, tuple(e["loc"])))
        first = errors[0]
        line = first_line + _locate(node, tuple(first["loc"]))
        message = f"{model.__name__}: {_describe(first, model)}"
        for other in errors[1:6]:
            other_line = first_line + _locate(node, tuple(other["loc"]))
            message += f"\n  also line {other_line}: {_describe(other, model)}"
        if len(errors) > 6:
            message += f"\n  ... and {len(errors) - 6} more errors"
        raise DocumentError(message, path=path, line=line) from None


def parse_yaml(text: str, model: type[M], *, path: str | os.PathLike[str] | None = None) -> M:
    """Parse a plain YAML file (e.g. ``safety.yaml``) into ``model``.

    Raises:
        DocumentError: YAML syntax error, duplicate key, missing ``version`` or a
            validation error, with the 1-based line in ``text``.
    """
    where = Path(path) if path is not None else None
    cached = PARSE_CACHE.get("yaml", model, text)
    if cached is not None:
        return cached
    node, data = _load(text, where, 1)
    value = _validate(node, data, model, where, 1)
    PARSE_CACHE.put("yaml", model, text, value)
    return value


def _read_text(path: Path) -> str:
    from phyagentos.untrusted import read_regular  # noqa: PLC0415
    from phyagentos.yamlsource import MAX_YAML_FILE_BYTES  # noqa: PLC0415

    try:  # a regular file only (a FIFO is refused, never waited on), bounded before it is read
        raw = read_regular(path, limit=MAX_YAML_FILE_BYTES)
    except ValueError as exc:
        raise DocumentError(str(exc), path=path, line=1) from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise DocumentError(f"not valid UTF-8 (byte {exc.start})", path=path, line=line) from None


def read_yaml(path: str | os.PathLike[str], model: type[M]) -> M:
    """Read and validate a plain YAML file (see :func:`parse_yaml`).

    Raises:
        DocumentError: malformed content (with path and line).
        OSError: the file cannot be read (e.g. ``FileNotFoundError``).
    """
    where = Path(path)
    return parse_yaml(_read_text(where), model, path=where)


# ---------------------------------------------------------------------------
# Parse cache: the same text parses to the same value.


def _plain(value: Any) -> bool:
    """True if ``value`` holds only what the YAML loader itself produces (dict with str
    keys, list, str, int, float, bool, None; exact types), so that dumping and loading
    it gives back an equal value of the same types."""
    stack = [value]
    while stack:
        v = stack.pop()
        t = type(v)
        if t is dict:
            for k, item in v.items():
                if type(k) is not str:
                    return False
                stack.append(item)
        elif t is list:
            stack.extend(v)
        elif t not in (str, int, float, bool, type(None)):
            return False
    return True


class _ParseCache:
    """Validated values by the exact text they were parsed from (and the model and
    kind of parse), least recently used first out.

    Every session hand-off re-reads files that have not changed since this process last
    read or wrote them (``TARGETS.md``, ``safety.yaml``, ``LOG.md`` before an append, a
    session file before its next transition); parsing and validating one costs about
    1 ms. A hit returns a new copy (unpickled), so callers may mutate what they get.
    The key is the whole text, never a file's size or time stamp, so a changed file is
    always parsed afresh, and errors are never cached. Bounded by entries and by the
    characters of the texts it holds.
    """

    def __init__(self, *, max_entries: int = 512, max_chars: int = 4_000_000) -> None:
        self._items: OrderedDict[tuple[str, type, str], bytes] = OrderedDict()
        self._chars = 0
        self._lock = threading.Lock()
        self.max_entries = max_entries
        self.max_chars = max_chars
        self.hits = 0
        self.misses = 0

    def get(self, kind: str, model: type, text: str) -> Any:
        key = (kind, model, text)
        with self._lock:
            blob = self._items.get(key)
            if blob is None:
                self.misses += 1
                return None
            self._items.move_to_end(key)
            self.hits += 1
        return pickle.loads(blob)

    def put(self, kind: str, model: type, text: str, value: Any) -> None:
        if len(text) > self.max_chars // 8:
            return
        try:
            blob = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 - an unpicklable value is simply not cached
            return
        key = (kind, model, text)
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return
            self._items[key] = blob
            self._chars += len(text)
            while len(self._items) > self.max_entries or self._chars > self.max_chars:
                (_, _, old), _ = self._items.popitem(last=False)
                self._chars -= len(old)

    def clear(self) -> None:
        """Forget every entry and reset the hit and miss counts."""
        with self._lock:
            self._items.clear()
            self._chars = 0
            self.hits = self.misses = 0


#: This process's parse cache (see :class:`_ParseCache`).
PARSE_CACHE = _ParseCache()


# ---------------------------------------------------------------------------
# Markdown fences.

# CommonMark backtick fences: up to 3 spaces of indent, 3+ backticks, an info
# string without backticks; the closing fence is at least as long, no info.
_OPEN = re.compile(r"^ {0,3}(`{3,})([^`]*)$")
_CLOSE = re.compile(r"^ {0,3}(`{3,})[ \t]*$")
_YAML_INFO = re.compile(r"^[ \t]*ya?ml[ \t]*$", re.IGNORECASE)
# Any YAML line that could close a fence forces a longer fence on output.
_TICK_RUN = re.compile(r"^ {0,3}(`{3,})", re.MULTILINE)


def _fence_needed(body: str) -> int:
    """Backticks of the fence around ``body``: three, or one more than the longest run
    of backticks that opens one of its lines (which could otherwise close the fence)."""
    longest = max((len(m.group(1)) for m in _TICK_RUN.finditer(body)), default=2)
    return max(3, longest + 1)


@dataclass(kw_only=True)
class Document(Generic[M]):
    """One protocol document: human prose around validated data.

    ``prefix`` is the text before the ```` ```yaml ```` fence line (empty or
    ending in a newline), ``suffix`` the text after the closing fence line;
    both are written back unchanged. ``path`` is where it was read from.
    """

    prefix: str = ""
    data: M
    suffix: str = ""
    path: Path | None = None


def _split_lines(text: str) -> list[tuple[int, str]]:
    """``(offset, line)`` pairs split on ``\\n`` only (str.splitlines would also
    split on form feeds and unicode separators inside prose)."""
    out, offset = [], 0
    for line in text.split("\n"):
        out.append((offset, line))
        offset += len(line) + 1
    return out


def parse_document(
    text: str, model: type[M], *, path: str | os.PathLike[str] | None = None
) -> Document[M]:
    """Split ``text`` into prose and its single YAML block, and validate the block.

    Raises:
        DocumentError: no ```` ```yaml ```` block, more than one, an unclosed
            fence, a YAML syntax error, a missing ``version``, or a validation
            error; ``line`` is the 1-based line in the file.
    """
    where = Path(path) if path is not None else None
    cached = PARSE_CACHE.get("document", model, text)
    if cached is not None:
        prefix, data, suffix = cached
        return Document(prefix=prefix, data=data, suffix=suffix, path=where)
    lines = _split_lines(text)
    blocks: list[tuple[int, int]] = []  # (open index, close index)
    open_at: tuple[int, int, bool] | None = None  # (index, backticks, is_yaml)
    for index, (_, raw) in enumerate(lines):
        line = raw[:-1] if raw.endswith("\r") else raw
        if open_at is None:
            match = _OPEN.match(line)
            if match:
                open_at = (index, len(match.group(1)), bool(_YAML_INFO.match(match.group(2))))
        else:
            match = _CLOSE.match(line)
            if match and len(match.group(1)) >= open_at[1]:
                if open_at[2]:
                    blocks.append((open_at[0], index))
                    if len(blocks) == 2:
                        raise DocumentError(
                            f"second ```yaml block (the first opens at line {blocks[0][0] + 1}); "
                            "a protocol document has exactly one",
                            path=where,
                            line=open_at[0] + 1,
                        )
                open_at = None
    if open_at is not None:
        kind = "```yaml block" if open_at[2] else "``` fence"
        raise DocumentError(
            f"{kind} opened here is never closed (add a closing ``` line)",
            path=where,
            line=open_at[0] + 1,
        )
    if not blocks:
        raise DocumentError(
            "no ```yaml block found; a protocol document is Markdown prose plus exactly "
            "one fenced ```yaml block holding its data",
            path=where,
            line=1,
        )
    open_index, close_index = blocks[0]
    body_start = lines[open_index + 1][0]
    body_end = lines[close_index][0]
    after = close_index + 1
    suffix = text[lines[after][0] :] if after < len(lines) else ""
    first_line = open_index + 2  # 1-based file line of the block's first YAML line
    node, data = _load(text[body_start:body_end], where, first_line)
    validated = _validate(node, data, model, where, first_line)
    doc = Document(prefix=text[: lines[open_index][0]], data=validated, suffix=suffix, path=where)
    PARSE_CACHE.put("document", model, text, (doc.prefix, validated, suffix))
    return doc


def render_document(doc: Document[Any]) -> str:
    """Return the document text: prefix, the data as a ```` ```yaml ```` block, suffix.

    A non-empty prefix that does not end in a newline gets one, so the fence
    starts its own line. The fence grows beyond three backticks when a YAML
    line could otherwise be read as the closing fence.
    """
    body = dump_yaml(doc.data)
    fence = "`" * _fence_needed(body)
    prefix = doc.prefix
    if prefix and not prefix.endswith("\n"):
        prefix += "\n"
    return f"{prefix}{fence}yaml\n{body}{fence}\n{doc.suffix}"


def read_document(path: str | os.PathLike[str], model: type[M]) -> Document[M]:
    """Read and validate the protocol document at ``path``.

    Raises:
        DocumentError: malformed document (see :func:`parse_document`).
        OSError: the file cannot be read (e.g. ``FileNotFoundError``).
    """
    where = Path(path)
    return parse_document(_read_text(where), model, path=where)


def write_document(doc: Document[Any], path: str | os.PathLike[str] | None = None, *,
                   durable: bool = True, validated: bool = False) -> Path:
    """Atomically write ``doc`` to ``path`` (default ``doc.path``); returns the path.

    ``durable=False`` skips the fsyncs (see :func:`~phyagentos.protocol.atomic.atomic_write_bytes`).

    The data is re-validated first so an invalid model (e.g. a field assigned
    after construction) never reaches disk; ``doc.data`` and ``doc.path`` are
    then set to the validated data and the path written. ``validated=True`` says the
    caller built ``doc.data`` by validation just now (e.g. ``Workspace``'s session
    writes, which validate with their own error message) and skips the second pass.

    Raises:
        DocumentError: the data does not validate against its model.
        ValueError: neither ``path`` nor ``doc.path`` is set.
        OSError: the write failed (the old file is left intact).
    """
    target = Path(path) if path is not None else doc.path
    if target is None:
        raise ValueError("write_document needs a path: pass one or set doc.path")
    model = type(doc.data)
    if not validated:
        try:
            doc.data = model.model_validate(doc.data.model_dump(mode="python", warnings=False))
        except ValidationError as exc:
            first = exc.errors()[0]
            raise DocumentError(
                f"refusing to write invalid {model.__name__}: {_describe(first, model)}", path=target
            ) from None
    # The validated copy is rendered (e.g. a dict appended to a list of models is now
    # that model) and kept, so ``doc`` matches what is on disk.
    text = render_document(doc)
    atomic_write_text(target, text, durable=durable)
    doc.path = target
    # What reading this text back would return, without parsing it: the validated data,
    # if its dump holds only what the loader produces (then loading and validating give
    # back an equal value of the same types). The cache keeps a pickled copy, so the
    # caller may go on mutating ``doc.data``.
    if _plain(doc.data.model_dump(mode="python", warnings=False)):
        prefix = doc.prefix if not doc.prefix or doc.prefix.endswith("\n") else doc.prefix + "\n"
        PARSE_CACHE.put("document", model, text, (prefix, doc.data, doc.suffix))
    return target
