"""The policy flow's recovery variants on LIBERO (issue 29, part 2): the policy ladder.

(a) On a real libero_object world with openpi's wire and a stand-in policy, a failed policy
    session's children walk the ladder in order -- the same prompt again from the current
    state, a corrected prompt (which reaches the policy server), a builtin re-grasp (a
    ``pick`` on the ``builtin`` runtime), the policy again with the step left -- and no session
    goes past the episode's step budget.
(b) The instruction's decomposition on LIBERO's own instructions (libero_object, libero_goal,
    LIBERO-10's two-object ones, libero_spatial's twins), the remaining step chosen from
    perceived evidence, and the ladder's rules (order, configuration, budget, held object).
(c) Nothing of it reads the privileged channel: the files are never opened while it plans
    (audit hook), a planted answer key changes nothing, and the CI check covers the module.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

from phyagentos.agent.instruction_steps import (
    DONE,
    HELD,
    HOLD,
    MOVE,
    OPEN,
    TODO,
    TURN_ON,
    InstructionNotRead,
    decompose,
    remaining_prompt,
    step_status,
)
from phyagentos.agent.recovery import (
    BUILTIN_REGRASP,
    CORRECTED_PROMPT,
    REGRASP_STEPS,
    RESUME_AFTER_REGRASP,
    RETRY,
    RecoveryPlanner,
    check_recovery_variants,
)
from phyagentos.agent.verifier import load_evidence
from phyagentos.protocol import Diagnosis, Revision, SessionRecord
from phyagentos.protocol.lifecycle import utc_now
from phyagentos.targets.libero.catalog import parse_bddl, suite_tasks

OBJECT_0 = "pick up the alphabet soup and place it in the basket"
TEN_0 = "put both the alphabet soup and the tomato sauce in the basket"


def declared(suite: str, task: int) -> dict:
    """What a user declares of a LIBERO task (names and categories), as a goal graph's scene holds it."""
    return parse_bddl(suite_tasks(suite)[task].bddl_path).declared()


# -- the privileged channel: never opened while the ladder plans -----------------------------------
_OPENED: list[str] | None = None


def _audit(event: str, args: tuple) -> None:
    if _OPENED is not None and event == "open" and args and "ground_truth" in str(args[0]):
        _OPENED.append(str(args[0]))


sys.addaudithook(_audit)


@contextmanager
def privileged_opens():
    """Collects the paths naming ``ground_truth`` that this process opens inside the block."""
    global _OPENED
    _OPENED = []
    try:
        yield _OPENED
    finally:
        _OPENED = None


# -- (b) decomposition --------------------------------------------------------------------------------
@pytest.mark.parametrize("task", range(10))
def test_every_libero_object_instruction_is_one_move_worded_back_as_libero_words_it(task):
    language = suite_tasks("libero_object")[task].instruction
    (step,) = decompose(language, declared("libero_object", task))
    assert step.action == MOVE and step.destination == "basket_1" and step.acquires == step.object
    assert step.prompt(TODO) == language  # "pick up the X and place it in the basket"
    noun = language.removeprefix("pick up ").removesuffix(" and place it in the basket")
    assert step.prompt(HELD) == f"place {noun} in the basket" and step.first_part() == f"pick up {noun}"
    assert step.accept() == [{"on": {"object": step.object, "support": "basket_1"}}]


