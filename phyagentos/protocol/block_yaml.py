"""A fast emitter for the common shape of protocol data, byte for byte as the codec's dumper.

Every protocol write renders its data as block YAML (:func:`~phyagentos.protocol.codec.dump_yaml`).
PyYAML's representer is pure Python even when libyaml emits: a 4 KB session record costs
about 3 ms to render on a 2-core CI machine, and every hand-off between two sessions
renders several (the verdict, the next session's submission, its claim and start, its
evidence). :func:`emit_block_yaml` writes the same text directly for data made only of

- ``dict`` with non-empty ``str`` keys of at most 122 characters (a YAML simple key to
  both PyYAML's and libyaml's emitters),
- ``list`` (up to 8 numbers on one line, ``[0.5, -0.2, 0.02]``, as the codec writes
  vectors; anything else one item per line),
- ``str`` of printable ASCII on one line, ``int``, ``float``, ``bool`` and ``None``,

with no container reached twice (PyYAML would write an anchor), and returns ``None``
for anything else, which the codec then renders with PyYAML as before: multi-line and
non-ASCII strings, other scalar types, aliases. The output equals PyYAML's for the
codec's dialect (``allow_unicode``, ``sort_keys=False``, ``indent=2``, unbounded width,
timestamps not resolved); ``tests/test_block_yaml.py`` pins that equality on generated
data and on every document of a real run.

The style rules followed are YAML 1.1 as PyYAML and libyaml emit it
(``Emitter.analyze_scalar`` / ``yaml_emitter_analyze_scalar``): a string is written
plain unless it would load as another type (``yes``, ``1.0``, ``null``, ``''``), starts
with an indicator (``#,[]{}&*!|>'"%@``` and backquote; ``?``, ``:`` or ``-`` followed by a
space or the end), starts with ``---`` or ``...``, holds ``": "`` or ``" #"``, ends with
``:``, or has a leading or trailing space; such strings are single-quoted with ``'``
doubled. Floats are written as ``repr`` in lower case with ``.0`` before a bare exponent,
``.nan``, ``.inf`` and ``-.inf`` (``SafeRepresenter.represent_float``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from re import Pattern
from typing import Any

__all__ = ["emit_block_yaml"]

_STR = "tag:yaml.org,2002:str"
_INT = "tag:yaml.org,2002:int"
_FLOAT = "tag:yaml.org,2002:float"

#: Printable ASCII on one line (no tab, no control character, no line break).
_PRINTABLE = re.compile(r"[\x20-\x7e]*\Z")
#: First characters that make a plain scalar impossible in block context.
_LEADING_INDICATORS = frozenset("#,[]{}&*!|>'\"%@`")
#: First characters that do so when followed by a space or the end of the string.
_LEADING_BEFORE_SPACE = frozenset("?:-")
#: A flow list: at most this many numbers (the codec's ``_represent_list``).
_FLOW_MAX = 8
#: The longest key both emitters write as a simple key: libyaml up to 128 characters,
#: PyYAML's own emitter under 128 counting the key's tag (``!!str``, 5) as well.
_SIMPLE_KEY_MAX = 122


class _Unsupported(Exception):
    """The data leaves the subset this emitter writes; the caller falls back to PyYAML."""


def _make_scalar(resolvers: dict[str | None, list[tuple[str, Pattern[str]]]]) -> Callable[[object], str]:
    wildcard = resolvers.get(None, [])
    cache: dict[str, str] = {}

    def detected(text: str) -> str:
        for tag, rx in (resolvers.get(text[0] if text else "", []) + wildcard):
            if rx.match(text):
                return tag
        return _STR

    def string(value: str) -> str:
        hit = cache.get(value)
        if hit is not None:
            return hit
        if not _PRINTABLE.match(value):
            raise _Unsupported
        if detected(value) != _STR or not _plain_allowed(value):
            text = "'" + value.replace("'", "''") + "'"
        else:
            text = value
        if len(cache) < 4096:
            cache[value] = text
        return text

    def scalar(value: object) -> str:
        kind = type(value)
        if kind is str:
            return string(value)  # type: ignore[arg-type]
        if value is None:
            return "null"
        if kind is bool:
            return "true" if value else "false"
        if kind is int:
            text = str(value)
            if detected(text) != _INT:
                raise _Unsupported
            return text
        if kind is float:
            if value != value:
                return ".nan"
            if math.isinf(value):  # type: ignore[arg-type]
                return ".inf" if value > 0 else "-.inf"  # type: ignore[operator]
            text = repr(value).lower()
            if "." not in text and "e" in text:
                text = text.replace("e", ".0e", 1)
            if detected(text) != _FLOAT:
                raise _Unsupported
            return text
        raise _Unsupported

    return scalar


def _plain_allowed(value: str) -> bool:
    """Whether a printable-ASCII, one-line string may be written plain in block context."""
    if not value or value[0] == " " or value[-1] == " ":
        return False
    first = value[0]
    if first in _LEADING_INDICATORS:
        return False
    if first in _LEADING_BEFORE_SPACE and (len(value) == 1 or value[1] == " "):
        return False
    if value.startswith(("---", "...")):
        return False
    return not (value[-1] == ":" or ": " in value or " #" in value)


#: Scalar types a list item's flat mapping may hold (see :func:`_flat_key`).
_SCALAR_TYPES = frozenset((str, int, float, bool, type(None)))
#: Texts of list items kept per dialect before the memo is emptied.
_ITEM_MEMO_MAX = 16384


def _flat_key(item: dict) -> tuple | None:
    """What the text of the list item ``item`` depends on, if it is a flat mapping (its
    values scalars or lists of scalars): keys, value types and values, floats by their
    ``repr`` (``0.0 == -0.0`` but their texts differ); else None. A TASK.md node or a
    session's transition is such an item, rendered again unchanged on every rewrite."""
    parts: list[tuple[Any, type, Any]] = []
    for key, value in item.items():
        kind = type(value)
        if kind is list:
            inner = []
            for x in value:
                xkind = type(x)
                if xkind not in _SCALAR_TYPES:
                    return None
                inner.append((xkind, repr(x) if xkind is float else x))
            parts.append((key, kind, tuple(inner)))
        elif kind in _SCALAR_TYPES:
            parts.append((key, kind, repr(value) if kind is float else value))
        else:
            return None
    return tuple(parts)


