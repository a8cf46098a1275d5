"""Goal-graph parsing, validation messages, and the DAG node-state logic."""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import networkx as nx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phyagentos.agent.dag import (
    NODE_STATES,
    blocked_nodes,
    find_dependency_cycle,
    is_complete,
    propagate_blocked,
    ready_nodes,
    to_digraph,
    topological_order,
)
from phyagentos.agent.goal_graph import (
    GoalGraph,
    GoalNode,
    load_goal_graph,
    parse_goal_graph,
)
from phyagentos.agent.render import plan_graph_of, to_mermaid
from phyagentos.errors import GoalGraphError
from phyagentos.resources import goal_graphs_dir

REPO = Path(__file__).resolve().parents[1]
SKILLS = {"pick", "place", "pick_and_place", "hold"}
TARGETS = {"franka_tabletop"}
SKILL_CHOICES = "'hold', 'pick', 'pick_and_place', 'place'"


def _load(tmp_path: Path, text: str) -> GoalGraph:
    path = tmp_path / "graph.yaml"
    path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
    return load_goal_graph(path, skills=SKILLS, targets=TARGETS)


def _error(tmp_path: Path, text: str, line: int) -> str:
    """Load ``text`` expecting a GoalGraphError at ``line``; return the message."""
    with pytest.raises(GoalGraphError) as info:
        _load(tmp_path, text)
    message = str(info.value)
    path = tmp_path / "graph.yaml"
    assert info.value.line == line, message
    assert info.value.path == path
    assert f"{path}:{line}: " in message
    assert "graph.yaml" in message
    return message


VALID = """
version: 1
name: demo
nodes:
  - id: pick_cube
    skill: pick
    target: franka_tabletop
    accept: {holding: cube}
  - id: place_cube
    skill: place
    target: franka_tabletop
    accept: {released: cube}
    depends_on: [pick_cube]
"""


# --------------------------------------------------------------------------- loading


@pytest.mark.parametrize("name", ["pick_and_place", "sort_two_cubes", "hold"])
def test_example_goal_graphs_load(name):
    graph = load_goal_graph(goal_graphs_dir() / f"{name}.yaml", skills=SKILLS, targets=TARGETS)
    assert graph.name == name
    assert graph.description
    assert all(node.target == "franka_tabletop" for node in graph.nodes)
    assert ready_nodes(to_digraph(graph), {}) == [graph.nodes[0].id]


def test_pick_and_place_example_has_wall_between_cube_and_goal():
    graph = load_goal_graph(goal_graphs_dir() / "pick_and_place.yaml", skills=SKILLS,
                            targets=TARGETS)
    assert graph.node_ids == ("pick_cube", "place_cube")
    assert graph.get_node("place_cube").depends_on == ("pick_cube",)
    assert graph.scene["objects"][0]["position"] == [0.5, -0.2]
    assert graph.scene["regions"][0]["center"] == [0.5, 0.25]
    wall = graph.scene["obstacles"][0]
    assert wall["center"] == [0.5, 0.03, 0.15] and wall["half_extents"] == [0.2, 0.01, 0.15]


def test_sort_two_cubes_blue_node_rechecks_red_cube_with_list_accept():
    graph = load_goal_graph(goal_graphs_dir() / "sort_two_cubes.yaml", skills=SKILLS,
                            targets=TARGETS)
    blue = graph.get_node("pick_and_place_blue")
    assert blue.depends_on == ("pick_and_place_red",)
    assert blue.accept == [
        {"inside": {"object": "blue_cube", "region": "blue_region"}},
        {"inside": {"object": "red_cube", "region": "red_region"}},
    ]


def test_valid_graph_keeps_values_and_node_lines(tmp_path):
    graph = _load(tmp_path, VALID)
    assert graph.path == tmp_path / "graph.yaml"
    assert graph.scene is None and graph.description == ""
    pick, place = graph.nodes
    assert pick == GoalNode(id="pick_cube", skill="pick", target="franka_tabletop", params={},
                            accept={"holding": "cube"}, depends_on=(), limits={}, line=4)
    assert place.line == 8 and place.depends_on == ("pick_cube",)


def test_defaults_fill_target_and_merge_params_and_limits(tmp_path):
    graph = _load(tmp_path, """
        version: 1
        name: demo
        defaults:
          target: franka_tabletop
          params: {speed: 0.5, object: cube}
          limits: {execution_timeout_s: 60}
        nodes:
          - id: a
            skill: pick
            params: {speed: 1.0}
            accept: {holding: cube}
          - id: b
            skill: hold
            accept: {still: {}}
            limits: {execution_timeout_s: 5}
    """)
    a, b = graph.nodes
    assert a.target == b.target == "franka_tabletop"
    assert a.params == {"speed": 1.0, "object": "cube"}
    assert b.params == {"speed": 0.5, "object": "cube"}
    assert a.limits == {"execution_timeout_s": 60} and b.limits == {"execution_timeout_s": 5}
    assert a.params is not b.params  # defaults are copied, not shared


