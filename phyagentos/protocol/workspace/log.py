"""LOG.md of a Workspace: bounded recent entries, spliced appends, and the monthly JSONL
archive entries age out to (mixed into :class:`~phyagentos.protocol.Workspace`)."""

from __future__ import annotations

import json
import logging
import re
import threading
from collections import OrderedDict
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from phyagentos.errors import ProtocolError

from ..atomic import append_lines_durably, atomic_write_text
from ..codec import (
    PARSE_CACHE,
    Document,
    _fence_needed,
    _plain,
    _read_text,
    dump_yaml,
    parse_document,
    write_document,
)
from ..runs import inside_workspace
from ..schemas import LogDoc, LogEntry
from .parts import WorkspaceParts
from .states import ts_key

log = logging.getLogger(__name__)


#: LOG.md texts this process wrote, by path, with where their YAML body ends: the spliced
#: append (``Workspace._append_log_spliced``) edits only a text it knows the layout of.
_LOG_TEXTS: OrderedDict[str, tuple[str, int]] = OrderedDict()


_LOG_TEXTS_LOCK = threading.Lock()


_LOG_TEXTS_MAX = 64  # workspaces a process remembers its LOG.md text for


def _remember_log_text(path: Path, text: str, body_end: int) -> None:
    with _LOG_TEXTS_LOCK:
        _LOG_TEXTS[str(path)] = (text, body_end)
        _LOG_TEXTS.move_to_end(str(path))
        while len(_LOG_TEXTS) > _LOG_TEXTS_MAX:
            _LOG_TEXTS.popitem(last=False)


def _body_end(text: str, suffix: str) -> int:
    """Offset of the closing fence of a rendered document whose suffix is ``suffix``."""
    end = len(text) - len(suffix) - 1  # the newline after the closing fence
    start = end
    while start > 0 and text[start - 1] == "`":
        start -= 1
    return start


#: the session id of an archived log line (``_archive`` writes ``json.dumps`` of a LogEntry:
#: ids are plain, e.g. ``r20261123T070410-fb0c-h11-1``, so they need no JSON unescaping)
_LOG_SESSION_ID = re.compile(r'"session_id": "([^"\\]*)"')


