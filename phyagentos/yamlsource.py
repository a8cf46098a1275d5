"""YAML loading that remembers where every mapping and key came from.

Authored YAML (trees, skill manifests, acceptance criteria) must produce errors
naming the file and line. :func:`load_yaml` returns plain Python containers whose
mappings are :class:`SourceMap` (a ``dict``) carrying the 1-based line of the
mapping and of each key, so validators can point at the offending line.

Every YAML text the project reads (goal graphs, protocol documents, skills, trees,
``safety.yaml``) is bounded before it is constructed (:func:`check_bounds`): at most
:data:`MAX_YAML_CHARS` characters, :data:`MAX_ALIASES` alias references, an expanded
tree of at most :data:`MAX_EXPANDED_NODES` nodes more than the text itself holds, and
no recursive alias. A "billion laughs" alias bomb of a kilobyte therefore fails in
milliseconds with the file and the line of the anchor that expands too far, instead
of consuming gigabytes in a later ``deepcopy`` or dump.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import yaml

__all__ = ["SourceMap", "SourceList", "load_yaml", "load_plain", "read_yaml", "line_of", "line_at", "item_line", "to_plain",
           "check_bounds",
           "compose_bounded", "excerpt", "clip", "MAX_YAML_CHARS", "MAX_YAML_FILE_BYTES", "MAX_ALIASES",
           "MAX_EXPANDED_NODES", "MAX_DEPTH"]

#: Longest YAML text read (characters): far above any authored file or protocol block.
MAX_YAML_CHARS = 64 * 1024 * 1024
#: Largest YAML file read (bytes, checked before reading): UTF-8 is at most 4 bytes a character.
MAX_YAML_FILE_BYTES = 4 * MAX_YAML_CHARS
#: Alias references (``*name``) per YAML text; authored files use a handful.
MAX_ALIASES = 256
#: Extra nodes aliases may add when expanded (beyond the nodes written in the text).
MAX_EXPANDED_NODES = 100_000
#: Deepest nesting of mappings and sequences.
MAX_DEPTH = 200
#: Longest excerpt of user data quoted in an error message (characters).
MAX_EXCERPT_CHARS = 200


def clip(text: str, limit: int = MAX_EXCERPT_CHARS) -> str:
    """``text`` cut to ``limit`` characters (messages that embed other messages stay bounded)."""
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} chars)"


def excerpt(value: Any, limit: int = MAX_EXCERPT_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters (error messages quote bounded excerpts)."""
    text = repr(value) if not isinstance(value, str) else repr(value[: limit + 1])
    return text if len(text) <= limit else text[:limit] + f"... ({len(str(value))} chars)"


def _error(error: type[Exception], message: str, *, path: str | Path | None, line: int | None) -> Exception:
    """``error(message, path=, line=)``; for an error class without those keywords, the
    message prefixed with ``path:line`` (and ``path``/``line`` set as attributes)."""
    located: Callable[..., Exception] = error  # PhyAgentOSError subclasses with path=/line= (errors._Located)
    try:
        return located(message, path=path, line=line)
    except TypeError:
        loc = f"{path}:{line}" if path is not None and line is not None else (str(path) if path is not None else "")
        exc = error(f"{loc}: {message}" if loc else message)
        exc.path, exc.line = path, line  # type: ignore[attr-defined]
        return exc