def test_dependency_may_name_a_node_defined_later(tmp_path):
    graph = _load(tmp_path, """
        version: 1
        name: demo
        nodes:
          - id: second
            skill: place
            target: franka_tabletop
            accept: {}
            depends_on: [first]
          - id: first
            skill: pick
            target: franka_tabletop
            accept: {}
    """)
    assert topological_order(to_digraph(graph)) == ["first", "second"]


def test_parse_goal_graph_without_path_reports_bare_line():
    with pytest.raises(GoalGraphError) as info:
        parse_goal_graph("version: 1\nname: x\nnodes: []\n", skills=SKILLS, targets=TARGETS)
    assert info.value.line == 3 and info.value.path is None
    assert str(info.value).startswith("nodes is empty")  # no location prefix without a path


def test_unreadable_file_is_a_goal_graph_error(tmp_path):
    with pytest.raises(GoalGraphError, match="cannot read goal graph") as info:
        load_goal_graph(tmp_path / "missing.yaml", skills=SKILLS, targets=TARGETS)
    assert "missing.yaml" in str(info.value)


# --------------------------------------------------------------------------- validation errors


def test_yaml_syntax_error_names_line(tmp_path):
    message = _error(tmp_path, """
        version: 1
        name: demo
          nodes: []
    """, line=3)
    assert "YAML syntax error" in message


def test_top_level_that_is_not_a_mapping_lists_valid_keys(tmp_path):
    message = _error(tmp_path, """
        - id: a
        - id: b
    """, line=1)
    assert "top level must be a mapping" in message
    assert "'defaults', 'description', 'name', 'nodes', 'provenance', 'scene', 'schedule', 'version'" in message


def test_empty_file_is_rejected(tmp_path):
    assert "empty" in _error(tmp_path, "\n", line=1)


def test_unknown_top_level_key_lists_valid_keys(tmp_path):
    message = _error(tmp_path, VALID + "extra: 1\n", line=13)
    assert "unknown key 'extra' in goal graph" in message
    assert "valid keys: 'defaults', 'description', 'name', 'nodes', 'provenance', 'scene', 'schedule', 'version'" in message


def test_misspelt_top_level_key_suggests_the_right_one(tmp_path):
    message = _error(tmp_path, VALID.replace("name: demo", "nmae: demo"), line=2)
    assert "unknown key 'nmae'" in message and "did you mean 'name'?" in message


def test_unknown_node_key_lists_valid_node_keys(tmp_path):
    message = _error(tmp_path, VALID.replace("    accept: {released: cube}",
                                             "    accept: {released: cube}\n    retries: 3"),
                     line=12)
    assert "unknown key 'retries' in node" in message
    assert ("valid keys: 'accept', 'depends_on', 'id', 'limits', 'params', 'runtime', 'skill', 'target'"
            in message)


def test_missing_top_level_key_lists_required_keys(tmp_path):
    message = _error(tmp_path, """
        version: 1
        nodes:
          - id: a
            skill: hold
            target: franka_tabletop
            accept: {}
    """, line=1)
    assert "missing required key(s) 'name'" in message
    assert "required keys: 'name', 'nodes', 'version'" in message


def test_missing_node_key_is_reported_at_the_node(tmp_path):
    message = _error(tmp_path, VALID.replace("    accept: {released: cube}\n", ""), line=8)
    assert "node is missing required key(s) 'accept'" in message
    assert "required keys: 'accept', 'id', 'skill', 'target'" in message


def test_misspelt_node_key_is_reported_instead_of_missing_key(tmp_path):
    message = _error(tmp_path, VALID.replace("    skill: place", "    skil: place"), line=9)
    assert "unknown key 'skil'" in message and "did you mean 'skill'?" in message


def test_missing_target_without_defaults_is_reported(tmp_path):
    message = _error(tmp_path, VALID.replace("    target: franka_tabletop\n", "", 1), line=4)
    assert "missing required key(s) 'target'" in message


def test_bad_node_id_format_shows_pattern(tmp_path):
    message = _error(tmp_path, VALID.replace("id: place_cube", "id: Place-Cube"), line=8)
    assert "invalid node id 'Place-Cube'" in message
    assert "^[a-z][a-z0-9_]*$" in message


