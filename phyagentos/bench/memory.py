"""Memory protocols of a benchmark run: ``off``, ``frozen`` and ``learn``.

Each episode runs in its own workspace; its LESSONS.md, KNOWLEDGE.md and SKILL.md come
from the bench workspace (the *bench memory*) according to the mode, which also sets the
AgentCoordinator's switches (``use_memory`` retrieval, ``consolidate`` writing):

- ``off``: episodes start from the empty templates, retrieve nothing and keep nothing
  (the system without epistemic memory);
- ``frozen``: every episode retrieves from the same snapshot of the bench memory taken
  when the run was compiled and consolidates nothing (a *measurement*: results do not
  depend on episode order or worker count);
- ``learn``: an episode starts from the bench memory as it is when the episode starts,
  and afterwards its lessons and knowledge are merged back under the documents' locks
  (an *adaptation* pass: results depend on order, and the report says so).

Merging is by entry id (procedure name): counters grow by the episode's increments over
the snapshot it started from, lists are unioned, ``verified`` is or-ed, nested models
(a lesson's trial counts) merge by the same rules, other fields take the episode's value
(:func:`_merge_entries`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from pydantic import BaseModel

from phyagentos.errors import BenchError
from phyagentos.protocol import KnowledgeDoc, LessonsDoc, SkillDoc, Workspace

__all__ = ["MEMORY_MODES", "MEMORY_DOCS", "MemoryPolicy", "merge_lessons", "merge_knowledge", "merge_skills"]

logger = logging.getLogger(__name__)

MEMORY_MODES: tuple[str, ...] = ("off", "frozen", "learn")
MEMORY_DOCS = ("LESSONS", "KNOWLEDGE", "SKILL")


def _union(a: list, b: list) -> list:
    return list(dict.fromkeys([*a, *b]))


def _merge_entries(base: list, before: list, after: list, key: str) -> list:
    """Entries of ``base`` plus what an episode changed from ``before`` to ``after``.

    Per entry (matched on ``key``): unchanged ones are skipped; new ones are added; for
    one the bench memory has too, integer counters grow by the episode's increment,
    lists are unioned, ``verified`` is or-ed and every other field takes the
    episode's (newest) value.
    """
    merged = {getattr(e, key): e.model_copy(deep=True) for e in base}
    seen = {getattr(e, key): e for e in before}
    for entry in after:
        k = getattr(entry, key)
        prior = seen.get(k)
        if prior == entry:
            continue
        old = merged.get(k)
        if old is None:
            merged[k] = entry.model_copy(deep=True)
            continue
        merged[k] = _merge_model(old, prior, entry)
    return list(merged.values())


def _merge_model(cur: BaseModel, prior: BaseModel | None, new: BaseModel) -> BaseModel:
    """``cur`` plus what changed from ``prior`` to ``new``, field by field (the rules of
    :func:`_merge_entries`; a nested model, e.g. a lesson's trial counts, is merged by the
    same rules, so two episodes' trial steps and deaths add up)."""
    update = {}
    for name in type(new).model_fields:
        n, c = getattr(new, name), getattr(cur, name)
        p = getattr(prior, name) if prior is not None else None
        if isinstance(n, bool):
            update[name] = c or n if name == "verified" else n
        elif isinstance(n, int):
            update[name] = c + max(n - (p if isinstance(p, int) else 0), 0)
        elif isinstance(n, list):
            update[name] = _union(c, n)
        elif isinstance(n, BaseModel) and isinstance(c, BaseModel):
            update[name] = _merge_model(c, p if isinstance(p, BaseModel) else None, n)
        else:
            update[name] = n
    return type(new).model_validate({**cur.model_dump(), **{k: v.model_dump() if isinstance(v, BaseModel) else v
                                                            for k, v in update.items()}})


def merge_lessons(base: LessonsDoc, before: LessonsDoc, after: LessonsDoc) -> LessonsDoc:
    """``base`` plus what an episode added between ``before`` and ``after``; a candidate the
    episode confirmed into a lesson leaves the candidates."""
    lessons = _merge_entries(base.lessons, before.lessons, after.lessons, "id")
    ids = {lesson.id for lesson in lessons}
    candidates = [c for c in _merge_entries(base.candidates, before.candidates, after.candidates, "id")
                  if c.id not in ids]
    return base.model_copy(update={"lessons": lessons, "candidates": candidates})


def merge_knowledge(base: KnowledgeDoc, before: KnowledgeDoc, after: KnowledgeDoc) -> KnowledgeDoc:
    """``base`` plus the episode's increments between ``before`` and ``after`` (by entry id)."""
    return base.model_copy(update={"entries": _merge_entries(base.entries, before.entries, after.entries, "id")})


def merge_skills(base: SkillDoc, before: SkillDoc, after: SkillDoc) -> SkillDoc:
    """``base`` plus the procedures an episode promoted or updated (by name)."""
    return base.model_copy(update={"procedures": _merge_entries(base.procedures, before.procedures,
                                                                after.procedures, "name")})


_MERGES = {"LESSONS": (LessonsDoc, merge_lessons), "KNOWLEDGE": (KnowledgeDoc, merge_knowledge),
           "SKILL": (SkillDoc, merge_skills)}


@dataclass(frozen=True)
class MemoryPolicy:
    """Moves memory between the bench workspace and an episode workspace.

    Attributes:
        mode: one of :data:`MEMORY_MODES`.
        bench_root: the bench workspace directory (holds the bench memory).
        snapshot_dir: directory holding the ``frozen`` snapshot (LESSONS.md, KNOWLEDGE.md).
    """

    mode: str
    bench_root: Path
    snapshot_dir: Path

    def __post_init__(self) -> None:
        if self.mode not in MEMORY_MODES:
            raise BenchError(f"unknown memory mode {self.mode!r}; valid modes: {', '.join(MEMORY_MODES)}")

    @property
    def protocol(self) -> str:
        """``adaptation`` for ``learn``, else ``measurement``."""
        return "adaptation" if self.mode == "learn" else "measurement"

    def template_files(self) -> dict[str, Path]:
        """Memory documents an episode workspace is created from (``off``: none, the
        package templates are used)."""
        if self.mode == "off":
            return {}
        source = self.snapshot_dir if self.mode == "frozen" else self.bench_root
        return {key: source / f"{key}.md" for key in MEMORY_DOCS}

    def before_episode(self, episode_ws: Workspace) -> None:
        """``learn``: copy the current bench memory in and remember it as the baseline."""
        if self.mode != "learn":
            return
        bench = Workspace.open(self.bench_root)
        for key in MEMORY_DOCS:
            data = bench.read(key).data
            episode_ws.update(key, lambda _doc, data=data: data)
            (episode_ws.root / f".{key}.before.json").write_text(data.model_dump_json(), encoding="utf-8")

    def after_episode(self, episode_ws: Workspace) -> None:
        """``learn``: merge the episode's new lessons and knowledge into the bench memory."""
        if self.mode != "learn":
            return
        bench = Workspace.open(self.bench_root)
        for key in MEMORY_DOCS:
            model, merge = _MERGES[key]
            before = model.model_validate_json((episode_ws.root / f".{key}.before.json").read_text(encoding="utf-8"))
            after = episode_ws.read(key).data
            bench.update(key, lambda base, before=before, after=after, merge=merge: merge(base, before, after))
        logger.debug("merged memory of %s into %s", episode_ws.root, self.bench_root)
