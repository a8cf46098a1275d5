"""ContextBuilder retrieval with scope, KNOWLEDGE.md counts and promotion to SKILL.md."""

from __future__ import annotations

import pytest

from phyagentos.agent.memory import ContextBuilder, KnowledgeBase, LessonBook, PromotionPolicy, promote
from phyagentos.agent.memory.conditions import scope_matches
from phyagentos.agent.memory.knowledge import knowledge_id
from phyagentos.agent.memory.observed import ObservedObject
from phyagentos.protocol import Diagnosis, Revision, SessionRecord, TargetSpec, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now

SCENE = {"objects": [{"name": "cube", "half_extents": [0.02, 0.02, 0.02], "position": [0.5, -0.2]},
                     {"name": "crate", "half_extents": [0.04, 0.04, 0.03], "position": [0.6, 0.1]}]}
#: A slip of the cube seen earlier in the run (from proprioception), the only risk factor here.
SLIPPED = ObservedObject(name="cube", slips=1)
FIRM = Revision(strategy="firmer_grip", cause="object_slipped", parameters={"grip_force_n": 40.0})


@pytest.fixture
def ws(tmp_path):
    ws = Workspace.create(tmp_path / "ws")

    def add_second_arm(doc):  # a second embodiment: another driver
        doc.targets.append(TargetSpec(name="second_arm", kind="simulation", driver="other_arm", capabilities=["grasp"],
                                      observations=["object_poses"], action={"space": "joint_position", "dof": 5}))

    ws.update("TARGETS", add_second_arm)
    return ws


def rec(sid, params, *, recovery=None, context=None) -> SessionRecord:
    now = utc_now()
    return SessionRecord(session_id=sid, run_id="r", node="pick_cube", skill="pick", target="franka_tabletop",
                         parameters=params, recovery=recovery, context=context, created_at=now, updated_at=now)


def ok():
    return Verdict(verdict="success", reason="ok", at=utc_now())


def learn_firm_grip(ws, builder) -> str:
    """One recovered slip on the Franka with the slippery cube, as the coordinator records it."""
    cond = builder.conditions(goal="g/pick_cube", skill="pick", target="franka_tabletop",
                              parameters={"object": "cube"}, scene=SCENE, observed=SLIPPED)
    book = LessonBook(ws)
    parent = rec("a-pick_cube-1", {"object": "cube"})
    child = rec("a-pick_cube-2", {"object": "cube", "grip_force_n": 40.0}, recovery=FIRM)
    diag = Diagnosis(cause="object_slipped", category="execution", summary="slipped")
    lid = book.propose(parent=parent, child=child, diagnosis=diag, revision=FIRM, conditions=cond)
    book.resolve(child, ok(), cond, history=[parent])
    return lid


def test_risk_factors_come_from_observable_properties_only(ws):
    builder = ContextBuilder(ws)

    def cond(scene, obj="cube", observed=None):
        return builder.conditions(goal="g/n", skill="pick", target="franka_tabletop", parameters={"object": obj},
                                  scene=scene, observed=observed)

    plain = cond(SCENE)
    assert plain.object_class == "box-medium" and plain.risk_factors == ()
    assert plain.object_properties == {"shape": "box", "size_m": [0.04, 0.04, 0.04], "size_source": "declared"}
    # what a robot cannot observe changes nothing: physical parameters, poses, the disturbance list
    privileged = {"objects": [{**SCENE["objects"][0], "mass": 1.5, "friction": 0.05, "position": [0.5, 0.3]},
                              SCENE["objects"][1]],
                  "perturbations": [{"kind": "low_friction", "object": "cube"}, {"kind": "perception_noise"}]}
    assert cond(privileged) == plain
    # what it can: a mass estimated from the wrist load, slips seen, perceived size and shape, clutter
    seen = ObservedObject(name="cube", size_m=(0.025, 0.04, 0.04), shape="cylinder", mass_estimate_kg=0.8, slips=2,
                          nearest_gap_m=0.005)
    c = cond(SCENE, observed=seen)
    assert c.risk_factors == ("clutter", "heavy_object", "round_object", "slipped_before", "small_object")
    assert c.object_class == "box-medium"  # keyed on the declaration: stable within a run
    assert c.object_properties["mass_estimate_kg"] == 0.8 and c.object_properties["size_source"] == "perceived"
    assert cond(SCENE, "crate").object_class == "box-large" and cond(SCENE, "crate").risk_factors == ("large_object",)
    assert cond({"objects": [{"name": "mug", "class": "mug"}]}, "mug").object_class == "mug"