@pytest.mark.parametrize("suite,task,want", [
    ("libero_goal", 1, [(MOVE, "akita_black_bowl_1", "flat_stove_1", "pick up the bowl and place it on the stove")]),
    ("libero_goal", 2, [(MOVE, "wine_bottle_1", "wooden_cabinet_1",
                         "pick up the wine bottle and place it on top of the cabinet")]),
    ("libero_goal", 6, [(MOVE, "cream_cheese_1", "akita_black_bowl_1",
                         "pick up the cream cheese and place it in the bowl")]),
    # "rack" names wine_rack_1 better than the "wine" it shares with wine_bottle_1
    ("libero_goal", 9, [(MOVE, "wine_bottle_1", "wine_rack_1", "pick up the wine bottle and place it on the rack")]),
    ("libero_goal", 7, [(TURN_ON, "flat_stove_1", None, "turn on the stove")]),
    ("libero_goal", 0, [(OPEN, "wooden_cabinet_1", "wooden_cabinet_1_middle_drawer",
                         "open the middle drawer of the cabinet")]),
    ("libero_10", 0, [(MOVE, "alphabet_soup_1", "basket_1", "pick up the alphabet soup and place it in the basket"),
                      (MOVE, "tomato_sauce_1", "basket_1", "pick up the tomato sauce and place it in the basket")]),
    ("libero_10", 1, [(MOVE, "cream_cheese_1", "basket_1", "pick up the cream cheese box and place it in the basket"),
                      (MOVE, "butter_1", "basket_1", "pick up the butter and place it in the basket")]),
    # "on it": the stove of the clause before
    ("libero_10", 2, [(TURN_ON, "flat_stove_1", None, "turn on the stove"),
                      (MOVE, "moka_pot_1", "flat_stove_1", "pick up the moka pot and place it on the stove")]),
    # a twin keeps the words that tell it apart
    ("libero_spatial", 0, [(MOVE, "akita_black_bowl_1", "plate_1", "pick up the black bowl between the plate and "
                                                                   "the ramekin and place it on the plate")]),
])
def test_libero_instructions_decompose_into_the_goal_planners_steps(suite, task, want):
    steps = decompose(suite_tasks(suite)[task].instruction, declared(suite, task))
    assert [(s.action, s.object, s.destination, s.prompt(TODO)) for s in steps] == want


def test_a_twin_is_placed_without_its_reference_once_it_is_in_the_hand():
    (step,) = decompose(suite_tasks("libero_spatial")[1].instruction, declared("libero_spatial", 1))
    assert step.prompt(HELD) == "place the black bowl on the plate"
    assert step.first_part() == "pick up the black bowl next to the ramekin"


@pytest.mark.parametrize("suite,task,why", [
    ("libero_10", 9, "no step closes"),          # "... and close it"
    ("libero_goal", 5, "a push is not a step here yet"),  # push: read by the rules, no policy-flow step
    ("libero_10", 6, "beside a landmark is not judged here yet"),  # "to the right of the plate"
])
def test_instructions_the_rules_do_not_read_are_refused_with_the_reason(suite, task, why):
    with pytest.raises(InstructionNotRead, match=why):
        decompose(suite_tasks(suite)[task].instruction, declared(suite, task))


def test_without_declared_objects_nothing_is_decomposed():
    with pytest.raises(InstructionNotRead, match="declares no objects"):
        decompose(OBJECT_0, {"objects": []})
    with pytest.raises(InstructionNotRead, match="declares no objects"):
        decompose(OBJECT_0, None)


# -- (b) the remaining step, from perceived evidence --------------------------------------------------
def _entity(name, position, size=(0.03, 0.03, 0.05), conf=0.9):
    return {"name": name, "kind": "object", "position": list(position), "size": list(size),
            "attributes": {"source": "perceived", "confidence": conf, "position_std_m": 0.003}}


BASKET = _entity("basket_1", (0.0, 0.25, 0.04), size=(0.1, 0.08, 0.04))


def _in_basket(name):
    return [_entity(name, (0.01, 0.24, 0.06)), {"subject": name, "relation": "inside", "object": "basket_1",
                                                 "confidence": 0.9}]


def _held(name):
    return [_entity(name, (0.1, 0.0, 0.3)), {"subject": "gripper", "relation": "holding", "object": name,
                                              "confidence": 0.9}]


def _on_table(name, x):
    return [_entity(name, (x, -0.15, 0.05))]


def snapshot(*parts):
    entities = [BASKET] + [p for part in parts for p in part if "name" in p]
    relations = [p for part in parts for p in part if "relation" in p]
    return {"stamp_s": 1.0, "frame": "world", "entities": entities, "relations": relations}


