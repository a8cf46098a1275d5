"""The Agent plane's loop for one run of a goal graph.

Everything it knows it reads from the workspace, so it can run in its own
process (``phyagentos agent``) or interleaved with the supervisor (``phyagentos run``):

1. verify every session of the run waiting in ``awaiting_verification``
   (SessionVerifier on the evidence bundle; the verdict, with its diagnosis and for a
   replan the proposed revision, is appended to the attempt), apply the evidence
   retention policy (images of successes are dropped unless kept on purpose), and
   consolidate the verdict into memory (lessons, knowledge, promoted procedures);
2. on ``replan``, compile an immutable child session (``parent_session_id``
   lineage, the revision's parameters, ``recovery`` recording why) and mark the
   parent ``replanned``; the correction it tries becomes a lesson *candidate*;
3. derive node states from the sessions, block the subgraph below a failure, and
   compile pending sessions for nodes whose dependencies succeeded, each with the
   memory the ContextBuilder retrieves for it (recorded in the session's ``context``);
4. write TASK.md.

Three recoveries change more than parameters (:mod:`phyagentos.agent.recovery`,
:mod:`phyagentos.agent.retarget`):

- *another view* (``Revision.skill == "observe"``): the child session only looks again;
  the criteria are then judged on the acting session's evidence with the child's
  terminal snapshot as the terminal state (the session that acted is judged, with a
  better look at its result);
- *re-pick upstream* (``Revision.reopen``): a place that found nothing in the hand
  re-opens the upstream node that acquires the object. The coordinator compiles a new
  session of that node (parent: its latest session, ``recovery`` naming the cause),
  records the re-opening on the DAG edge (``reopened_by`` on the edge upstream ->
  node, and the new session id among the failed session's ``child_session_ids``), and
  compiles the node's child once the re-pick succeeded; if it fails, the node is
  blocked;
- *re-target* (``Revision.target``): the child runs the same node, skill and criteria on
  the other target the selector chose; its later children, the nodes downstream of it and
  any re-opened upstream node follow it there (:meth:`AgentCoordinator.world_target`: each
  target is its own world).

The coordinator is split along these seams: this module holds its state, the step and
the TASK.md and LOG.md writes, and its mix-ins the rest: :mod:`~phyagentos.agent.run_view`
(the run's sessions, node states, lineage, observations, re-openings, summary),
:mod:`~phyagentos.agent.verification` (1: verdicts, retention, consolidation) and
:mod:`~phyagentos.agent.replanning` (2, and the re-opening of upstream nodes).
"""

from __future__ import annotations

import logging
import os
from collections import Counter, OrderedDict
from typing import Callable

import networkx as nx

from phyagentos.errors import PhyAgentOSError
from phyagentos.protocol import (
    LogEntry,
    SessionRecord,
    TaskDoc,
    TaskNode,
    Workspace,
    file_identity,
    is_expired,
)
from phyagentos.protocol.schemas import TransitionRecord

from . import dag as dagmod
from .declared import declared_scene
from .goal_graph import GoalGraph
from .memory import ContextBuilder, PromotionPolicy
from .model_calls import planner_calls, with_calls
from .recovery import RecoveryPlanner, targets_capabilities
from .replanning import Replanning, _descends  # noqa: F401  (_descends: tests import it from here)
from .run_view import RunView, SessionSummary, node_state_of
from .session_compiler import SessionCompiler, new_run_id
from .verification import _VERDICT_OF_EVENT, Verification
from .verifier import EvidenceBundle, SessionVerifier, load_evidence

__all__ = ["AgentCoordinator", "SessionSummary", "node_state_of"]

logger = logging.getLogger(__name__)

#: Evidence bundles an AgentCoordinator keeps parsed (:meth:`AgentCoordinator._evidence`).
_BUNDLES_KEPT = 64