def test_lessons_written_under_the_old_scope_scheme_are_still_read(ws):
    from phyagentos.agent.memory.conditions import migrate_scope

    old = {"embodiment": "mujoco_franka", "skill": "pick", "object_class": "box-4x4x4cm",
           "risk_factors": ["low_friction", "small_object"]}
    assert migrate_scope(old) == {**old, "object_class": "box-medium", "risk_factors": ["small_object"]}
    c = ContextBuilder(ws).conditions(goal="g/n", skill="pick", target="franka_tabletop",
                                      parameters={"object": "cube"}, scene=SCENE)
    assert scope_matches({**old, "risk_factors": ["low_friction"]}, c)
    assert not scope_matches(old, c)  # small_object is observable and absent here


def test_a_verified_lesson_is_applied_with_provenance_where_its_scope_matches(ws):
    builder = ContextBuilder(ws)
    lid = learn_firm_grip(ws, builder)
    params, ctx = builder.build(goal="h/pick_cube", skill="pick", target="franka_tabletop",
                                parameters={"object": "cube"}, scene=SCENE, observed=SLIPPED)
    assert params == {"object": "cube", "grip_force_n": 40.0}
    assert ctx.parameters == {"grip_force_n": 40.0} and ctx.risk_factors == ["slipped_before"]
    lesson_items = [i for i in ctx.items if i.kind == "lesson"]
    assert [(i.id, i.applied, i.provenance) for i in lesson_items] == [(lid, {"grip_force_n": 40.0}, ["a-pick_cube-2"])]
    assert ctx.conditions["embodiment"] == "mujoco_franka" and ctx.conditions["object_class"] == "box-medium"


@pytest.mark.parametrize("case", ["other embodiment", "other object class", "risk factor absent", "other skill"])
def test_a_lesson_is_not_applied_where_its_conditions_do_not_match(ws, case):
    builder = ContextBuilder(ws)
    learn_firm_grip(ws, builder)
    target, skill, obj, observed = "franka_tabletop", "pick", "cube", SLIPPED
    if case == "other embodiment":
        target = "second_arm"
    elif case == "other object class":
        obj, observed = "crate", ObservedObject(name="crate", slips=1)
    elif case == "risk factor absent":
        observed = None
    else:
        skill = "pick_and_place"
    params, ctx = builder.build(goal="h/n", skill=skill, target=target, parameters={"object": obj, "region": "goal"}
                                if skill == "pick_and_place" else {"object": obj}, scene=SCENE, observed=observed)
    if case == "other embodiment":
        assert ctx.conditions["embodiment"] == "other_arm"  # read from TARGETS.md, not guessed
    assert "grip_force_n" not in params and ctx.parameters == {}
    assert not [i for i in ctx.items if i.kind == "lesson"]


def test_the_nodes_own_parameters_win_and_empty_memory_records_conditions_only(ws):
    builder = ContextBuilder(ws)
    learn_firm_grip(ws, builder)
    params, ctx = builder.build(goal="h/pick_cube", skill="pick", target="franka_tabletop",
                                parameters={"object": "cube", "grip_force_n": 25.0}, scene=SCENE, observed=SLIPPED)
    assert params["grip_force_n"] == 25.0 and ctx.parameters == {}
    params, ctx = ContextBuilder(ws, use_memory=False).build(goal="h/pick_cube", skill="pick", target="franka_tabletop",
                                                             parameters={"object": "cube"}, scene=SCENE,
                                                             observed=SLIPPED)
    assert params == {"object": "cube"} and ctx.items == [] and ctx.risk_factors == ["slipped_before"]