def check_bounds(node: Any, *, path: str | Path | None, error: type[Exception], first_line: int = 1) -> None:
    """Refuse a composed YAML node tree whose aliases or nesting exceed the limits.

    Args:
        node: the root :class:`yaml.Node` (``None`` for an empty document).
        path: file, for messages.
        error: exception class accepting ``(message, path=..., line=...)``.
        first_line: 1-based file line of the text's first line (YAML blocks inside
            Markdown documents start below the top of their file).

    Raises:
        error: more than :data:`MAX_ALIASES` aliases, a recursive alias, nesting deeper
            than :data:`MAX_DEPTH`, or an expansion beyond :data:`MAX_EXPANDED_NODES`
            extra nodes; the line is the anchor's (or the deepest node's).
    """
    if node is None:
        return
    # Iterative depth-first walk over the node DAG, each distinct node expanded once:
    # an edge to a finished node is an alias reference, an edge to a node still on
    # the path is a recursive alias. ``size`` is the expanded node count.
    state: dict[int, int] = {}  # 1 on the path, 2 finished
    size: dict[int, int] = {}
    aliases = unique = 0
    frames: list[tuple[Any, Any, int]] = [(node, iter(_children(node)), 1)]
    state[id(node)] = 1
    unique = 1
    while frames:
        current, children, depth = frames[-1]
        child = next(children, None)
        if child is None:
            frames.pop()
            total = 1 + sum(size[id(c)] for c in _children(current))
            size[id(current)] = total
            state[id(current)] = 2
            if total - unique > MAX_EXPANDED_NODES:
                raise _error(error, f"YAML aliases expand to more than {MAX_EXPANDED_NODES} extra nodes (the node starting "
                            f"here expands to {total}); write the data out or use fewer aliases",
                            path=path, line=first_line + current.start_mark.line)
            continue
        seen = state.get(id(child))
        if seen == 1:
            raise _error(error, "recursive YAML alias (a node contains itself)", path=path,
                        line=first_line + child.start_mark.line)
        if seen == 2:
            aliases += 1
            if aliases > MAX_ALIASES:
                raise _error(error, f"more than {MAX_ALIASES} YAML aliases", path=path,
                            line=first_line + child.start_mark.line)
            continue
        if depth + 1 > MAX_DEPTH:
            raise _error(error, f"YAML nesting deeper than {MAX_DEPTH} levels", path=path,
                        line=first_line + child.start_mark.line)
        state[id(child)] = 1
        unique += 1
        frames.append((child, iter(_children(child)), depth + 1))


def _children(node: Any) -> list:
    if isinstance(node, yaml.MappingNode):
        return [x for pair in node.value for x in pair]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def compose_bounded(text: str, *, path: str | Path | None, error: type[Exception], loader: type | None = None,
                    first_line: int = 1) -> Any:
    """Compose ``text`` into a node tree (``None`` when empty) and :func:`check_bounds` it.

    Raises:
        error: a text longer than :data:`MAX_YAML_CHARS`, a syntax error (with line),
            or a bound exceeded.
    """
    if len(text) > MAX_YAML_CHARS:
        raise _error(error, f"YAML text of {len(text)} characters is longer than the limit of {MAX_YAML_CHARS}",
                    path=path, line=first_line)
    instance = (loader or _Loader)(text)
    try:
        node = instance.get_single_node()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = " ".join(p for p in (exc.context, exc.problem) if p)
        raise _error(error, f"YAML syntax error: {clip(problem or str(exc))}", path=path,
                    line=first_line + mark.line if mark is not None else first_line) from None
    except yaml.YAMLError as exc:
        raise _error(error, f"YAML error: {clip(str(exc))}", path=path, line=first_line) from None
    finally:
        instance.dispose()
    if "&" in text:  # without an anchor there is no alias to expand
        check_bounds(node, path=path, error=error, first_line=first_line)
    return node


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


def _construct(text: str, loader_cls: type, *, path: str | Path | None, error: type[Exception]) -> Any:
    """Compose ``text`` within the bounds, then construct it with ``loader_cls``."""
    node = compose_bounded(text, path=path, error=error)
    if node is None:
        return None
    loader = loader_cls("")
    try:
        return loader.construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        raise _error(error, f"invalid YAML: {clip(str(exc.problem or exc))}", path=path, line=line) from None
    finally:
        loader.dispose()


def load_yaml(text: str, *, path: str | Path | None = None, error: type[Exception]) -> Any:
    """Parse ``text``; raise ``error(message, path=, line=)`` on a syntax error.

    Args:
        text: YAML source.
        path: file the text came from, used in messages.
        error: exception class accepting ``(message, path=..., line=...)``,
            e.g. :class:`~phyagentos.errors.GoalGraphError`.
    """
    return _construct(text, _Loader, path=path, error=error)


