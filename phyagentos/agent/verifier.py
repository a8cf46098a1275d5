"""SessionVerifier: judge an evidence bundle against the session's acceptance criteria.

The verdict comes from evidence (initial and terminal snapshots, runtime outcome,
safety events), never from a controller's return code alone:

- every criterion satisfied and no safety intervention -> ``success``;
- a criterion unknown (evidence missing) -> ``failure``: we cannot judge, so we do
  not claim success and do not retry blindly;
- a criterion unsatisfied -> ``replan`` while the session's replan budget lasts and
  the failure is not a safety stop, else ``failure``.

Verifiers are composable behind :class:`Verifier`; :class:`PredicateVerifier` is the
first, a model-based judge can be appended to :class:`SessionVerifier` later.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Protocol, Sequence

import yaml

from phyagentos.errors import VerifierError
from phyagentos.protocol import CriterionResult, SessionRecord, Verdict
from phyagentos.protocol.lifecycle import utc_now

from .criteria import CriterionOutcome, evaluate, parse_criteria

__all__ = ["EvidenceBundle", "Verifier", "PredicateVerifier", "SessionVerifier", "load_evidence"]

logger = logging.getLogger(__name__)

# Snapshots are large; libyaml's safe loader parses them ~10x faster than PyYAML's.
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


@dataclass(frozen=True)
class EvidenceBundle:
    """What a session left behind, as read from ``evidence/<session_id>/``.

    Attributes:
        session_id: the session.
        directory: the bundle directory.
        initial, terminal: environment snapshots before and after execution.
        outcome: the runtime's outcome record (status, failed primitive, error code).
        events: safety and target events (each a mapping with ``code``).
        files: bundle-relative file names, used as evidence references.
    """

    session_id: str
    directory: Path
    initial: Mapping[str, Any]
    terminal: Mapping[str, Any]
    outcome: Mapping[str, Any]
    events: Sequence[Mapping[str, Any]]
    files: Mapping[str, str]


def load_evidence(directory: str | Path) -> EvidenceBundle:
    """Read ``bundle.yaml`` and the snapshots it references.

    Raises:
        VerifierError: if the bundle or a referenced file is missing or unreadable.
    """
    directory = Path(directory)
    index = directory / "bundle.yaml"
    try:
        bundle = yaml.load(index.read_text(encoding="utf-8"), Loader=_YAML_LOADER)
        files = bundle["files"]

        def load(key):
            name = files.get(key)
            return yaml.load((directory / name).read_text(encoding="utf-8"), Loader=_YAML_LOADER) if name else {}

        return EvidenceBundle(
            session_id=bundle["session_id"],
            directory=directory,
            initial=load("initial") or {},
            terminal=load("terminal") or {},
            outcome=bundle.get("outcome", {}),
            events=load("events") or [],
            files=files,
        )
    except (OSError, KeyError, TypeError, yaml.YAMLError) as exc:
        raise VerifierError(f"evidence bundle {index} unreadable: {exc}") from None


class Verifier(Protocol):
    """Anything that turns (session, evidence) into per-criterion outcomes."""

    name: str

    def judge(self, session: SessionRecord, evidence: EvidenceBundle) -> list[CriterionOutcome]: ...


class PredicateVerifier:
    """Evaluates the structured ``accept`` predicates on the snapshots."""

    name = "predicates"

    def judge(self, session: SessionRecord, evidence: EvidenceBundle) -> list[CriterionOutcome]:
        criteria = parse_criteria(session.accept, where=f"session {session.session_id} accept")
        refs = tuple(f"{evidence.directory.name}/{evidence.files[k]}" for k in ("initial", "terminal") if k in evidence.files)
        return [evaluate(c, evidence.initial, evidence.terminal, refs=refs) for c in criteria]


class SessionVerifier:
    """Composes verifiers and turns their outcomes into a :class:`Verdict`.

    Args:
        verifiers: judges run in order; all their outcomes count.
        max_replans: replan budget along one lineage (root session + children).
    """

    def __init__(self, verifiers: Sequence[Verifier] | None = None, *, max_replans: int = 2):
        self.verifiers = list(verifiers) if verifiers is not None else [PredicateVerifier()]
        self.max_replans = max_replans

    def verify(self, session: SessionRecord, evidence: EvidenceBundle, *, lineage_depth: int = 0) -> Verdict:
        """Judge ``evidence`` for ``session``.

        Args:
            lineage_depth: how many replans preceded this session (0 for a root).

        Raises:
            VerifierError: malformed acceptance criteria.
        """
        outcomes: list[CriterionOutcome] = []
        for verifier in self.verifiers:
            outcomes.extend(verifier.judge(session, evidence))
        criteria = [
            CriterionResult(
                name=o.criterion.name, predicate=o.criterion.text, status=o.status, reason=o.reason, evidence=list(o.evidence)
            )
            for o in outcomes
        ]
        safety = [e for e in evidence.events if str(e.get("code", "")).startswith("safety.")]
        runtime_error = evidence.outcome.get("error_code")
        names = "+".join(v.name for v in self.verifiers)
        if not outcomes:
            return Verdict(verdict="failure", reason="no acceptance criteria: a controller return code alone never counts as success",
                           criteria=criteria, verifier=names, at=utc_now())
        unknown = [o for o in outcomes if o.status == "unknown"]
        unsatisfied = [o for o in outcomes if o.status == "unsatisfied"]
        if not unknown and not unsatisfied and not safety:
            return Verdict(verdict="success", reason=f"all {len(outcomes)} criteria satisfied", criteria=criteria,
                           verifier=names, at=utc_now())
        if unknown:
            reason = "cannot judge: " + "; ".join(f"{o.criterion.text}: {o.reason}" for o in unknown)
            return Verdict(verdict="failure", reason=reason, criteria=criteria, verifier=names, at=utc_now())
        detail = "; ".join(f"{o.criterion.text}: {o.reason}" for o in unsatisfied)
        if safety:
            codes = sorted({str(e["code"]) for e in safety})
            return Verdict(verdict="failure", reason=f"safety intervention {codes}; {detail}".rstrip("; "),
                           criteria=criteria, verifier=names, at=utc_now())
        if runtime_error:
            detail = f"{detail} (runtime reported {runtime_error})"
        if lineage_depth < self.max_replans:
            return Verdict(verdict="replan", reason=f"unsatisfied: {detail}; replan {lineage_depth + 1}/{self.max_replans}",
                           criteria=criteria, verifier=names, at=utc_now())
        return Verdict(verdict="failure", reason=f"unsatisfied after {lineage_depth} replans: {detail}",
                       criteria=criteria, verifier=names, at=utc_now())