def test_scope_matching_is_by_subset_of_risk_factors():
    builder_cond = {"embodiment": "e", "skill": "pick", "object_class": "box-medium"}
    from phyagentos.agent.memory.conditions import Conditions

    cond = Conditions(goal="g", skill="pick", target="t", embodiment="e", object="cube", object_class="box-medium",
                      risk_factors=("clutter", "slipped_before"))
    assert scope_matches({**builder_cond, "risk_factors": ["slipped_before"]}, cond)
    assert scope_matches({**builder_cond, "risk_factors": []}, cond)
    assert not scope_matches({**builder_cond, "risk_factors": ["heavy_object"]}, cond)


def test_knowledge_counts_verdicts_merges_duplicates_and_promotes_a_varied_procedure(ws):
    builder = ContextBuilder(ws)
    cond = builder.conditions(goal="g/pick_cube", skill="pick", target="franka_tabletop",
                              parameters={"object": "cube"}, scene=SCENE, observed=SLIPPED)
    kb = KnowledgeBase(ws)
    fail = Verdict(verdict="replan", reason="no", at=utc_now())
    assert kb.record(rec("x-1", {}), fail, cond, strategy={"grip_force_n": 40.0}, initial_state="50,-20") is None
    policy = PromotionPolicy(min_successes=5, min_success_rate=0.8, min_initial_states=3)
    for i, state in enumerate(["50,-20", "50,-20", "48,-22", "52,-24", "52,-24"]):
        kid = kb.record(rec(f"s{i}-1", {}), ok(), cond, strategy={"grip_force_n": 40.0}, initial_state=state)
        assert promote(ws, policy) == ([f"pick.{kid}"] if i == 4 else [])
    (entry,) = kb.document().entries
    assert entry.id == knowledge_id(entry.conditions, {"grip_force_n": 40.0})
    assert (entry.successes, entry.attempts) == (5, 5) and entry.initial_states == ["50,-20", "48,-22", "52,-24"]
    assert entry.provenance[-1] == "s4-1" and entry.conditions["risk_factors"] == ["slipped_before"]
    (proc,) = ws.read("SKILL").data.procedures
    assert proc.base_skill == "pick" and proc.parameters == {"grip_force_n": 40.0}
    assert proc.distinct_initial_states == 3 and proc.provenance == entry.provenance
    # a promoted procedure is the first thing the ContextBuilder applies
    params, ctx = builder.build(goal="h/pick_cube", skill="pick", target="franka_tabletop",
                                parameters={"object": "cube"}, scene=SCENE, observed=SLIPPED)
    assert params["grip_force_n"] == 40.0 and ctx.items[0].kind == "procedure" and ctx.items[0].id == proc.name
    # failures pull the rate under the threshold: the procedure is withdrawn
    for i in range(2):
        kb.record(rec(f"f{i}-1", {}), fail, cond, strategy={"grip_force_n": 40.0}, initial_state="50,-20")
    promote(ws, policy)
    assert ws.read("SKILL").data.procedures == []


def test_default_parameters_are_knowledge_but_never_a_procedure(ws):
    cond = ContextBuilder(ws).conditions(goal="g/pick_cube", skill="pick", target="franka_tabletop",
                                         parameters={"object": "cube"}, scene={"objects": SCENE["objects"]})
    kb = KnowledgeBase(ws)
    for i in range(6):
        kb.record(rec(f"s{i}-1", {}), ok(), cond, strategy={}, initial_state=f"{i},0")
    assert kb.document().entries[0].successes == 6
    assert promote(ws, PromotionPolicy()) == [] and ws.read("SKILL").data.procedures == []
