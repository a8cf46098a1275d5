"""Another target for a failed node: the SkillRuntime-Target Selector asked again, after a failure.

A revision may move a node to another target (``Revision.target``) when the failure is one of
the arm's own reach or planning (:data:`RETARGET_CAUSES`) and another enabled target of
TARGETS.md has the skill's capabilities and observations and reaches the poses: the
:func:`~phyagentos.agent.selector.select_target` the Goal Planner uses, asked about the
positions the failed attempt *perceived* (its evidence bundle's ``initial.yaml``), with the
reach oracle the composition root wires (the Runtime's IK through
:class:`~phyagentos.protocol.reach.ReachQuery`). Every target's reason is kept
(:class:`~phyagentos.agent.selector.Selection`), the failed one's as well.

A target is its own world (each simulates its own, or is a real robot): a node whose upstream
nodes moved things on the first target would not find them on another. So a re-target is only
offered for a node whose upstream nodes moved nothing: none, or only nodes of a skill that looks
(:data:`LOOKING_SKILLS`, e.g. the Goal Planner's look-first ``observe`` node on a fresh
workspace: the re-targeted node perceives its own world again before it acts); an upstream node
whose sessions cannot be found counts as one that moved things. Otherwise the answer says why
none is offered. The nodes downstream of a re-targeted node follow it to the new target
(:meth:`phyagentos.agent.coordinator.AgentCoordinator.world_target`).
"""

from __future__ import annotations

import logging
from typing import Any, Mapping, Sequence

from phyagentos.errors import ProtocolError, VerifierError
from phyagentos.protocol import SessionRecord, Workspace
from phyagentos.protocol.reach import ReachOracle

from .recovery import ACQUIRING_SKILLS, RETARGET_CAUSES
from .selector import Selection, SkillRequirements, select_target
from .verifier import load_evidence

__all__ = ["LOOKING_SKILLS", "RETARGET_CAUSES", "TargetChooser"]

logger = logging.getLogger(__name__)

#: Skills that only look: an upstream node of these left nothing in its target's world.
LOOKING_SKILLS = frozenset({"observe"})


class TargetChooser:
    """Chooses another capable target for a failed session's node.

    Args:
        workspace: the workspace (TARGETS.md, and the evidence bundles of failed attempts).
        reach: the reach oracle (the Runtime's IK); ``None``: the selector's reach envelope only.
        requirements: skill requirements (default: the skill manifests).
    """

    def __init__(self, workspace: Workspace, *, reach: ReachOracle | None = None,
                 requirements: Mapping[str, SkillRequirements] | None = None):
        self.workspace = workspace
        self.reach = reach
        self.requirements = requirements
        self._chosen: dict[str, Selection] = {}

    def perceived_positions(self, session: SessionRecord) -> dict[str, list[float]]:
        """Object name -> (x, y) m in the world frame, as the session's last attempt perceived them
        (its evidence bundle's initial snapshot); empty when there is none."""
        attempt = session.attempts[-1] if session.attempts else None
        if attempt is None or not attempt.evidence:
            return {}
        try:
            bundle = load_evidence(self.workspace.root / attempt.evidence)
        except VerifierError as exc:
            logger.warning("no perceived positions for %s: %s", session.session_id, exc)
            return {}
        return {str(e["name"]): [float(e["position"][0]), float(e["position"][1])]
                for e in bundle.initial.get("entities") or []
                if e.get("kind") == "object" and e.get("position") is not None}

    def _acting_upstream(self, session: SessionRecord) -> list[str]:
        """The upstream nodes of ``session`` that may have moved things: all but those whose sessions in
        this run are of a :data:`LOOKING_SKILLS` skill (a node with no session found counts as acting)."""
        if not session.depends_on:
            return []
        skills: dict[str, set[str]] = {}
        try:
            for rec in self.workspace.list_sessions(run_id=session.run_id):
                skills.setdefault(rec.node, set()).add(rec.skill)
        except (ProtocolError, OSError) as exc:  # unreadable: every upstream node counts as acting
            logger.warning("upstream sessions of %s not read: %s", session.session_id, exc)
            return list(session.depends_on)
        return [n for n in session.depends_on if not skills.get(n) or not skills[n] <= LOOKING_SKILLS]

    def choose(self, session: SessionRecord, *, cause: str, targets: Sequence[Mapping[str, Any]] | None = None) -> Selection:
        """The selector's choice among the targets other than ``session.target`` for ``session``'s node
        (``Selection.target`` ``None`` when none fits, with each target's reason). Asked once per session."""
        if session.session_id in self._chosen:
            return self._chosen[session.session_id]
        failed = f"failed here: {cause}"
        acting = self._acting_upstream(session)
        if acting:
            sel = Selection(None, None, {session.target: failed, "*": (
                f"not offered: the node depends on {', '.join(acting)}, whose effects are in "
                f"{session.target}'s world; another target is another world")})
            self._chosen[session.session_id] = sel
            return sel
        if targets is None:
            targets = [t.model_dump(mode="json") for t in self.workspace.read("TARGETS").data.targets]
        others = [t for t in targets if t["name"] != session.target]
        obj = session.parameters.get("object")
        dest = session.parameters.get("region")
        obj = obj if isinstance(obj, str) else None
        dest = dest if isinstance(dest, str) else None
        seen = self.perceived_positions(session)
        wanted = [n for n in (obj, dest) if n]
        positions = {n: seen[n] for n in wanted if n in seen}
        regions = {r.get("name") for r in (session.scene or {}).get("regions") or [] if isinstance(r, dict)}
        unknown = [n for n in wanted if n not in seen and n not in regions]
        declared = {str(o["name"]): [float(o["position"][0]), float(o["position"][1])]
                    for o in (session.scene or {}).get("objects") or []
                    if isinstance(o, dict) and o.get("name") in unknown and o.get("position") is not None}
        sel = select_target(session.skill, targets=others, positions=positions, unknown=unknown,
                            requirements=self.requirements, reach=self.reach, scene=session.scene or {},
                            pick=obj if session.skill in ACQUIRING_SKILLS else None,
                            place=(obj, dest) if obj and dest else None, declared=declared)
        sel = Selection(sel.target, sel.runtime, {session.target: failed, **sel.reasons}, sel.out_of_reach, sel.fits)
        logger.info("re-target for %s (%s): %s", session.session_id, cause, sel.target or "none fits")
        self._chosen[session.session_id] = sel
        return sel
