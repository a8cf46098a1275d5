"""Another view on a real run: a criterion the verifier cannot judge from what was perceived
makes the coordinator run an ``observe`` child and judge the acting session on that view."""

from __future__ import annotations

import pytest
import yaml

import phyagentos.app.orchestrator as orchestrator
from phyagentos.agent.coordinator import AgentCoordinator
from phyagentos.protocol import Workspace
from phyagentos.resources import goal_graphs_dir

pytestmark = pytest.mark.sim


class BlurredFirstView(AgentCoordinator):
    """Before the first verification of ``place_cube``, its terminal snapshot is degraded as
    a poor perception would leave it: the cube seen with confidence 0.2 (everything else as
    recorded). The runtime, the observe child and the verdicts are real."""

    blurred: list[str] = []

    def step(self) -> int:
        for s in self.sessions():
            if s.node == "place_cube" and s.state == "awaiting_verification" and not self.blurred:
                path = self.workspace.root / s.attempts[-1].evidence / "terminal.yaml"
                snap = yaml.safe_load(path.read_text())
                for e in snap["entities"]:
                    if e["name"] == "cube":
                        e.setdefault("attributes", {}).update(confidence=0.2, source="perceived")
                path.write_text(yaml.safe_dump(snap))
                self.blurred.append(s.session_id)
        return super().step()


def test_a_low_confidence_result_is_looked_at_again_and_judged_on_the_new_view(tmp_path, monkeypatch):
    BlurredFirstView.blurred = []
    monkeypatch.setattr(orchestrator, "AgentCoordinator", BlurredFirstView)
    report = orchestrator.run_goal_graph(goal_graphs_dir() / "pick_and_place.yaml", tmp_path / "ws")
    ws = Workspace.open(tmp_path / "ws")
    assert report.succeeded, [(s.session_id, s.skill, s.verdict, s.cause, s.reason) for s in report.sessions]
    rows = [(s.node, s.skill, s.status, s.verdict) for s in report.sessions]
    assert rows == [("pick_cube", "pick", "succeeded", "success"), ("place_cube", "place", "replanned", "replan"),
                    ("place_cube", "observe", "succeeded", "success")]
    place, view = (ws.load_session(s.session_id) for s in report.sessions[1:])
    first = place.attempts[-1].verdict
    assert first.diagnosis.cause == "perception_unknown" and first.revision.strategy == "another_view"
    assert [c.status for c in first.criteria] == ["unknown", "satisfied"]
    # the child only looked (skill observe, 4 frames) and the place was judged on that view
    assert view.parent_session_id == place.session_id and view.parameters == {"samples": 4}
    assert view.recovery.skill == "observe" and view.accept == place.accept
    judged = view.attempts[-1].verdict
    assert [c.status for c in judged.criteria] == ["satisfied", "satisfied"]
    assert any(f"evidence/{view.session_id}/" in ref for c in judged.criteria for ref in c.evidence)