def test_duplicate_node_id_names_first_definition(tmp_path):
    message = _error(tmp_path, VALID.replace("id: place_cube", "id: pick_cube")
                     .replace("depends_on: [pick_cube]", "depends_on: []"), line=8)
    assert "duplicate node id 'pick_cube' (first defined at line 4)" in message


def test_unknown_skill_lists_valid_skills(tmp_path):
    message = _error(tmp_path, VALID.replace("skill: place", "skill: plcae"), line=9)
    assert "node 'place_cube': unknown skill 'plcae'" in message
    assert "did you mean 'place'?" in message
    assert f"valid skills: {SKILL_CHOICES}" in message


def test_unknown_target_lists_valid_targets(tmp_path):
    text = VALID.replace("    target: franka_tabletop\n    accept: {released",
                         "    target: ur5_tabletop\n    accept: {released")
    message = _error(tmp_path, text, line=10)
    assert "unknown target 'ur5_tabletop'" in message
    assert "valid targets: 'franka_tabletop'" in message


def test_unknown_target_in_defaults_is_reported_at_defaults(tmp_path):
    message = _error(tmp_path, """
        version: 1
        name: demo
        defaults:
          target: mars_rover
        nodes:
          - id: a
            skill: hold
            accept: {}
    """, line=4)
    assert "defaults: unknown target 'mars_rover'" in message
    assert "valid targets: 'franka_tabletop'" in message


def test_unknown_dependency_lists_node_ids(tmp_path):
    message = _error(tmp_path, VALID.replace("[pick_cube]", "[pick_cub]"), line=12)
    assert "depends on unknown node 'pick_cub'" in message
    assert "did you mean 'pick_cube'?" in message
    assert "valid node ids: 'pick_cube'" in message


def test_self_dependency_is_rejected(tmp_path):
    message = _error(tmp_path, VALID.replace("[pick_cube]", "[pick_cube, place_cube]"), line=12)
    assert "node 'place_cube': depends on itself" in message
    assert "valid node ids: 'pick_cube'" in message


def test_cycle_is_printed_as_arrow_chain(tmp_path):
    message = _error(tmp_path, """
        version: 1
        name: demo
        defaults: {target: franka_tabletop}
        nodes:
          - id: a
            skill: hold
            accept: {}
            depends_on: [c]
          - id: b
            skill: hold
            accept: {}
            depends_on: [a]
          - id: c
            skill: hold
            accept: {}
            depends_on: [b]
    """, line=8)
    assert "dependency cycle a -> b -> c -> a" in message
    assert "'b' depends_on 'a' (line 12)" in message
    assert "'a' depends_on 'c' (line 8)" in message


@pytest.mark.parametrize("key, value", [("params", "[cube]"), ("params", "cube")])
def test_params_of_wrong_type_is_rejected(tmp_path, key, value):
    text = VALID.replace("    accept: {released: cube}",
                         f"    {key}: {value}\n    accept: {{released: cube}}")
    message = _error(tmp_path, text, line=11)
    assert "params must be a mapping of parameter name -> value" in message


@pytest.mark.parametrize("value", ["cube", "[cube]", "[{a: 1, b: 2}]", "null"])
def test_accept_of_wrong_type_is_rejected(tmp_path, value):
    message = _error(tmp_path, VALID.replace("accept: {released: cube}", f"accept: {value}"),
                     line=11)
    assert "accept" in message
    assert "mapping of predicate name -> arguments" in message
    assert "list of single-key mappings" in message


def test_empty_nodes_list_is_rejected(tmp_path):
    message = _error(tmp_path, "version: 1\nname: demo\nnodes: []\n", line=3)
    assert "nodes is empty" in message and "'accept', 'depends_on', 'id'" in message


def test_unsupported_version_lists_valid_versions(tmp_path):
    message = _error(tmp_path, VALID.replace("version: 1", "version: 2"), line=1)
    assert "unsupported version 2; valid versions: 1" in message


def test_duplicate_yaml_key_is_rejected(tmp_path):
    message = _error(tmp_path, VALID.replace("    accept: {holding: cube}",
                                             "    accept: {holding: cube}\n    skill: place"),
                     line=8)
    assert "duplicate key 'skill' in node (first defined at line 5)" in message


def test_negative_limit_is_rejected(tmp_path):
    message = _error(tmp_path, VALID.replace("    depends_on: [pick_cube]",
                                             "    limits: {execution_timeout_s: -1}"), line=12)
    assert "limit 'execution_timeout_s' must be a non-negative number" in message