def bundle(tmp_path, terminal, *, name="s", trace=(), answer_key=None):
    """An evidence bundle on disk, as a runner writes one; ``answer_key``: a planted
    ``ground_truth.yaml`` beside it (never listed in the bundle: the scorer's file)."""
    d = tmp_path / "evidence" / name
    d.mkdir(parents=True)
    (d / "initial.yaml").write_text(yaml.safe_dump(snapshot()))
    (d / "terminal.yaml").write_text(yaml.safe_dump(terminal))
    (d / "trace.jsonl").write_text("".join(json.dumps(r) + "\n" for r in trace))
    (d / "events.yaml").write_text("[]\n")
    files = {"initial": "initial.yaml", "terminal": "terminal.yaml", "trace": "trace.jsonl", "events": "events.yaml"}
    (d / "bundle.yaml").write_text(yaml.safe_dump({"session_id": name, "files": files, "outcome": {
        "status": "completed", "error_code": None, "failed_primitive": None, "message": "policy reported done"}}))
    if answer_key is not None:
        (d / "ground_truth.yaml").write_text(yaml.safe_dump(answer_key))
    return load_evidence(d)


@pytest.mark.parametrize("suite,task,terminal,tried,want", [
    # libero_object: nothing done -> the first step; the soup held -> its place
    ("libero_object", 0, snapshot(_on_table("alphabet_soup_1", -0.1)), OBJECT_0, "pick up the alphabet soup"),
    ("libero_object", 0, snapshot(_on_table("alphabet_soup_1", -0.1)), "pick up the alphabet soup", OBJECT_0),
    ("libero_object", 0, snapshot(_held("alphabet_soup_1")), OBJECT_0, "place the alphabet soup in the basket"),
    # not perceived at all: not done (doing it again is safer than skipping it)
    ("libero_object", 0, snapshot(), OBJECT_0, "pick up the alphabet soup"),
    # LIBERO-10's two objects: the one not yet placed, in libero_object's words
    ("libero_10", 0, snapshot(_on_table("alphabet_soup_1", -0.1), _on_table("tomato_sauce_1", 0.1)), TEN_0,
     "pick up the alphabet soup and place it in the basket"),
    ("libero_10", 0, snapshot(_in_basket("alphabet_soup_1"), _on_table("tomato_sauce_1", 0.1)), TEN_0,
     "pick up the tomato sauce and place it in the basket"),
    ("libero_10", 0, snapshot(_in_basket("alphabet_soup_1"), _held("tomato_sauce_1")), TEN_0,
     "place the tomato sauce in the basket"),
    # the hand holds the second object: it is placed first (the hand is not free for the first)
    ("libero_10", 0, snapshot(_on_table("alphabet_soup_1", -0.1), _held("tomato_sauce_1")), TEN_0,
     "place the tomato sauce in the basket"),
])
def test_the_step_left_is_chosen_from_the_perceived_evidence(tmp_path, suite, task, terminal, tried, want):
    steps = decompose(suite_tasks(suite)[task].instruction, declared(suite, task))
    left = remaining_prompt(steps, step_status(steps, bundle(tmp_path, terminal)), tried=tried)
    assert left is not None and left.prompt == want, left


def test_statuses_and_nothing_left_when_every_step_is_done(tmp_path):
    steps = decompose(TEN_0, declared("libero_10", 0))
    ev = bundle(tmp_path, snapshot(_in_basket("alphabet_soup_1"), _held("tomato_sauce_1")))
    assert step_status(steps, ev) == [DONE, HELD]
    done = bundle(tmp_path, snapshot(_in_basket("alphabet_soup_1"), _in_basket("tomato_sauce_1")), name="t")
    assert step_status(steps, done) == [DONE, DONE]
    assert remaining_prompt(steps, [DONE, DONE], tried=TEN_0) is None


def test_a_hold_step_is_done_when_held():
    (step,) = decompose("pick up the alphabet soup", declared("libero_object", 0))
    assert step.action == HOLD and step.prompt() == "pick up the alphabet soup" and step.accept() == [
        {"holding": "alphabet_soup_1"}]


# -- (b) the ladder's rules, without a world -----------------------------------------------------------
CRITERIA_UNMET = Diagnosis(cause="criteria_unmet", category="verifier", summary="the criteria are not met")
SCENE = {"suite": "libero_object", "task": 0, "init": 0, **declared("libero_object", 0)}


def policy_session(sid="r-do_task-1", prompt=OBJECT_0, parent=None, recovery=None, **params):
    now = utc_now()
    return SessionRecord(session_id=sid, run_id="r", node="do_task", skill="libero_policy", skill_runtime="policy",
                         target="libero", parameters={"prompt": prompt, "policy_preset": "pi05_libero", **params},
                         accept=[{"on": {"object": "alphabet_soup_1", "support": "basket_1"}}], scene=SCENE,
                         parent_session_id=parent, recovery=recovery, created_at=now, updated_at=now)


