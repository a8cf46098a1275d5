"""Recovery asks a target only for what it can do: a firmer grip needs a hand that takes a force."""

from __future__ import annotations

from phyagentos.agent.recovery import RecoveryPlanner, beyond_target
from phyagentos.agent.reviser import ModelReviser
from phyagentos.app.factories import make_reviser
from phyagentos.bench.libero import target_entry
from phyagentos.protocol import Diagnosis, Revision, SessionRecord, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now
from phyagentos.protocol.schemas import Attempt, TargetSpec

CAPS = {"franka_tabletop": frozenset({"arm", "parallel_gripper", "grasp", "place", "grip_force"}),
        "libero": frozenset({"arm", "parallel_gripper", "grasp", "place"})}
SLIPPED = Diagnosis(cause="object_slipped", category="execution", summary="the bowl slipped out when lifted",
                    facts={"tcp_end_z_m": 0.4, "grip_closed_on_object": True})


def _session(target: str, skill: str = "pick", **params) -> SessionRecord:
    now = utc_now()
    node = f"{skill}_bowl"
    return SessionRecord(session_id=f"r1-{node}-1", run_id="r1", node=node, skill=skill, target=target,
                         parameters={"object": "bowl", **({"region": "plate"} if skill == "place" else {}), **params},
                         accept={"holding": "bowl"}, created_at=now, updated_at=now)


def _replanned(session: SessionRecord, revision: Revision) -> SessionRecord:
    """``session`` with a last attempt whose verdict proposed ``revision``."""
    now = utc_now()
    verdict = Verdict(verdict="replan", reason=revision.rationale, diagnosis=SLIPPED, revision=revision, at=now)
    return session.model_copy(update={"attempts": [Attempt(number=1, started_at=now, verdict=verdict)]})


def test_a_slip_on_a_hand_without_force_control_gets_the_slower_lift_never_a_grip_force():
    planner = RecoveryPlanner(capabilities=CAPS.get)
    libero = planner.plan(_session("libero"), SLIPPED)
    assert libero is not None and libero.strategy == "firmest_grip_slower_transfer" and libero.step == 2
    assert libero.parameters == {"transfer_velocity_scale": 0.5, "lift_velocity_scale": 0.15}
    tabletop = planner.plan(_session("franka_tabletop"), SLIPPED)
    assert tabletop is not None and tabletop.strategy == "firmer_grip" and tabletop.parameters == {"grip_force_n": 40.0}
    # unknown target or no lookup: every declared parameter, as before
    assert RecoveryPlanner().plan(_session("libero"), SLIPPED).parameters == {"grip_force_n": 40.0}
    assert planner.plan(_session("elsewhere"), SLIPPED).parameters == {"grip_force_n": 40.0}


def test_a_second_slip_is_not_given_the_same_skipped_to_rung_again():
    planner = RecoveryPlanner(capabilities=CAPS.get)
    first = _session("libero")
    revision = planner.plan(first, SLIPPED)
    child = _session("libero", **revision.parameters)
    assert planner.plan(child, SLIPPED, history=[_replanned(first, revision)]) is None
    # a slip during the place re-opens the pick with the slower lift, once
    place = _session("libero", skill="place")
    repick = planner.plan(place, SLIPPED, upstream="pick_bowl")
    assert repick is not None and repick.reopen == "pick_bowl" and "grip_force_n" not in repick.parameters
    assert repick.parameters == {"transfer_velocity_scale": 0.5, "lift_velocity_scale": 0.15}
    assert planner.plan(place, SLIPPED, history=[_replanned(place, repick)], upstream="pick_bowl") is None


def test_the_model_reviser_is_never_offered_a_grip_force_the_target_lacks():
    reviser = ModelReviser(client=None, fallback=RecoveryPlanner(capabilities=CAPS.get), capabilities=CAPS.get)
    params = lambda target: {v["properties"]["parameter"]["enum"][0]  # noqa: E731
                             for v in reviser.menu(_session(target), SLIPPED) if v["properties"]["action"]["enum"] == ["adjust"]}
    assert "grip_force_n" not in params("libero") and "lift_velocity_scale" in params("libero")
    assert "grip_force_n" in params("franka_tabletop")


def test_the_composition_root_reads_each_targets_capabilities_from_targets_md(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    ws.update("TARGETS", lambda doc: doc.targets.append(TargetSpec.model_validate(target_entry())))
    reviser = make_reviser("rules", ws.root)
    assert "grip_force" in reviser.capabilities("franka_tabletop")  # the shipped template's tabletop Franka
    assert "grip_force" not in reviser.capabilities("libero") and reviser.capabilities("nowhere") is None
    assert beyond_target({"grip_force_n", "lift_velocity_scale"}, "libero", reviser.capabilities) == {"grip_force_n"}
    assert beyond_target({"grip_force_n"}, "franka_tabletop", reviser.capabilities) == set()


def test_a_coordinator_without_an_explicit_verifier_gets_the_ladder_that_reads_targets_md(tmp_path):
    """The AgentCoordinator's default (the bench's episodes build it so): a slip in a place on
    LIBERO re-opens the pick with the slower lift, never a grip force its hand would refuse
    with a target error; the tabletop Franka still gets the firmer grip."""
    import yaml

    from phyagentos.agent.coordinator import AgentCoordinator
    from phyagentos.agent.goal_graph import parse_goal_graph

    ws = Workspace.create(tmp_path / "ws")
    ws.update("TARGETS", lambda doc: doc.targets.append(TargetSpec.model_validate(target_entry())))
    doc = {"version": 1, "name": "g", "nodes": [{"id": "pick_bowl", "skill": "pick", "target": "libero",
                                                 "params": {"object": "bowl"}, "accept": {}}]}
    graph = parse_goal_graph(yaml.safe_dump(doc), skills=["pick"], targets=["libero"])
    recovery = AgentCoordinator(ws, graph, run_id="r1").verifier.recovery
    repick = recovery.plan(_session("libero", skill="place"), SLIPPED, upstream="pick_bowl")
    assert repick is not None and repick.reopen == "pick_bowl"
    assert repick.parameters == {"transfer_velocity_scale": 0.5, "lift_velocity_scale": 0.15}
    assert recovery.plan(_session("franka_tabletop"), SLIPPED).parameters == {"grip_force_n": 40.0}