class _Emitter:
    """One rendering: the parts written so far and the containers already seen."""

    __slots__ = ("out", "seen", "scalar", "memo")

    def __init__(self, scalar: Callable[[object], str], memo: dict | None = None) -> None:
        self.out: list[str] = []
        self.seen: set[int] = set()
        self.scalar = scalar
        self.memo = memo if memo is not None else {}

    def _enter(self, container: object) -> None:
        ident = id(container)
        if ident in self.seen:
            raise _Unsupported  # PyYAML writes an anchor and an alias
        self.seen.add(ident)

    def flow(self, items: Sequence[object]) -> str | None:
        """``[a, b]`` if ``items`` is a list the codec writes on one line, else None."""
        if not items:
            return "[]"
        if len(items) > _FLOW_MAX:
            return None
        for item in items:
            kind = type(item)
            if kind is not float and kind is not int:
                return None
        return "[" + ", ".join(self.scalar(item) for item in items) + "]"

    def mapping(self, data: dict, indent: int, inline: bool) -> None:
        """Write the non-empty ``data`` at column ``indent``; ``inline``: its first key
        continues the current line (after ``- ``)."""
        self._enter(data)
        out = self.out
        pad = " " * indent
        scalar = self.scalar
        for key, value in data.items():
            if type(key) is not str or not key or len(key) > _SIMPLE_KEY_MAX:
                raise _Unsupported  # an empty key is a complex key ("? ''") to PyYAML's emitter
            if inline:
                inline = False
            else:
                out.append(pad)
            out.append(scalar(key))
            self.node(value, indent, False)

    def sequence(self, items: list, indent: int, inline: bool) -> None:
        """Write the non-empty block list ``items`` with its dashes at column ``indent``.

        The text of an item that is a flat mapping is kept (per dialect, by column and
        :func:`_flat_key`) and written again for an equal item without rendering it."""
        self._enter(items)
        out = self.out
        pad = " " * indent
        memo = self.memo
        for item in items:
            if inline:
                inline = False
                out.append("- ")
            else:
                out.append(pad + "- ")
            key = _flat_key(item) if type(item) is dict and item else None
            if key is None:
                self.node(item, indent, True)
                continue
            key = (indent, key)
            text = memo.get(key)
            if text is not None:
                self._enter(item)  # containers are still counted: one reached twice is declined
                for value in item.values():
                    if type(value) is list:
                        self._enter(value)
                out.append(text)
                continue
            start = len(out)
            self.node(item, indent, True)
            if len(memo) >= _ITEM_MEMO_MAX:
                memo.clear()
            memo[key] = "".join(out[start:])

    def node(self, value: object, indent: int, after_dash: bool) -> None:
        """Write ``value`` after a key at column ``indent`` (the line holds the key) or,
        ``after_dash``, after a ``- `` at column ``indent``."""
        kind = type(value)
        if kind is dict:
            if value:
                if not after_dash:
                    self.out.append(":\n")
                self.mapping(value, indent + 2, after_dash)  # type: ignore[arg-type]
                return
            self._enter(value)
            text = "{}"
        elif kind is list:
            flow = self.flow(value)  # type: ignore[arg-type]
            if flow is None:
                if after_dash:
                    self.sequence(value, indent + 2, True)  # type: ignore[arg-type]
                else:
                    self.out.append(":\n")
                    self.sequence(value, indent, False)  # type: ignore[arg-type]  # indentless under a key
                return
            self._enter(value)
            text = flow
        else:
            text = self.scalar(value)
        self.out.append(text + "\n" if after_dash else ": " + text + "\n")


