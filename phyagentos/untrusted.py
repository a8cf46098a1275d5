"""Helpers for input nobody vouches for: one place for each bound (issue 33).

Every surface that takes text, files or bodies from a user, a browser or an MCP client
uses these, so each class of hostile input is handled once:

- :func:`quote`: user text quoted in a message, cut to :data:`MAX_QUOTE_CHARS` characters.
- :func:`redact_secrets`: credentials (URL userinfo, ``key=`` / ``token=`` / ``password=``
  values, ``Authorization`` headers, ``sk-...`` keys, and every value registered with
  :func:`register_secret`) replaced by ``***``. The root error
  (:class:`~phyagentos.errors.PhyAgentOSError`) applies it to every message, the CLI's
  log handler through :class:`RedactingFilter`, the MCP server to every answer.
- :func:`loads_json`: JSON bounded in bytes and nesting depth *before* it is parsed (a
  deeply nested body is a ``ValueError``, never a ``RecursionError``).
- :func:`read_regular` / :func:`open_regular`: a file opened without blocking and read
  only if it is a regular file (a FIFO or a device is refused instead of hanging the
  reader), optionally only if it resolves, links followed, inside a root directory, and
  never more than a byte limit.
"""

from __future__ import annotations

import logging
import os
import re
import stat
import threading
from pathlib import Path
from typing import Any

__all__ = ["MAX_QUOTE_CHARS", "MAX_JSON_DEPTH", "MAX_PATH_CHARS", "quote", "redact_secrets", "register_secret",
           "RedactingFilter", "json_depth", "loads_json", "NotConfined", "NotRegular", "confined", "open_regular",
           "read_regular"]

#: Longest excerpt of user text quoted in a message (characters), as elsewhere in the project.
MAX_QUOTE_CHARS = 200
#: Deepest nesting of JSON arrays and objects accepted from outside (the view, MCP arguments).
MAX_JSON_DEPTH = 64
#: Longest relative path accepted from a URL or a request (characters); Linux's PATH_MAX is 4096.
MAX_PATH_CHARS = 1024
#: Longest path component (bytes, UTF-8); Linux's NAME_MAX.
MAX_NAME_BYTES = 255


def quote(text: Any, limit: int = MAX_QUOTE_CHARS) -> str:
    """``repr(text)`` (a string's first ``limit`` characters) with ``... (N chars)`` when cut:
    user text quoted in a message is bounded, never echoed whole."""
    s = text if isinstance(text, str) else repr(text)
    if len(s) <= limit:
        return repr(s) if isinstance(text, str) else s
    head = repr(s[:limit]) if isinstance(text, str) else s[:limit]
    return f"{head}... ({len(s)} chars)"


# -- secrets -------------------------------------------------------------------------------

_SECRET_WORDS = r"(?:api[_-]?key|apikey|access[_-]?token|auth[_-]?token|token|secret|password|passwd|pwd)"
_PATTERNS: tuple[tuple[re.Pattern[str], str], ...] = (
    # scheme://user:password@host or scheme://token@host
    (re.compile(r"(?i)\b([a-z][a-z0-9+.\-]*://)[^/\s@'\"<>]+@"), r"\1***@"),
    # ?api_key=...&token=...
    (re.compile(rf"(?i)([?&;]{_SECRET_WORDS}=)[^&#\s'\"]+"), r"\1***"),
    # Authorization: Bearer ...; Bearer ...
    (re.compile(r"(?i)\b(authorization\s*[:=]\s*(?:(?:bearer|basic|token)\s+)?)[^\s,;'\"]+"), r"\1***"),
    (re.compile(r"(?i)\b(bearer\s+)[A-Za-z0-9._~+/\-]+=*"), r"\1***"),
    # api_key: XYZ, password=XYZ, "token": "XYZ"
    (re.compile(rf"(?i)\b({_SECRET_WORDS}[\"']?\s*[:=]\s*[\"']?)[^\s\"',;&)}}\]]+"), r"\1***"),
    # provider key formats (OpenAI-style sk-..., GitHub ghp_...)
    (re.compile(r"\b(sk|pk|rk)-[A-Za-z0-9_\-]{16,}"), r"\1-***"),
    (re.compile(r"\bgh[pousr]_[A-Za-z0-9]{20,}"), "gh*_***"),
)
_REGISTERED: set[str] = set()
_REGISTERED_LOCK = threading.Lock()
#: Registered secrets shorter than this are not replaced (they would mangle ordinary words).
MIN_REGISTERED_SECRET_CHARS = 6


def register_secret(value: str | None) -> None:
    """Redact ``value`` (e.g. the API key read from the environment) wherever it appears
    in a message from now on; values shorter than :data:`MIN_REGISTERED_SECRET_CHARS`
    characters are ignored."""
    if value and len(value) >= MIN_REGISTERED_SECRET_CHARS:
        with _REGISTERED_LOCK:
            _REGISTERED.add(value)