class _PlainLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe loader constructing plain ``dict``/``list`` (for data that is dumped again)."""


def load_plain(text: str, *, path: str | Path | None = None, error: type[Exception]) -> Any:
    """Like :func:`load_yaml` (the same bounds) but with plain ``dict`` and ``list``
    containers, for data that is re-dumped or compared (evidence, reports).

    Raises:
        error: ``(message, path=..., line=...)``: a bound exceeded or a syntax error.
    """
    return _construct(text, _PlainLoader, path=path, error=error)


def read_yaml(path: str | Path, *, error: type[Exception], plain: bool = True, root: str | Path | None = None) -> Any:
    """Read the YAML file at ``path`` with every bound of :func:`load_yaml`: a file larger
    than :data:`MAX_YAML_FILE_BYTES` is refused before it is read, an alias bomb while it
    is composed (milliseconds, with the anchor's line). Only a regular file is read: a
    FIFO or a device is refused without blocking (:func:`phyagentos.untrusted.open_regular`).

    Args:
        path: the file.
        error: exception class for YAML problems (called with ``path=``/``line=`` when
            it takes them, else with the location in the message).
        plain: plain containers (:func:`load_plain`) or line-carrying ones (:func:`load_yaml`).
        root: when given, the file must resolve (links followed) inside this directory.

    Raises:
        OSError: the file cannot be read (``FileNotFoundError``; a special file:
            :class:`~phyagentos.untrusted.NotRegular`; outside ``root``:
            :class:`~phyagentos.untrusted.NotConfined`).
        error: too large, not UTF-8, a syntax error or a bound exceeded.
    """
    import os  # noqa: PLC0415

    from phyagentos.untrusted import open_regular  # noqa: PLC0415

    path = Path(path)
    fd = open_regular(path, root=root)
    with os.fdopen(fd, "rb") as fh:
        size = os.fstat(fd).st_size
        if size > MAX_YAML_FILE_BYTES:
            raise _error(error, f"YAML file of {size} bytes is larger than the limit of {MAX_YAML_FILE_BYTES}",
                         path=path, line=1)
        raw = fh.read(MAX_YAML_FILE_BYTES + 1)
    if len(raw) > MAX_YAML_FILE_BYTES:
        raise _error(error, f"YAML file is larger than the limit of {MAX_YAML_FILE_BYTES} bytes", path=path, line=1)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _error(error, f"not UTF-8 text: {exc.reason} at byte {exc.start}", path=path, line=None) from None
    return (load_plain if plain else load_yaml)(text, path=path, error=error)


def line_of(value: Any, key: Any = None) -> int | None:
    """Best-known 1-based line of ``value`` (or of ``key`` inside it)."""
    if isinstance(value, SourceMap):
        return value.key_line(key) if key is not None else value.line
    return getattr(value, "line", None)


def item_line(seq: Any, index: int) -> int | None:
    """1-based line of item ``index`` of a :class:`SourceList` (else the list's line, or ``None``)."""
    lines = getattr(seq, "item_lines", None)
    if lines is not None and 0 <= index < len(lines):
        return lines[index]
    return getattr(seq, "line", None)


def line_at(value: Any, loc: tuple[Any, ...] | list[Any]) -> int | None:
    """1-based line of the deepest node reachable from ``value`` along ``loc`` (mapping keys
    and sequence indices, e.g. a pydantic error's ``loc``): a key's own line, an item's line.
    A tail that cannot be followed (a missing key, a union branch name) stops the walk at
    the nearest known line."""
    line = line_of(value)
    for part in loc:
        if isinstance(value, SourceMap) and part in value:
            line, value = value.key_line(part), value[part]
        elif isinstance(value, SourceList) and isinstance(part, int) and 0 <= part < len(value):
            line, value = item_line(value, part), value[part]
        else:
            break
    return line


def to_plain(value: Any) -> Any:
    """``value`` with every :class:`SourceMap`/:class:`SourceList` turned into a plain
    ``dict``/``list`` (for data that is dumped with ``yaml.safe_dump`` or kept)."""
    if isinstance(value, dict):
        return {k: to_plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [to_plain(v) for v in value]
    return value