def emit_block_yaml(data: object, resolvers: dict[str | None, list[tuple[str, Pattern[str]]]]) -> str | None:
    """``data`` as the codec's block YAML, or ``None`` if it leaves this emitter's subset.

    Args:
        data: a non-empty ``dict`` (a protocol document's data as plain Python values).
        resolvers: the dialect's implicit resolvers (first character -> ``[(tag, regex)]``,
            ``yaml.resolver.Resolver.yaml_implicit_resolvers`` minus the dropped tags),
            which decide which strings must be quoted to stay strings.

    Returns:
        The text PyYAML would write with the codec's dumper, or ``None`` (the caller
        renders with PyYAML): an empty or non-dict top level, a multi-line or
        non-ASCII string, a key that is not a short string, a type other than
        dict, list, str, int, float, bool and None (subclasses included), or a
        container reached twice.
    """
    if type(data) is not dict or not data:
        return None
    emitter = _Emitter(*_scalar_for(resolvers))
    try:
        emitter.mapping(data, 0, False)
    except (_Unsupported, RecursionError):
        return None
    return "".join(emitter.out)


#: id(resolvers) -> (resolvers, their scalar writer, their list items' texts); the dict is
#: kept so its id stays its own.
_SCALARS: dict[int, tuple[object, Callable[[object], str], dict]] = {}


def _scalar_for(resolvers: dict[str | None, list[tuple[str, Pattern[str]]]]) -> tuple[Callable[[object], str], dict]:
    hit = _SCALARS.get(id(resolvers))
    if hit is None or hit[0] is not resolvers:
        hit = _SCALARS[id(resolvers)] = (resolvers, _make_scalar(resolvers), {})
    return hit[1], hit[2]