def budget_trace(used, budget=280):
    return [{"kind": "runtime_end", "status": "completed", "ticks": 2, "message": "done", "control_steps": used,
             "step_budget": budget}]


def walk(ladder, evidence_of, diagnosis=CRITERIA_UNMET, **params):
    """The strategies a lineage takes until the ladder ends: each child as the coordinator compiles it."""
    history: list[SessionRecord] = []
    session = policy_session(**params)
    taken = []
    for generation in range(2, 10):
        revision = ladder.plan(session, diagnosis, history=history, evidence=evidence_of(session))
        if revision is None:
            return taken
        taken.append(revision)
        history.append(session)
        child = f"r-do_task-{generation}"
        if revision.skill == "pick":
            now = utc_now()
            session = SessionRecord(session_id=child, run_id="r", node="do_task", skill="pick",
                                    skill_runtime=revision.runtime, target="libero", parameters=revision.parameters,
                                    accept=session.accept, scene=SCENE, parent_session_id=session.session_id,
                                    recovery=revision, created_at=now, updated_at=now)
        else:
            acting = next(h for h in reversed(history) if h.skill == "libero_policy")
            session = policy_session(child, parent=session.session_id, recovery=revision,
                                     **{**params, "prompt": revision.parameters.get("prompt", acting.parameters["prompt"])})
    raise AssertionError("the ladder did not end")


def test_the_ladder_takes_each_variant_once_in_order_and_records_why(tmp_path):
    nothing = bundle(tmp_path, snapshot(_on_table("alphabet_soup_1", -0.1)), trace=budget_trace(20))
    taken = walk(RecoveryPlanner(), lambda s: nothing)
    assert [r.strategy for r in taken] == [RETRY, CORRECTED_PROMPT, BUILTIN_REGRASP, RESUME_AFTER_REGRASP]
    assert [r.step for r in taken] == [1, 2, 3, 4] and {r.cause for r in taken} == {"criteria_unmet"}
    retry, corrected, regrasp, resume = taken
    assert retry.parameters == {} and retry.skill is None and OBJECT_0 in retry.rationale
    assert corrected.parameters == {"prompt": "pick up the alphabet soup"}
    assert "alphabet_soup_1 on basket_1: todo" in corrected.rationale and "260 control steps left" in corrected.rationale
    assert (regrasp.skill, regrasp.runtime, regrasp.parameters) == ("pick", "builtin", {"object": "alphabet_soup_1"})
    # the pick's evidence: the soup still on the table -> the policy again, the whole step (not the pick just tried)
    assert (resume.skill, resume.runtime) == ("libero_policy", "policy") and resume.parameters == {"prompt": OBJECT_0}
    assert all(r.rationale.startswith("addresses criteria_unmet: ") for r in taken)
    assert RecoveryPlanner().replan_budget(policy_session()) == 4


def test_after_a_successful_re_grasp_the_policy_is_asked_for_the_place(tmp_path):
    before = bundle(tmp_path, snapshot(_on_table("alphabet_soup_1", -0.1)), trace=budget_trace(20))
    held = bundle(tmp_path, snapshot(_held("alphabet_soup_1")), name="picked")
    taken = walk(RecoveryPlanner(policy_variants=["builtin_regrasp"]),
                 lambda s: held if s.skill == "pick" else before)
    assert [r.strategy for r in taken] == [BUILTIN_REGRASP, RESUME_AFTER_REGRASP]
    assert taken[1].parameters == {"prompt": "place the alphabet soup in the basket"}


@pytest.mark.parametrize("variants,want", [
    (["retry"], [RETRY]),                                  # the paper's retry-only baseline
    ([], []),                                              # no recovery
    (["corrected_prompt", "retry"], [CORRECTED_PROMPT, RETRY]),
])
def test_the_node_chooses_its_variants(tmp_path, variants, want):
    nothing = bundle(tmp_path, snapshot(_on_table("alphabet_soup_1", -0.1)), trace=budget_trace(20))
    taken = walk(RecoveryPlanner(), lambda s: nothing, recovery_variants=variants)
    assert [r.strategy for r in taken] == want
    assert RecoveryPlanner().replan_budget(policy_session(recovery_variants=variants)) == len(want)