class AgentCoordinator(RunView, Verification, Replanning):
    """Compiles, verifies and tracks one run of ``graph`` in ``workspace``.

    Args:
        workspace: the protocol workspace.
        graph: the validated goal graph.
        run_id: continue this run (default: a new run id).
        seed: base seed for the run's sessions.
        verifier: the SessionVerifier (default: predicates, 2 replans).
        evaluation: benchmark evaluation configuration recorded in every session.
        use_memory: retrieve lessons, knowledge and procedures for new sessions
            (``False``: run as if memory were empty; conditions are still recorded).
        consolidate: write verdicts into memory (LESSONS.md, KNOWLEDGE.md, SKILL.md);
            ``False`` keeps memory frozen (a measurement).
        keep_success_images: keep the RGB images of sessions whose verdict is success
            (failures always keep theirs).
        promotion: thresholds for promoting knowledge to SKILL.md.

    What it reads is :class:`~phyagentos.agent.run_view.RunView`'s, verdicts are
    :class:`~phyagentos.agent.verification.Verification`'s and child sessions
    :class:`~phyagentos.agent.replanning.Replanning`'s; it keeps the state, steps the
    run and writes TASK.md and the verdicts' LOG.md lines.
    """

    #: verdicts' LOG.md lines not yet appended (see :meth:`step`); a list once constructed
    _owed_log: list[LogEntry] | tuple = ()

    def __init__(self, workspace: Workspace, graph: GoalGraph, *, run_id: str | None = None, seed: int | None = 0,
                 verifier: SessionVerifier | None = None, evaluation: dict | None = None, use_memory: bool = True,
                 consolidate: bool = True, keep_success_images: bool = False,
                 promotion: PromotionPolicy | None = None):
        self.workspace = workspace
        self.graph = graph
        self.run_id = run_id or new_run_id()
        # frozen: the run's DAG never changes shape (edge attributes such as
        # ``reopened_by`` still may), so its topological order is sorted once
        self.dag = nx.freeze(dagmod.to_digraph(graph))
        self.compiler = SessionCompiler(workspace, graph, self.run_id, seed=seed, evaluation=evaluation)
        # the default ladder asks each node's target only for what TARGETS.md says it can do
        self.verifier = verifier or SessionVerifier(recovery=RecoveryPlanner(capabilities=targets_capabilities(workspace)))
        self.verifier.set_upstream(self.upstream_acquirer)
        self.context_builder = ContextBuilder(workspace, use_memory=use_memory, trials=consolidate)
        self.consolidate = consolidate
        self.keep_success_images = keep_success_images
        self.promotion = promotion or PromotionPolicy()
        #: called right after each session :meth:`step` submits (e.g. to wake a supervisor)
        self.on_submit: Callable[[], None] | None = None
        #: the run's sessions as the last :meth:`step` left them (for its caller's report)
        self.last_sessions: list[SessionRecord] | None = None
        #: ``True``: a step that submitted sessions leaves TASK.md (a view) to :meth:`write_task`,
        #: which its caller runs once the hand-off is over (``drive_run``: once no session of the
        #: run waits to be claimed or started), so that the step's re-listing and the view's
        #: rendering do not compete with the supervisor's claim for the interpreter
        self.defer_task_view = False
        #: whether TASK.md lags behind the last step (a deferred write is due)
        self.task_view_stale = False
        #: verdicts' LOG.md lines not yet appended (see :meth:`step`)
        self._owed_log: list[LogEntry] = []
        #: whether the first step looked for verdict lines an earlier agent of this run owed
        self._lines_checked = False
        #: evidence bundles read for verdicts and observations, by directory (see :meth:`_evidence`)
        self._bundles: OrderedDict[str, tuple[tuple[int, int, int], EvidenceBundle]] = OrderedDict()


    # -- the loop --------------------------------------------------------

    def step(self) -> int:
        """Verify, replan, compile ready nodes and write TASK.md; returns actions taken.

        The run's sessions are listed again only after a replan or a resumed node (a
        verdict patches the listing with the record it wrote); ``on_submit``, if set, is
        called as soon as a ready node's session is submitted (``drive_run`` wakes the
        supervisor with it, before TASK.md is rewritten).

        The verdicts' LOG.md lines are appended after the ready nodes are submitted:
        the verdict in the session file is what a dependent session waits for, and the
        log line only records it. With :attr:`defer_task_view`,
        a step that submitted leaves them to :meth:`write_task`, with TASK.md. Each line
        carries its verdict's time (``at``); another process's line may precede it. A
        coordinator's first step also appends the lines an earlier agent of the run died
        owing (:meth:`_verdict_lines_owed`): a killed agent's lines are appended by the
        run's next agent (an agent that starts on a run another live agent still serves
        may append a line twice, never lose one).

        Raises:
            DocumentError: LOG.md or another protocol document is malformed (a LOG.md
                append fails after this step's session writes; nothing is lost).
        """
        try:
            actions = self._step()
        except BaseException:
            self.append_owed_log(quiet=True)
            raise
        if not (self.defer_task_view and self.task_view_stale):
            self.append_owed_log()
        return actions

    def append_owed_log(self, *, quiet: bool = False) -> None:
        """Append the verdicts' LOG.md lines that steps owe (see :meth:`step`), oldest
        first. Every line is tried; the first failure is raised afterwards (``quiet``:
        only logged, e.g. while another exception ends the run).

        Raises:
            DocumentError: LOG.md is malformed (LOG.md is left as it was).
            ProtocolError: LOG.md is missing.
            OSError: LOG.md or its archive cannot be written.
        """
        owed, self._owed_log = list(self._owed_log), []
        first: Exception | None = None
        for entry in owed:
            try:
                self.workspace.append_log(entry)
            except (PhyAgentOSError, OSError) as exc:
                logger.error("could not append the verdict of session %s to LOG.md: %s", entry.session_id, exc)
                first = first or exc
        if first is not None and not quiet:
            raise first

    def _verdict_lines_owed(self, sessions: list[SessionRecord]) -> list[LogEntry]:
        """The LOG.md lines of this run's verdicts that are in no log (LOG.md or its
        archive), oldest first: an agent killed between a verdict and its line (see
        :meth:`step`) owes them, and the coordinator that takes the run over appends
        them with its first step, each with its verdict's time, state and reason (from
        the session file). Lines are matched by session and event, counted."""
        verdicts: list[tuple[SessionRecord, TransitionRecord, str]] = [
            (rec, t, f"verdict_{_VERDICT_OF_EVENT[name]}") for rec in sessions for t in rec.transitions
            if t.source == "verifying" and (name := t.event.split(":", 1)[0]) in _VERDICT_OF_EVENT]
        if not verdicts:
            return []
        try:
            logged = Counter((e.session_id, e.event) for e in self.workspace.log_entries_of(
                {rec.session_id for rec, _, _ in verdicts}, since=min(t.at for _, t, _ in verdicts)))
        except (PhyAgentOSError, OSError) as exc:  # the next append reports it (and writes nothing)
            logger.warning("run %s: LOG.md not checked for owed verdict lines: %s", self.run_id, exc)
            return []
        owed: list[LogEntry] = []
        for rec, t, event in sorted(verdicts, key=lambda v: v[1].at):
            if logged[(rec.session_id, event)] > 0:
                logged[(rec.session_id, event)] -= 1
                continue
            verdict = next((a.verdict for a in reversed(rec.attempts) if a.verdict is not None), None)
            owed.append(LogEntry(at=t.at, session_id=rec.session_id, node=rec.node, event=event, state=t.dest,
                                 message=verdict.reason if verdict is not None else ""))
        if owed:
            logger.warning("run %s: appending %d verdict line(s) to LOG.md that an earlier agent owed: %s",
                           self.run_id, len(owed), ", ".join(e.session_id for e in owed))
        return owed

    def _step(self) -> int:
        actions = 0
        sessions = self.sessions()
        if not self._lines_checked:
            self._owed_log[:0] = self._verdict_lines_owed(sessions)
            self._lines_checked = True
        verified: dict[str, SessionRecord] = {}
        for rec in sessions:
            # a verification whose agent died (its lease expired) is taken up again
            if rec.state == "awaiting_verification" or (rec.state == "verifying" and is_expired(rec.lease)):
                done = self._verify(rec.session_id)
                if done is not None:
                    verified[done.session_id] = done
                    actions += 1
        if verified:  # what the verdicts wrote; nothing else of this run changes state by them
            sessions = [verified.get(rec.session_id, rec) for rec in sessions]
        replanned = 0
        for rec in sessions:
            if rec.state == "awaiting_replan":
                replanned += self._replan(rec.session_id)
        if replanned:
            sessions = self.sessions()
        resumed = self._resume_after_reopen(sessions)
        if resumed:
            sessions = self.sessions()
        actions += replanned + resumed
        self.reopen_edges(sessions)
        states = self.node_states(sessions)
        submitted: list[SessionRecord] = []
        latest = self.latest_by_node(sessions)
        ready = dagmod.ready_nodes(self.dag, states)
        if self.graph.schedule == "file_order":  # one at a time, first in file order
            in_flight = any(st == dagmod.RUNNING for st in states.values())
            ready = [] if in_flight else ready[:1]
        for node_id in ready:
            node = self.graph.get_node(node_id)
            target = self.world_target(node_id, latest)
            params, context = self.context_builder.build(goal=f"{self.graph.name}/{node.id}", skill=node.skill,
                                                         target=target or node.target, parameters=node.params,
                                                         scene=declared_scene(self.graph.scene),
                                                         observed=self.observed(node.params.get("object"), sessions),
                                                         run_id=self.run_id)
            context = with_calls(context, planner_calls(self.graph.provenance))  # the plan's model calls
            submitted.append(self.compiler.compile_node(node, parameters=params, context=context, target=target))
            if self.on_submit is not None:
                self.on_submit()
        actions += len(submitted)
        if submitted and self.defer_task_view:
            # the sessions this step left: the listing it made plus what it submitted (the
            # only change this step made after that listing)
            self.last_sessions = [*sessions, *submitted]
            self.task_view_stale = True
        else:
            self._write_task(self.sessions() if submitted else sessions)
        return actions

    def write_task(self) -> None:
        """Write what the last step deferred (see :attr:`defer_task_view`): the verdicts'
        LOG.md lines, then TASK.md with the run's sessions as that step left them,
        exactly what it would have written itself (without listing them again: a change
        made since, e.g. a supervisor's rejection, changes the run's active sessions,
        and the step that follows writes its own).

        Raises:
            DocumentError, ProtocolError, OSError: as for :meth:`append_owed_log` (TASK.md
                is still written).
        """
        try:
            self.append_owed_log()
        finally:
            self._write_task(self.last_sessions)

    def _write_task(self, sessions: list[SessionRecord] | None = None) -> None:
        sessions = self.sessions() if sessions is None else sessions
        self.last_sessions = sessions
        self.task_view_stale = False
        states = self.node_states(sessions)
        by_node: dict[str, list[str]] = {}
        for s in sessions:
            by_node.setdefault(s.node, []).append(s.session_id)
        nodes = [
            TaskNode(id=n.id, skill=n.skill, target=n.target, depends_on=list(n.depends_on), state=states[n.id],
                     session_ids=by_node.get(n.id, []))
            for n in self.graph.nodes
        ]

        def apply(doc: TaskDoc) -> TaskDoc:
            return TaskDoc(version=doc.version, run_id=self.run_id, goal_graph=str(self.graph.path) if self.graph.path else None,
                           nodes=nodes)

        # TASK.md is a view derived from the session files on every step: atomic, not fsynced.
        self.workspace.update("TASK", apply, durable=False)


    # -- evidence --------------------------------------------------------

    def _evidence(self, directory, *, fresh: bool = False) -> EvidenceBundle:
        """:func:`load_evidence` of ``directory``, read again only when its ``bundle.yaml``
        is another file than last time (inode, modification time, size) or ``fresh``.

        A bundle is written once, ``bundle.yaml`` last, and replaced atomically if ever
        (a new inode); the verdict's read serves the observations that the next node's
        context is compiled from (a pick's bundle for its place: 7 ms on that hand-off).
        Keeps the latest :data:`_BUNDLES_KEPT` bundles; they are frozen and only read.

        Raises:
            VerifierError: as :func:`load_evidence`.
        """
        key = str(directory)
        try:
            stamp = file_identity(os.path.join(key, "bundle.yaml"))
        except OSError:
            stamp = None
        kept = self._bundles.get(key)
        if kept is not None and not fresh and stamp is not None and kept[0] == stamp:
            self._bundles.move_to_end(key)
            return kept[1]
        bundle = load_evidence(directory)
        if stamp is not None:
            self._bundles[key] = (stamp, bundle)
            self._bundles.move_to_end(key)
            while len(self._bundles) > _BUNDLES_KEPT:
                self._bundles.popitem(last=False)
        return bundle

