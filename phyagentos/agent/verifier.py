"""SessionVerifier: judge an evidence bundle against the session's acceptance criteria.

The verdict is the paper's V(G, S0, ST, tau, H): task and criteria G, initial and
terminal snapshots S0 and ST, trace tau, history H (the session's lineage). It comes
from evidence, never from a controller's return code alone:

- every criterion satisfied and no safety intervention -> ``success``;
- a criterion ``unknown`` (the entity not perceived, perceived below the confidence
  threshold, or within the uncertainty band of the boundary, see
  :mod:`phyagentos.agent.criteria`) and nothing else explains the failure -> ``replan``
  with a revision asking for another view (a child of skill ``observe`` with more
  frames, judged on that view) once, then ``failure`` with cause
  ``perception_unknown``. Never ``success``;
- a criterion unsatisfied -> ``replan`` while the session's replan budget lasts, the
  failure is not a safety stop, and a recovery strategy is left for the diagnosed
  cause; else ``failure``. The recovery gets the evidence bundle too (the policy ladder
  reads what it leaves of the instruction's steps).

The snapshots are the runtime's *perceived* snapshots; the verifier never reads the
simulator's privileged channel.

Every verdict that is not a success carries a :class:`~phyagentos.protocol.Diagnosis`
(:mod:`phyagentos.agent.diagnosis`); a ``replan`` verdict carries the
:class:`~phyagentos.protocol.Revision` its child session runs with
(:mod:`phyagentos.agent.recovery`).

Judges are composable behind :class:`Verifier`: :class:`PredicateVerifier` evaluates the
structured predicates; a model-based judge returning the same per-criterion outcomes
can be appended to :class:`SessionVerifier` later.
"""

from __future__ import annotations

import json
import logging
import posixpath
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Protocol, Sequence

import yaml

from phyagentos.errors import VerifierError
from phyagentos.protocol import CriterionResult, SessionRecord, Verdict
from phyagentos.protocol.lifecycle import utc_now
from phyagentos.yamlsource import read_yaml

from .criteria import CriterionOutcome, evaluate, parse_criteria
from .diagnosis import diagnose
from .held_object import refine
from .recovery import RecoveryPlanner

__all__ = ["EvidenceBundle", "Verifier", "PredicateVerifier", "SessionVerifier", "load_evidence"]

logger = logging.getLogger(__name__)

_IMAGE_KEYS = ("initial_image", "terminal_image")


@dataclass(frozen=True)
class EvidenceBundle:
    """What a session left behind, as read from ``evidence/<session_id>/``.

    Attributes:
        session_id: the session.
        directory: the bundle directory.
        initial, terminal: perceived environment snapshots before and after execution.
        outcome: the runtime's outcome record (status, failed primitive, error code).
        events: safety and target events (each a mapping with ``code``).
        files: bundle key -> file name (``initial``, ``terminal``, ``trace``,
            ``events``, ``task``, ``initial_image``, ``terminal_image`` ...).
        trace: the action/observation trace, one mapping per record (may be empty).
        task: the task definition the runtime ran (may be empty for old bundles).
    """

    session_id: str
    directory: Path
    initial: Mapping[str, Any]
    terminal: Mapping[str, Any]
    outcome: Mapping[str, Any]
    events: Sequence[Mapping[str, Any]]
    files: Mapping[str, str]
    trace: Sequence[Mapping[str, Any]] = field(default_factory=tuple)
    task: Mapping[str, Any] = field(default_factory=dict)

    def ref(self, key: str) -> str | None:
        """Workspace-relative path (``evidence/<session>/<file>``) of bundle file ``key``,
        or ``None`` if the bundle has no such file (or it was pruned)."""
        name = self.files.get(key)
        if not name or not (self.directory / name).exists():
            return None
        return posixpath.normpath(f"{self.directory.parent.name}/{self.directory.name}/{name}")

    def refs(self, *keys: str) -> tuple[str, ...]:
        """:meth:`ref` of each key that exists, in order."""
        return tuple(r for r in (self.ref(k) for k in keys) if r)

    @property
    def images(self) -> tuple[str, ...]:
        """Workspace-relative paths of the RGB images still on disk."""
        return self.refs(*_IMAGE_KEYS)


def _read_trace(path: Path) -> tuple[dict, ...]:
    if not path.is_file():
        return ()
    records = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.strip():
            records.append(json.loads(line))
    return tuple(records)


def load_evidence(directory: str | Path) -> EvidenceBundle:
    """Read ``bundle.yaml`` and the snapshots, events, trace and task it references.

    Raises:
        VerifierError: if the bundle or a referenced snapshot is missing or unreadable.
    """
    directory = Path(directory)
    index = directory / "bundle.yaml"
    try:
        # bounded (phyagentos.yamlsource): an alias bomb in any evidence file is refused in
        # milliseconds as a VerifierError naming the file and line (the run is set aside)
        bundle = read_yaml(index, error=VerifierError)
        files = bundle["files"]

        def load(key):
            name = files.get(key)
            return read_yaml(directory / name, error=VerifierError) if name else {}

        return EvidenceBundle(
            session_id=bundle["session_id"],
            directory=directory,
            initial=load("initial") or {},
            terminal=load("terminal") or {},
            outcome=bundle.get("outcome", {}),
            events=load("events") or [],
            files=files,
            trace=_read_trace(directory / files["trace"]) if files.get("trace") else (),
            task=load("task") or {},
        )
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError) as exc:
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
        refs = evidence.refs("initial", "terminal")
        # where the cameras leave holding/lifted unknown (the hand hides the object), the
        # held-object model decides from proprioception and forward kinematics
        return [refine(evaluate(c, evidence.initial, evidence.terminal, refs=refs), evidence) for c in criteria]