def test_unknown_variants_are_refused():
    with pytest.raises(ValueError, match="unknown policy recovery variant"):
        check_recovery_variants(["retry", "reset"])
    with pytest.raises(ValueError, match="named twice"):
        RecoveryPlanner(policy_variants=["retry", "retry"])
    assert check_recovery_variants("retry") == ("retry",)


def test_a_spent_budget_ends_the_ladder_and_a_short_one_skips_the_re_grasp(tmp_path):
    spent = bundle(tmp_path, snapshot(_on_table("alphabet_soup_1", -0.1)), trace=budget_trace(280))
    assert walk(RecoveryPlanner(), lambda s: spent) == []
    short = bundle(tmp_path, snapshot(_on_table("alphabet_soup_1", -0.1)), name="short",
                   trace=budget_trace(280 - REGRASP_STEPS + 1))
    assert [r.strategy for r in walk(RecoveryPlanner(), lambda s: short)] == [RETRY, CORRECTED_PROMPT]


def test_an_object_already_in_the_hand_is_not_grasped_again(tmp_path):
    held = bundle(tmp_path, snapshot(_held("alphabet_soup_1")), trace=budget_trace(20))
    taken = walk(RecoveryPlanner(), lambda s: held)
    assert [r.strategy for r in taken] == [RETRY, CORRECTED_PROMPT]
    assert taken[1].parameters == {"prompt": "place the alphabet soup in the basket"}


def test_without_a_readable_instruction_only_the_retry_is_left(tmp_path):
    nothing = bundle(tmp_path, snapshot(_on_table("alphabet_soup_1", -0.1)), trace=budget_trace(20))
    taken = walk(RecoveryPlanner(), lambda s: nothing, prompt="push the plate to the front of the stove")
    assert [r.strategy for r in taken] == [RETRY]


def test_a_safety_stop_or_a_software_error_gets_nothing_and_an_unjudged_one_another_view_first():
    for cause in ("safety_intervention", "runtime_error", "timeout"):
        assert RecoveryPlanner().plan(policy_session(), Diagnosis(cause=cause, category="x", summary="s")) is None
    unknown = Diagnosis(cause="perception_unknown", category="perception", summary="not seen")
    view = RecoveryPlanner().plan(policy_session(), unknown)
    # preflight refuses observe on the policy runtime: the view runs on observe's own, builtin
    assert (view.strategy, view.skill, view.runtime) == ("another_view", "observe", "builtin")


def test_an_observe_child_of_a_policy_node_runs_builtin():
    from phyagentos.agent.replanning import Replanning

    acting = policy_session()
    assert Replanning._child_runtime("observe", Revision(strategy="x", cause="y", skill="observe"), acting) == "builtin"
    assert Replanning._child_runtime(None, None, acting) is None  # the node's own
    assert Replanning._child_runtime("pick", Revision(strategy="x", cause="y", skill="pick", runtime="builtin"),
                                     acting) == "builtin"


# -- (c) no privileged channel ---------------------------------------------------------------------------
def test_planning_never_opens_the_answer_key_and_a_planted_one_changes_nothing(tmp_path):
    key = {"benchmark": {"success": True, "control_steps": 0}, "objects": {"alphabet_soup_1": {"position": [0, 0.25, 0]}},
           "held": "alphabet_soup_1"}
    nothing = snapshot(_on_table("alphabet_soup_1", -0.1))
    plain = bundle(tmp_path / "a", nothing, trace=budget_trace(20))
    keyed = bundle(tmp_path / "b", nothing, trace=budget_trace(20), answer_key=key)
    with privileged_opens() as opened:
        a = walk(RecoveryPlanner(), lambda s: plain)
        b = walk(RecoveryPlanner(), lambda s: keyed)
    assert opened == []
    assert [(r.strategy, r.parameters) for r in a] == [(r.strategy, r.parameters) for r in b]


def test_the_ci_check_covers_the_new_module(tmp_path):
    from test_ground_truth_boundary import run_check

    copy = tmp_path / "repo"
    shutil.copytree(Path(__file__).resolve().parents[1] / "phyagentos", copy / "phyagentos",
                    ignore=shutil.ignore_patterns("__pycache__"))
    module = copy / "phyagentos" / "agent" / "instruction_steps.py"
    module.write_text(module.read_text() + "\n\ndef _peek(ev):\n    return ev.directory / 'ground_truth.yaml'\n")
    result = run_check(copy)
    assert result.returncode == 1 and "phyagentos/agent/instruction_steps.py:" in result.stdout


