"""Tool policy for text that reaches a model: instructions and entity names.

An instruction or an object name that tries to change the rules ("ignore the safety
limits", "disable the guard") is rejected before any model sees it, logged with the
offending text, and nothing moves. Names must also be plain identifiers
(``^[a-z][a-z0-9_]*$``): anything else cannot be a goal-graph value.

This is a policy filter, not the planner: it decides nothing about *what* to do, only
refuses text that asks to bypass the SafetyGuard or the validator.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass

__all__ = ["InjectionFinding", "screen_text", "INJECTION_PATTERNS", "NAME_PATTERN"]

logger = logging.getLogger(__name__)

NAME_PATTERN = re.compile(r"^[a-z][a-z0-9_]*$")

#: (code, pattern): phrases that ask to bypass safety or the system's own instructions.
INJECTION_PATTERNS: tuple[tuple[str, re.Pattern[str]], ...] = (
    ("override_instructions", re.compile(r"\b(ignore|disregard|forget|override)\b.{0,40}"
                                         r"\b(instruction|rule|prompt|polic|limit|safety|guard|constraint)", re.I)),
    ("disable_safety", re.compile(r"\b(disable|deactivate|turn\s+off|switch\s+off|bypass|remove|skip|circumvent)\b"
                                  r".{0,40}\b(guard|safety|limit|e-?stop|emergency|validator|check|constraint)", re.I)),
    ("unsafe_motion", re.compile(r"\b(max(imum)?|full|unlimited)\s+(speed|force|torque|velocity)\b"
                                 r"|\bas\s+fast\s+as\s+possible\b|\bno\s+limits?\b", re.I)),
    ("role_hijack", re.compile(r"\b(you\s+are\s+now|new\s+instructions?|system\s+prompt|jailbreak|developer\s+mode)\b", re.I)),
)


@dataclass(frozen=True)
class InjectionFinding:
    """One rejected text: where it came from, the policy code and the offending text."""

    source: str
    code: str
    text: str
    match: str

    def __str__(self) -> str:
        from phyagentos.untrusted import quote  # noqa: PLC0415

        return f"{self.source}: {self.code} ({quote(self.match, 80)} in {quote(self.text)})"


def screen_text(text: str, *, source: str) -> list[InjectionFinding]:
    """Every policy violation in ``text`` (empty list: acceptable). Findings are logged at WARNING."""
    findings = []
    for code, pattern in INJECTION_PATTERNS:
        m = pattern.search(text)
        if m:
            findings.append(InjectionFinding(source=source, code=code, text=text, match=m.group(0)))
    for f in findings:
        logger.warning("policy rejected %s", f)
    return findings