class SessionVerifier:
    """Composes verifiers and turns their outcomes into a :class:`Verdict`.

    Args:
        verifiers: judges run in order; all their outcomes count.
        max_replans: replan budget along one lineage (root session + children); a recovery
            that bounds a lineage itself (``replan_budget``: the policy ladder's rungs) sets it
            for that lineage.
        recovery: chooses the revision of a ``replan`` verdict (default: the built-in
            strategies for the shipped skills); a cause with no strategy left turns
            the verdict into ``failure``.
    """

    def __init__(self, verifiers: Sequence[Verifier] | None = None, *, max_replans: int = 2,
                 recovery: RecoveryPlanner | None = None):
        self.verifiers = list(verifiers) if verifiers is not None else [PredicateVerifier()]
        self.max_replans = max_replans
        self.recovery = recovery if recovery is not None else RecoveryPlanner()
        self.upstream: Callable[[SessionRecord], str | None] = lambda session: None

    def set_upstream(self, finder: Callable[[SessionRecord], str | None]) -> None:
        """Install ``finder(session) -> goal node id``: the node upstream of ``session``'s that
        acquires its object (the coordinator's DAG), for re-picks after a release."""
        self.upstream = finder

    def verify(self, session: SessionRecord, evidence: EvidenceBundle, *, lineage_depth: int | None = None,
               history: Sequence[SessionRecord] = ()) -> Verdict:
        """Judge ``evidence`` for ``session``.

        Args:
            lineage_depth: how many replans preceded this session (0 for a root);
                defaults to ``len(history)``.
            history: the session's ancestors, oldest first (their revisions and
                diagnoses decide the next escalation step).

        Raises:
            VerifierError: malformed acceptance criteria.
        """
        depth = len(history) if lineage_depth is None else lineage_depth
        outcomes: list[CriterionOutcome] = []
        for verifier in self.verifiers:
            outcomes.extend(verifier.judge(session, evidence))
        criteria = [
            CriterionResult(
                name=o.criterion.name, predicate=o.criterion.text, status=o.status, reason=o.reason, evidence=list(o.evidence)
            )
            for o in outcomes
        ]
        names = "+".join(v.name for v in self.verifiers)
        refs = list(evidence.refs("task", "initial", "terminal", "trace", "events", *_IMAGE_KEYS))

        def verdict(kind: str, reason: str, **extra) -> Verdict:
            return Verdict(verdict=kind, reason=reason, criteria=criteria, verifier=names, at=utc_now(), evidence=refs,
                           **extra)

        safety = [e for e in evidence.events if str(e.get("code", "")).startswith("safety.")]
        runtime_error = evidence.outcome.get("error_code")
        unknown = [o for o in outcomes if o.status == "unknown"]
        unsatisfied = [o for o in outcomes if o.status == "unsatisfied"]
        if outcomes and not unknown and not unsatisfied and not safety:
            return verdict("success", f"all {len(outcomes)} criteria satisfied")
        diagnosis = diagnose(session, evidence, unknown=[f"{o.criterion.text}: {o.reason}" for o in unknown])
        if not outcomes:
            return verdict("failure", "no acceptance criteria: a controller return code alone never counts as success",
                           diagnosis=diagnosis)
        detail = "; ".join(f"{o.criterion.text}: {o.reason}" for o in unsatisfied + unknown)
        if safety:
            codes = sorted({str(e["code"]) for e in safety})
            return verdict("failure", f"safety intervention {codes}; {detail}".rstrip("; "), diagnosis=diagnosis)
        if diagnosis.cause == "perception_unknown":
            detail = "cannot judge: " + detail
        elif runtime_error:
            detail = f"{detail} (runtime reported {runtime_error})"
        detail = f"{detail}; diagnosis {diagnosis.cause}: {diagnosis.summary}"
        limit = self._replan_limit(session, history)
        if depth >= limit:
            return verdict("failure", f"unsatisfied after {depth} replans: {detail}", diagnosis=diagnosis)
        revision = self.recovery.plan(session, diagnosis, history=history, upstream=self.upstream(session),
                                      evidence=evidence)
        if revision is None:
            return verdict("failure", f"no recovery strategy left for {diagnosis.cause}: {detail}",
                           diagnosis=diagnosis)
        return verdict("replan", f"{detail}; replan {depth + 1}/{limit} "
                                 f"with {revision.strategy}", diagnosis=diagnosis, revision=revision)

    def _replan_limit(self, session: SessionRecord, history: Sequence[SessionRecord]) -> int:
        """Replans ``session``'s lineage may take: the recovery's own bound for it where it states
        one (``replan_budget``: a prompt-driven policy's ladder, one per rung), else
        :attr:`max_replans`."""
        budget = getattr(self.recovery, "replan_budget", None)
        own = budget(session, history) if budget is not None else None
        return self.max_replans if own is None else int(own)