def test_first_error_in_file_order_is_reported(tmp_path):
    # The second node's unknown skill precedes the unknown top-level key at the end,
    # although the top-level keys are checked first.
    text = VALID.replace("skill: place", "skill: plcae") + "extra: 1\n"
    message = _error(tmp_path, text, line=9)
    assert "unknown skill 'plcae'" in message


def test_cycles_are_checked_after_per_node_errors(tmp_path):
    message = _error(tmp_path, """
        version: 1
        name: demo
        defaults: {target: franka_tabletop}
        nodes:
          - id: a
            skill: hold
            accept: {}
            depends_on: [b]
          - id: b
            skill: jump
            accept: {}
            depends_on: [a]
    """, line=10)
    assert "unknown skill 'jump'" in message


# --------------------------------------------------------------------------- DAG and node states


def _graph(edges: dict[str, list[str]]) -> GoalGraph:
    nodes = tuple(GoalNode(id=i, skill="hold", target="franka_tabletop", accept={},
                           depends_on=tuple(deps), line=k + 1)
                  for k, (i, deps) in enumerate(edges.items()))
    return GoalGraph(name="g", description="", path=None, scene=None, nodes=nodes)


# a -> b -> d, a -> c -> d ; x independent
DIAMOND = {"a": [], "b": ["a"], "c": ["a"], "d": ["b", "c"], "x": []}


def test_to_digraph_edges_run_from_dependency_to_dependent():
    graph = _graph(DIAMOND)
    dag = to_digraph(graph)
    assert list(dag.nodes) == ["a", "b", "c", "d", "x"]
    assert set(dag.edges) == {("a", "b"), ("a", "c"), ("b", "d"), ("c", "d")}
    assert dag.nodes["d"]["node"] is graph.get_node("d")


def test_to_digraph_rejects_dangling_dependency_of_code_built_graph():
    with pytest.raises(GoalGraphError, match="unknown node 'zz'"):
        to_digraph(_graph({"a": ["zz"]}))


def test_ready_nodes_are_waiting_roots_in_file_order():
    dag = to_digraph(_graph(DIAMOND))
    assert ready_nodes(dag, {}) == ["a", "x"]
    assert ready_nodes(dag, {"a": "succeeded"}) == ["b", "c", "x"]
    assert ready_nodes(dag, {"a": "succeeded", "b": "succeeded", "x": "running"}) == ["c"]
    assert ready_nodes(dag, {"a": "succeeded", "b": "succeeded", "c": "succeeded"}) == ["d", "x"]


def test_failed_node_blocks_descendants_but_not_independent_branch():
    dag = to_digraph(_graph(DIAMOND))
    states = {"a": "succeeded", "b": "failed"}
    assert blocked_nodes(dag, states) == ["d"]
    assert ready_nodes(dag, states) == ["c", "x"]
    new = propagate_blocked(dag, states)
    assert new == {"a": "succeeded", "b": "failed", "c": "waiting", "d": "blocked",
                   "x": "waiting"}
    assert states == {"a": "succeeded", "b": "failed"}  # input untouched


def test_failure_blocks_all_transitive_descendants():
    dag = to_digraph(_graph(DIAMOND))
    states = propagate_blocked(dag, {"a": "cancelled"})
    assert [n for n, s in states.items() if s == "blocked"] == ["b", "c", "d"]
    assert states["x"] == "waiting"
    assert not is_complete(dag, states)
    assert is_complete(dag, {**states, "x": "succeeded"})


def test_unknown_state_or_node_is_rejected_with_choices():
    dag = to_digraph(_graph(DIAMOND))
    with pytest.raises(GoalGraphError, match="valid states: .*'waiting'"):
        ready_nodes(dag, {"a": "done"})
    with pytest.raises(GoalGraphError, match="valid node ids: 'a', 'b'"):
        ready_nodes(dag, {"zz": "waiting"})


def test_the_plan_renders_as_mermaid_with_edges_and_state_classes_before_any_session():
    dag = to_digraph(_graph(DIAMOND))
    text = to_mermaid(plan_graph_of(dag, {"a": "succeeded", "b": "failed"}))
    assert text.startswith("flowchart LR\n")
    assert "  n_a --> n_b\n" in text
    assert 'subgraph n_d["d · hold · blocked"]' in text
    assert "  class n_b node_failed\n" in text
    assert "  class n_c,n_x node_waiting\n" in text
    for state in ("succeeded", "failed", "blocked", "waiting"):
        assert f"classDef node_{state} " in text
    assert to_mermaid(plan_graph_of(dag)).count("node_waiting fill:") == 1


# --------------------------------------------------------------------------- properties


