"""YAML loading that remembers where every mapping and key came from.

Authored YAML (trees, skill manifests, acceptance criteria) must produce errors
naming the file and line. :func:`load_yaml` returns plain Python containers whose
mappings are :class:`SourceMap` (a ``dict``) carrying the 1-based line of the
mapping and of each key, so validators can point at the offending line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ["SourceMap", "SourceList", "load_yaml", "line_of"]


class SourceMap(dict):
    """A ``dict`` with ``line`` (1-based line of the mapping) and ``key_lines``."""

    line: int | None = None
    key_lines: dict

    def key_line(self, key: Any) -> int | None:
        """1-based line of ``key`` in the source, or the mapping's line."""
        return self.key_lines.get(key, self.line)


class SourceList(list):
    """A ``list`` with ``line`` (1-based) and ``item_lines`` for its elements."""

    line: int | None = None
    item_lines: list


class _Loader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe loader; libyaml's parser when available (marks still carry lines)."""


def _construct_mapping(loader: _Loader, node: yaml.MappingNode) -> SourceMap:
    loader.flatten_mapping(node)
    out = SourceMap()
    out.line = node.start_mark.line + 1
    out.key_lines = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        out[key] = loader.construct_object(value_node, deep=True)
        out.key_lines[key] = key_node.start_mark.line + 1
    return out


def _construct_sequence(loader: _Loader, node: yaml.SequenceNode) -> SourceList:
    out = SourceList(loader.construct_object(child, deep=True) for child in node.value)
    out.line = node.start_mark.line + 1
    out.item_lines = [child.start_mark.line + 1 for child in node.value]
    return out


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_sequence)


def load_yaml(text: str, *, path: str | Path | None = None, error: type[Exception]) -> Any:
    """Parse ``text``; raise ``error(message, path=, line=)`` on a syntax error.

    Args:
        text: YAML source.
        path: file the text came from, used in messages.
        error: exception class accepting ``(message, path=..., line=...)``,
            e.g. :class:`~phyagentos.errors.GoalGraphError`.
    """
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        raise error(f"invalid YAML: {exc.problem or exc}", path=path, line=line) from None


def line_of(value: Any, key: Any = None) -> int | None:
    """Best-known 1-based line of ``value`` (or of ``key`` inside it)."""
    if isinstance(value, SourceMap):
        return value.key_line(key) if key is not None else value.line
    return getattr(value, "line", None)
