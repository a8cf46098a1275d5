"""The goal-graph schema as pydantic models: its errors map back to file:line, it exports a JSON schema."""

from __future__ import annotations

import textwrap

import pytest
from pydantic import ValidationError

from phyagentos.agent.goal_graph import parse_goal_graph
from phyagentos.agent.goal_graph_schema import (
    DEFAULTS_KEYS,
    NODE_KEYS,
    TOP_LEVEL_KEYS,
    GoalGraphSpec,
)
from phyagentos.errors import GoalGraphError

SKILLS = ["pick", "place"]
TARGETS = ["franka_tabletop"]


def _error(text: str) -> GoalGraphError:
    with pytest.raises(GoalGraphError) as info:
        parse_goal_graph(textwrap.dedent(text).lstrip("\n"), path="g.yaml", skills=SKILLS, targets=TARGETS)
    return info.value


def test_a_schema_error_in_a_nested_node_field_names_the_file_and_line_of_the_offending_value():
    error = _error("""
        version: 1
        name: demo
        nodes:
          - id: pick_cube
            skill: pick
            target: franka_tabletop
            accept: {holding: cube}
            limits:
              execution_timeout_s: 10
              settle_s: -2
    """)
    assert error.line == 10
    assert str(error) == ("g.yaml:10: node 'pick_cube': limit 'settle_s' must be a non-negative number, "
                          "got the scalar '-2'")


def test_an_unknown_key_error_points_at_the_key_and_keeps_the_did_you_mean_and_the_valid_keys():
    error = _error("""
        version: 1
        name: demo
        nodes:
          - id: pick_cube
            skill: pick
            target: franka_tabletop
            accept: {holding: cube}
            depends: [place_cube]
    """)
    assert error.line == 8
    assert "unknown key 'depends' in node (did you mean 'depends_on'?)" in str(error)
    assert "valid keys: 'accept', 'depends_on', 'id', 'limits', 'params', 'runtime', 'skill', 'target'" in str(error)


def test_the_message_describes_the_scalar_as_the_yaml_wrote_it():
    # YAML reads `yes` as a boolean: the message quotes what the file says, not Python's True
    error = _error("""
        version: 1
        name: demo
        nodes:
          - id: pick_cube
            skill: yes
            target: franka_tabletop
            accept: {holding: cube}
    """)
    assert error.line == 5 and "node 'pick_cube': skill must be a string, got the scalar 'yes'" in str(error)


def test_the_json_schema_of_a_goal_graph_can_be_exported_and_names_every_key():
    schema = GoalGraphSpec.model_json_schema()
    assert set(schema["properties"]) == set(TOP_LEVEL_KEYS)
    assert set(schema["required"]) == {"version", "name", "nodes"}
    assert schema["additionalProperties"] is False
    definitions = schema["$defs"]
    assert set(definitions["GoalNodeSpec"]["properties"]) == set(NODE_KEYS)
    assert set(definitions["GoalNodeSpec"]["required"]) == {"id", "accept"}  # skill, target may come from defaults
    assert set(definitions["DefaultsSpec"]["properties"]) == set(DEFAULTS_KEYS)


def test_the_schema_validates_plain_data_with_skills_and_targets_from_the_validation_context():
    data = {"version": 1, "name": "demo", "defaults": {"target": "franka_tabletop"},
            "nodes": [{"id": "pick_cube", "skill": "pick", "accept": {"holding": "cube"}},
                      {"id": "place_cube", "skill": "plcae", "accept": {}, "depends_on": ["pick_cube"]}]}
    with pytest.raises(ValidationError) as info:
        GoalGraphSpec.model_validate(data, context={"skills": SKILLS, "targets": TARGETS})
    (error,) = info.value.errors()
    assert error["loc"] == ("nodes", 1, "skill")
    assert error["msg"] == ("node 'place_cube': unknown skill 'plcae' (did you mean 'place'?); "
                            "valid skills: 'pick', 'place'")
    data["nodes"][1]["skill"] = "place"
    spec = GoalGraphSpec.model_validate(data, context={"skills": SKILLS, "targets": TARGETS})
    assert spec.nodes[1].depends_on == ("pick_cube",) and spec.defaults.target == "franka_tabletop"