# -- (a) the ladder on a real LIBERO world, through sessions ----------------------------------------------
def test_a_failed_policy_session_walks_the_ladder_within_liberos_budget(tmp_path):
    from test_policy_openpi_libero import OpenpiConventionServer, StandInPolicy

    from phyagentos.app.orchestrator import run_goal_graph
    from phyagentos.bench.libero import target_entry
    from phyagentos.protocol import Workspace
    from phyagentos.protocol.schemas import TargetSpec

    ws = Workspace.create(tmp_path / "ws")
    ws.update("TARGETS", lambda doc: doc.targets.append(TargetSpec.model_validate(target_entry())))
    policy = StandInPolicy(horizon=10, done_after=2)  # 2 chunks of 5 steps, then every inference says done
    budget = 200  # room for the re-grasp (REGRASP_STEPS) after 20 policy steps
    with OpenpiConventionServer(policy) as server:
        graph = tmp_path / "g.yaml"
        graph.write_text(yaml.safe_dump({
            "version": 1, "name": "libero_policy_ladder", "defaults": {"target": "libero"},
            # the declared objects and fixtures (names and categories), as `phyagentos bench libero_*` declares them
            "scene": SCENE,
            "nodes": [{"id": "do_task", "skill": "libero_policy", "runtime": "policy",
                       "params": {"prompt": OBJECT_0, "policy_preset": "pi05_libero", "policy_endpoint": server.uri,
                                  "max_steps": budget, "heartbeat_timeout_s": 30,
                                  "recovery_variants": ["retry", "corrected_prompt", "builtin_regrasp"]},
                       "accept": [{"holding": "alphabet_soup_1"}],
                       "limits": {"heartbeat_timeout_s": 120, "execution_timeout_s": 600}}]}))
        started = time.monotonic()
        with privileged_opens() as opened:
            report = run_goal_graph(graph, tmp_path / "ws", seed=0, use_memory=False, consolidate=False)
    assert opened == [], opened  # the Agent plane (this process) never opened an answer key
    assert time.monotonic() - started < 240
    assert not report.succeeded  # a fixed chunk picks nothing; the soup is not perceived, so not re-grasped
    sessions = report.sessions
    assert [s.strategy for s in sessions] == [None, RETRY, CORRECTED_PROMPT, BUILTIN_REGRASP, RESUME_AFTER_REGRASP]
    assert [s.verdict for s in sessions] == ["replan"] * 4 + ["failure"], report.to_dict()
    assert "unsatisfied after 4 replans" in sessions[-1].reason
    ws = Workspace.open(tmp_path / "ws")
    records = [ws.load_session(s.session_id) for s in sessions]
    assert [(r.skill, r.skill_runtime) for r in records] == [("libero_policy", "policy")] * 3 + [
        ("pick", "builtin"), ("libero_policy", "policy")]
    assert records[3].parameters == {"object": "alphabet_soup_1"}
    assert records[4].parameters["policy_endpoint"] == server.uri  # the policy's own parameters, continued
    assert records[3].attempts[-1].verdict.diagnosis.cause == "object_not_seen"  # no look measured here
    # what reached the policy server: the instruction (2 inferences, then the retry's), the corrected
    # prompt (nothing done: the first step), and after the failed re-grasp the whole step again
    assert [p["prompt"] for p in policy.received] == [OBJECT_0] * 3 + ["pick up the alphabet soup", OBJECT_0]
    # every session drew on the episode's budget, from the state the one before left
    steps = []
    for rec in records:
        gt = yaml.safe_load((tmp_path / "ws" / rec.attempts[-1].evidence / "ground_truth.yaml").read_text())
        steps.append(gt["benchmark"]["control_steps"])
    assert steps[:3] == [10, 15, 20] and steps == sorted(steps) and steps[-1] <= budget, steps
    ends = [r for r in load_evidence(tmp_path / "ws" / records[2].attempts[-1].evidence).trace
            if r["kind"] == "runtime_end"]
    assert ends[-1]["control_steps"] == 20 and ends[-1]["step_budget"] == budget