def redact_secrets(text: str) -> str:
    """``text`` with credentials replaced by ``***`` (see the module docstring).

    Idempotent and total: any string in, a string out (never raises)."""
    if not isinstance(text, str) or not text:
        return text
    for value in tuple(_REGISTERED):
        if value in text:
            text = text.replace(value, "***")
    for pattern, repl in _PATTERNS:
        text = pattern.sub(repl, text)
    return text


class RedactingFilter(logging.Filter):
    """A logging filter that redacts the formatted message of every record it passes
    (attach it to a handler: handler filters see records from every logger)."""

    def filter(self, record: logging.LogRecord) -> bool:  # noqa: A003 - logging's name
        try:
            message = record.getMessage()
        except Exception:  # noqa: BLE001 - a broken format is logging's to report
            return True
        clean = redact_secrets(message)
        if clean != message or record.args:
            record.msg, record.args = clean, None
        if record.exc_info and record.exc_info[1] is not None and not record.exc_text:
            import traceback  # noqa: PLC0415

            record.exc_text = redact_secrets("".join(traceback.format_exception(*record.exc_info)).rstrip())
            record.exc_info = None
        return True


# -- JSON -----------------------------------------------------------------------------------

_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)
_BRACKETS = re.compile(r"[\[\]{}]")


def json_depth(text: str) -> int:
    """Deepest nesting of arrays/objects in JSON ``text``, found without parsing it
    (strings skipped; linear time, no recursion)."""
    depth = deepest = 0
    for ch in _BRACKETS.findall(_JSON_STRING.sub('""', text)):
        if ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        else:
            depth -= 1
    return deepest


def loads_json(data: bytes | str, *, max_bytes: int, max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON from outside, bounded before parsing.

    Args:
        data: the text (UTF-8 bytes or str).
        max_bytes: longest accepted input (bytes; characters for a str).
        max_depth: deepest accepted nesting of arrays and objects.

    Raises:
        ValueError: too long, too deep, not UTF-8 or not JSON (the message says which,
            and never quotes more than :data:`MAX_QUOTE_CHARS` characters of the input).
    """
    import json  # noqa: PLC0415

    if len(data) > max_bytes:
        raise ValueError(f"JSON of {len(data)} bytes is longer than the limit of {max_bytes}")
    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ValueError(f"JSON is not UTF-8 (byte {exc.start})") from None
    depth = json_depth(data)
    if depth > max_depth:
        raise ValueError(f"JSON nested {depth} levels deep; the limit is {max_depth}")
    try:
        return json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise ValueError(f"not JSON: {quote(str(exc))}") from None


# -- files ----------------------------------------------------------------------------------


class NotConfined(OSError):
    """A path resolves (links followed) outside the directory it must stay in."""


class NotRegular(OSError):
    """A path names something other than a regular file (a FIFO, a device, a directory)."""


def confined(root: str | os.PathLike[str], path: str | os.PathLike[str]) -> Path:
    """``path`` resolved with every link followed, if it stays inside ``root`` (also resolved).

    Raises:
        NotConfined: it resolves outside ``root``, or is too long to resolve
            (:data:`MAX_PATH_CHARS`, :data:`MAX_NAME_BYTES`).
    """
    text = os.fspath(path)
    if len(text) > MAX_PATH_CHARS + len(os.fspath(root)) + 1 or \
            any(len(part.encode("utf-8", "surrogateescape")) > MAX_NAME_BYTES for part in Path(text).parts):
        raise NotConfined(f"path of {len(text)} characters is too long")
    base = Path(root).resolve()
    try:
        resolved = Path(path).resolve()
    except (OSError, RuntimeError) as exc:  # a link loop, a name too long
        raise NotConfined(f"{quote(text)} cannot be resolved: {exc.__class__.__name__}") from None
    if resolved != base and not resolved.is_relative_to(base):
        raise NotConfined(f"{quote(text)} resolves outside {base}")
    return resolved


def open_regular(path: str | os.PathLike[str], *, root: str | os.PathLike[str] | None = None) -> int:
    """A read-only descriptor of ``path``, opened with ``O_NONBLOCK`` (a FIFO without a
    writer never blocks the caller) and kept only if it is a regular file; with ``root``,
    only if the path resolves (links followed) inside ``root``. The caller closes it.

    Raises:
        FileNotFoundError: no such file.
        NotConfined: outside ``root``.
        NotRegular: a FIFO, a socket, a device or a directory.
        OSError: it cannot be opened.
    """
    target = confined(root, path) if root is not None else Path(path)
    fd = os.open(target, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOCTTY", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotRegular(f"{quote(os.fspath(path))} is not a regular file")
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd


def read_regular(path: str | os.PathLike[str], *, limit: int, root: str | os.PathLike[str] | None = None) -> bytes:
    """The bytes of the regular file ``path`` (see :func:`open_regular`), at most ``limit``.

    Raises:
        FileNotFoundError, NotConfined, NotRegular, OSError: as :func:`open_regular`.
        ValueError: the file holds more than ``limit`` bytes (nothing is returned).
    """
    fd = open_regular(path, root=root)
    with os.fdopen(fd, "rb") as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"{quote(os.fspath(path))} is larger than the limit of {limit} bytes")
    return data