class WorkspaceLog(WorkspaceParts):
    """LOG.md and its monthly archive. Mixed into :class:`~phyagentos.protocol.Workspace`."""

    def append_log(self, entry: LogEntry) -> None:
        """Append ``entry`` to LOG.md, moving entries beyond the newest
        :attr:`LOG_MAX_ENTRIES` to ``log/archive-YYYY-MM.jsonl`` (month of each
        entry's ``at``, one JSON object per line).

        Archived lines are written and fsynced before LOG.md is replaced, so a
        crash can duplicate an archived entry but never lose one.

        Raises:
            DocumentError: LOG.md is malformed (nothing is written).
            ProtocolError: LOG.md is missing.
            OSError: the archive cannot be written (LOG.md is left unchanged).
        """
        if not isinstance(entry, LogEntry):
            raise ProtocolError(f"append_log needs a LogEntry, got {type(entry).__name__}")
        _, filename, _ = self._doc("LOG")
        path = inside_workspace(self.root / filename, self.root)
        with self._lock("LOG"):
            try:
                text = _read_text(path)
            except FileNotFoundError:
                raise ProtocolError(f"{filename} missing from workspace {self.root}; "
                                    "Workspace.create restores it") from None
            doc = parse_document(text, LogDoc, path=path)
            if self._append_log_spliced(path, text, doc, entry):
                return
            doc.data.entries.append(entry)
            overflow = len(doc.data.entries) - self.LOG_MAX_ENTRIES
            if overflow > 0:
                self._archive(doc.data.entries[:overflow])
                del doc.data.entries[:overflow]
            write_document(doc)
            written = _read_text(path)  # what was just written, under the lock
            _remember_log_text(path, written, _body_end(written, doc.suffix))

    def log_entries_of(self, session_ids: Iterable[str], *, since: str) -> list[LogEntry]:
        """The log entries of ``session_ids``, oldest first: those in LOG.md and those aged out
        to ``log/archive-YYYY-MM.jsonl`` from the month of ``since`` (a UTC timestamp,
        ``2026-11-23T07:00:00Z``) on. An archived line that does not parse is skipped with
        a warning (the archive is append-only: a torn last line is a crash's, not data).

        Raises:
            DocumentError: LOG.md is malformed.
            ProtocolError: LOG.md is missing.
        """
        wanted = set(session_ids)
        if not wanted:
            return []
        current = [e for e in self.read("LOG").data.entries if e.session_id in wanted]
        first = f"archive-{ts_key(since).strftime('%Y-%m')}.jsonl"
        archived: list[LogEntry] = []
        for archive in sorted(self.log_dir.glob("archive-*.jsonl")) if self.log_dir.is_dir() else []:
            if archive.name < first:
                continue
            with open(archive, encoding="utf-8") as handle:
                for number, line in enumerate(handle, 1):
                    found = _LOG_SESSION_ID.search(line)  # one look-up a line, however many sessions
                    if found is None or found.group(1) not in wanted:
                        continue
                    try:
                        archived.append(LogEntry.model_validate(json.loads(line)))
                    except (ValueError, ValidationError) as exc:
                        log.warning("%s:%d: log line skipped: %s", archive, number, exc)
        return archived + current

    def _append_log_spliced(self, path: Path, text: str, doc: Document[Any], entry: LogEntry) -> bool:
        """Append ``entry`` (and age out the oldest entry at the bound) by editing the text
        instead of rendering every entry again: LOG.md is rewritten on every transition
        and rendering 200 entries took ~15 ms. Only when ``text`` is exactly what this
        process last wrote (so its layout is the renderer's: one ``- `` line at column 0
        per entry, the entries last, a three-backtick fence), the entry's lines cannot
        touch the fence, no entry ends the YAML open-ended and at most one entry ages out; the result is then byte for byte
        what rendering the whole document gives (property test). Returns False to have
        the caller render the whole document instead."""
        with _LOG_TEXTS_LOCK:
            known = _LOG_TEXTS.get(str(path))
        if known is None or known[0] != text or not doc.data.entries or len(doc.data.entries) > self.LOG_MAX_ENTRIES:
            return False
        body_end = known[1]
        if text[body_end:body_end + 4] != "```\n":
            return False
        plain = entry.model_dump(mode="python", warnings=False)
        block = dump_yaml({"entries": [plain]})
        if not block.startswith("entries:\n- ") or _fence_needed(block) > 3 or not _plain(plain):
            return False
        item = block[len("entries:\n"):]
        prefix = doc.prefix if not doc.prefix or doc.prefix.endswith("\n") else doc.prefix + "\n"
        body_start = len(prefix) + len("```yaml\n")
        head, tail = text[:body_end], text[body_end:]
        if head.endswith("\n...\n") or item.endswith("\n...\n"):
            # libyaml ends a document with "..." once any scalar in it was open-ended (a
            # literal block keeping its final newlines): whether the whole log still needs
            # the marker depends on every entry, so such logs are rendered whole.
            return False
        entries = [*doc.data.entries, LogEntry.model_validate(plain)]
        if len(entries) > self.LOG_MAX_ENTRIES:
            first = head.find("\nentries:\n- ", body_start - 1)
            if first < 0:
                return False
            first += len("\nentries:\n")
            second = head.find("\n- ", first)
            second = len(head) if second < 0 else second + 1
            self._archive(entries[:1])
            head = head[:first] + head[second:]
            entries = entries[1:]
        new_text = head + item + tail
        atomic_write_text(path, new_text)
        PARSE_CACHE.put("document", LogDoc, new_text,
                        (prefix, doc.data.model_copy(update={"entries": entries}), doc.suffix))
        _remember_log_text(path, new_text, len(head) + len(item))
        return True

    def _archive(self, entries: list[LogEntry]) -> None:
        by_month: dict[str, list[str]] = {}
        for item in entries:
            month = ts_key(item.at).strftime("%Y-%m")
            line = json.dumps(item.model_dump(mode="json"), ensure_ascii=False)
            by_month.setdefault(month, []).append(line + "\n")
        for month, lines in sorted(by_month.items()):
            append_lines_durably(self.log_dir / f"archive-{month}.jsonl", lines)
        log.debug("archived %d log entries", len(entries))

