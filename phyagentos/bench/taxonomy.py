"""Error taxonomy of unsuccessful sessions, derived from their evidence.

Categories (the paper's Section 4.4): ``perception``, ``policy``, ``adapter``,
``execution``, ``timeout``, ``safety``, ``verifier``. A session is classified from, in
order of precedence:

0. the verdict's diagnosis when the verifier made one (its category and cause);
1. its lifecycle state (``rejected`` -> adapter: preflight refused the composition;
   ``timed_out`` -> timeout);
2. safety events in the evidence bundle (``safety.*`` codes) -> safety;
3. the runtime's error code, by prefix (table :data:`CODE_PREFIXES`): perception
   failures, the skill failing to produce a motion (IK, planning, timing) as *policy*,
   actuation that did not do what was commanded (tracking, grasp missed or slipped,
   target errors) as *execution*;
4. otherwise the runtime reported completion but the verdict found the world wrong (or
   could not judge it): *verifier* — a failure only the SessionVerifier caught.

A code matching no prefix is reported as ``other`` with the code, never dropped.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

__all__ = ["CATEGORIES", "CODE_PREFIXES", "classify"]

CATEGORIES: tuple[str, ...] = ("perception", "policy", "adapter", "execution", "timeout", "safety", "verifier", "other")

#: Error-code prefix -> category (first match wins; codes are ``<subsystem>.<detail>``).
CODE_PREFIXES: tuple[tuple[str, str], ...] = (
    ("perception.", "perception"),
    ("ik.", "policy"),
    ("planning.", "policy"),
    ("timing.", "policy"),
    ("motion.", "policy"),
    ("skill.", "policy"),
    ("policy.", "policy"),
    ("preflight.", "adapter"),
    ("adapter.", "adapter"),
    ("bridge.", "adapter"),
    ("execution.", "execution"),
    ("grasp.", "execution"),
    ("target.", "execution"),
    ("runtime.", "execution"),
    ("cancelled.", "execution"),
    ("timeout.", "timeout"),
    ("heartbeat.", "timeout"),
    ("safety.", "safety"),
    ("verifier.", "verifier"),
)


def _by_code(code: str) -> str:
    for prefix, category in CODE_PREFIXES:
        if code.startswith(prefix):
            return category
    return "other"


#: Categories of the verifier's diagnosis (:mod:`phyagentos.agent.diagnosis`) that are
#: named differently here.
_DIAGNOSIS_CATEGORY = {"planning": "policy", "precondition": "execution", "unknown": "other"}


def classify(*, state: str, error_code: str | None, rejection_codes: Sequence[str] = (),
             events: Sequence[Mapping[str, Any]] = (), diagnosis: Mapping[str, Any] | None = None) -> tuple[str, str]:
    """``(category, cause)`` of an unsuccessful session; ``cause`` is the code or rule used.

    A verdict's ``diagnosis`` (category and cause the verifier derived from the evidence,
    e.g. perceived versus true object pose) wins over the rules below when present.
    """
    if diagnosis and diagnosis.get("category"):
        category = str(diagnosis["category"])
        category = _DIAGNOSIS_CATEGORY.get(category, category)
        return (category if category in CATEGORIES else "other"), str(diagnosis.get("cause") or category)
    if state == "rejected":
        return "adapter", rejection_codes[0] if rejection_codes else "preflight.rejected"
    if state == "timed_out":
        return "timeout", error_code or "timeout.execution"
    safety = [str(e.get("code")) for e in events if str(e.get("code", "")).startswith("safety.")]
    if safety:
        return "safety", safety[0]
    if error_code:
        return _by_code(error_code), error_code
    return "verifier", "verdict.unsatisfied"