def _graph_text(n: int, edges: set[tuple[int, int]], file_order: list[int]
                ) -> tuple[str, dict[int, int]]:
    """YAML for nodes n0..n{n-1} (edge (i, j): j depends on i); returns text and depends_on lines."""
    lines = ["version: 1", "name: random", "defaults:", "  target: franka_tabletop", "nodes:"]
    dep_line = {}
    for j in file_order:
        deps = sorted(i for i, k in edges if k == j)
        lines += [f"  - id: n{j}", "    skill: hold", "    accept: {}"]
        lines.append(f"    depends_on: [{', '.join(f'n{i}' for i in deps)}]")
        dep_line[j] = len(lines)
    return "\n".join(lines) + "\n", dep_line


@st.composite
def random_dags(draw, min_nodes=1):
    n = draw(st.integers(min_nodes, 8))
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    edges = draw(st.sets(st.sampled_from(pairs))) if pairs else set()
    file_order = draw(st.permutations(range(n)))
    return n, edges, list(file_order)


@settings(max_examples=150, deadline=None)
@given(random_dags(), st.data())
def test_random_dags_are_accepted_and_ready_nodes_respect_dependencies(dag_spec, data):
    n, edges, file_order = dag_spec
    text, _ = _graph_text(n, edges, file_order)
    graph = parse_goal_graph(text, path="random.yaml", skills=SKILLS, targets=TARGETS)
    dag = to_digraph(graph)
    assert set(dag.edges) == {(f"n{i}", f"n{j}") for i, j in edges}

    # Any state assignment: ready == waiting with every predecessor succeeded.
    states = {f"n{i}": data.draw(st.sampled_from(NODE_STATES)) for i in range(n)}
    ready = ready_nodes(dag, states)
    for node in dag.nodes:
        expect = states[node] == "waiting" and all(
            states[p] == "succeeded" for p in dag.predecessors(node))
        assert (node in ready) == expect

    # Running the first ready node to success each time executes a topological order.
    states, done = {}, []
    while not is_complete(dag, states):
        ready = ready_nodes(dag, states)
        assert ready, "an incomplete acyclic graph always has a ready node"
        node = ready[0]
        assert all(p in done for p in dag.predecessors(node))
        states[node] = "succeeded"
        done.append(node)
    assert sorted(done) == sorted(dag.nodes)


@settings(max_examples=150, deadline=None)
@given(random_dags(min_nodes=2), st.data())
def test_random_graphs_with_a_back_edge_are_rejected_as_real_cycles(dag_spec, data):
    n, edges, file_order = dag_spec
    chain = sorted(data.draw(st.sets(st.integers(0, n - 1), min_size=2)))
    edges = set(edges) | set(zip(chain, chain[1:])) | {(chain[-1], chain[0])}
    text, dep_line = _graph_text(n, edges, file_order)
    with pytest.raises(GoalGraphError) as info:
        parse_goal_graph(text, path="random.yaml", skills=SKILLS, targets=TARGETS)
    message = str(info.value)
    match = re.search(r"dependency cycle ((?:n\d+ -> )+n\d+) ", message)
    assert match, message
    cycle = [int(name[1:]) for name in match.group(1).split(" -> ")]
    assert cycle[0] == cycle[-1] and len(cycle) >= 3
    for u, v in zip(cycle, cycle[1:]):
        assert (u, v) in edges, f"{u} -> {v} is not a dependency in {message}"
    # Reported at the depends_on line of the cycle's earliest node in the file.
    first = min(cycle, key=file_order.index)
    assert cycle[0] == first
    assert info.value.line == dep_line[first]
    assert message.startswith(f"random.yaml:{dep_line[first]}: ")


def test_find_dependency_cycle_is_none_for_acyclic_graph():
    assert find_dependency_cycle(nx.DiGraph([("a", "b")])) is None
    assert find_dependency_cycle(nx.DiGraph([("b", "a"), ("a", "b")])) == ("b", "a")


def test_a_provenance_with_a_malformed_model_call_record_is_rejected_with_its_line(tmp_path):
    message = _error(tmp_path, VALID + "provenance:\n  model_calls:\n  - {role: planner}\n", line=14)
    assert "provenance.model_calls[0] is not a model call record" in message


# --------------------------------------------------------------------------- schedule


def test_schedule_defaults_to_eager_and_reads_file_order(tmp_path):
    assert _load(tmp_path, VALID).schedule == "eager"
    assert _load(tmp_path, VALID + "schedule: file_order\n").schedule == "file_order"


def test_unknown_schedule_lists_the_valid_ones(tmp_path):
    message = _error(tmp_path, VALID + "schedule: lifo\n", line=13)
    assert "unknown schedule 'lifo'" in message and "'eager', 'file_order'" in message
