"""The live tree publisher (``evidence/<session>/tree.json``): throttled, complete, JSON-safe."""

from __future__ import annotations

import json
import time

import numpy as np
import py_trees
from py_trees.common import Access, Status

from phyagentos.runtime.tree_status import TreeStatusPublisher, json_safe, tree_status


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class _Writer(py_trees.behaviour.Behaviour):
    """Writes a numpy array to the blackboard, RUNNING for ``n`` ticks, then SUCCESS."""

    def __init__(self, name: str, n: int) -> None:
        super().__init__(name)
        self.n, self.count = n, 0
        self.bb = self.attach_blackboard_client(name=name)
        self.bb.register_key("goal", access=Access.WRITE)

    def update(self) -> Status:
        self.count += 1
        self.bb.goal = np.arange(3.0) * self.count
        self.feedback_message = f"step {self.count}"
        return Status.SUCCESS if self.count >= self.n else Status.RUNNING


def _wait_until(predicate, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)


def _tree():
    py_trees.blackboard.Blackboard.clear()
    root = py_trees.composites.Sequence("Root", memory=True)
    reader = py_trees.behaviours.CheckBlackboardVariableExists(name="Check", variable_name="goal")
    root.add_children([_Writer("Write", 3), reader])
    return root


def test_publishes_at_most_max_rate_and_always_the_final_state(tmp_path):
    clock = _Clock()
    root = _tree()
    pub = TreeStatusPublisher(tmp_path / "tree.json", session_id="s-1", max_rate_hz=10.0, clock=clock)
    tree = py_trees.trees.BehaviourTree(root)
    written = []
    for _ in range(3):  # three ticks within 20 ms: only the first is written
        tree.tick()
        written.append(pub(root))
        clock.t += 0.01
    assert written == [True, False, False]
    _wait_until(lambda: pub.writes == 1)  # written on the publisher's thread
    doc = json.loads((tmp_path / "tree.json").read_text())
    assert doc["tick"] == 1 and not doc["final"]
    assert [(n["name"], n["status"]) for n in doc["nodes"]] == [("Root", "running"), ("Write", "running"), ("Check", "invalid")]
    clock.t += 0.2
    tree.tick()  # the 4th tick: the finished sequence restarted, Write succeeds at once (count 4 >= 3)
    assert pub(root)
    assert pub(root, final=True)  # forced, whatever the rate
    doc = json.loads((tmp_path / "tree.json").read_text())
    assert doc["final"] and doc["tick"] == 4 and pub.published == 3 and pub.writes >= 2
    assert [(n["name"], n["status"]) for n in doc["nodes"]] == [("Root", "success"), ("Write", "success"), ("Check", "success")]
    write = doc["nodes"][1]
    assert write["writes"] == ["/goal"] and write["message"] == "step 4" and write["kind"] == "leaf"
    assert doc["nodes"][0]["kind"] == "composite" and doc["nodes"][1]["parent"] == 0
    assert doc["blackboard"] == {"/goal": [0.0, 4.0, 8.0]}
    assert not list(tmp_path.glob(".*.tmp"))  # the atomic write left no temporary file


def test_a_tree_of_thousands_of_nodes_is_published_whole(tmp_path):
    py_trees.blackboard.Blackboard.clear()
    root = py_trees.composites.Parallel("Root", policy=py_trees.common.ParallelPolicy.SuccessOnAll())
    for i in range(50):
        branch = py_trees.composites.Sequence(f"Branch{i}", memory=False)
        branch.add_children([py_trees.behaviours.Running(name=f"Leaf{i}.{j}") for j in range(40)])
        root.add_child(branch)
    # A deep chain too: no recursion limit.
    node = root
    for d in range(300):  # py_trees itself ticks recursively; 300 deep is well past real trees
        child = py_trees.composites.Sequence(f"Deep{d}", memory=False)
        node.add_child(child) if d else root.add_child(child)
        node = child
    node.add_child(py_trees.behaviours.Success(name="Bottom"))
    py_trees.trees.BehaviourTree(root).tick()
    status = tree_status(root)
    assert len(status["nodes"]) == 1 + 50 * 41 + 300 + 1
    assert {n["status"] for n in status["nodes"]} >= {"running", "invalid"}
    pub = TreeStatusPublisher(tmp_path / "tree.json", session_id="big")
    assert pub(root, final=True)
    assert len(json.loads((tmp_path / "tree.json").read_text())["nodes"]) == len(status["nodes"])


def test_json_safe_summarises_what_json_cannot_hold():
    big = np.zeros((100, 7))
    value = {"q": np.array([0.1234567, 2.0]), "big": big, "n": np.int64(3), "nan": float("nan"),
             "obj": object(), "long": list(range(100))}
    out = json_safe(value)
    json.dumps(out)
    assert out["q"] == [0.12346, 2.0] and out["big"] == {"shape": [100, 7], "dtype": "float64"}
    assert out["n"] == 3 and out["nan"] == "nan" and out["obj"].startswith("<object")
    assert len(out["long"]) == 33 and out["long"][-1] == "... 68 more"


def test_the_history_keeps_every_change_of_status_with_simulated_time_and_stays_bounded(tmp_path):
    sim = {"t": 0.0}
    root = _tree()
    pub = TreeStatusPublisher(tmp_path / "tree.json", session_id="s-h", sim_clock=lambda: sim["t"], max_history=6)
    tree = py_trees.trees.BehaviourTree(root)
    for _ in range(4):
        tree.tick()
        pub(root)
        sim["t"] += 0.1
    pub(root, final=True)
    hist = json.loads((tmp_path / "tree_history.json").read_text())
    assert [n["name"] for n in hist["nodes"]] == ["Root", "Write", "Check"]
    # ticks 1-2 identical (Write running) are one entry; tick 3 all succeed; 4 restarts and succeeds at once
    assert hist["entries"][0] == [1, 0.0, "RRI"]
    assert [e[2] for e in hist["entries"]][-1] == "SSS" and hist["entries"][-1][0] == 4
    assert all(b[0] > a[0] for a, b in zip(hist["entries"], hist["entries"][1:]))
    assert hist["decimated"] == 0 and hist["codes"]["R"] == "running"
    # bounded: a tree whose status flips every tick keeps at most max_history entries, first and last kept
    flip = py_trees.behaviours.Periodic(name="Flip", n=1)
    pub2 = TreeStatusPublisher(tmp_path / "flip" / "tree.json", session_id="s-f", max_history=6)
    (tmp_path / "flip").mkdir()
    t2 = py_trees.trees.BehaviourTree(flip)
    for _ in range(40):
        t2.tick()
        pub2(flip)
    pub2(flip, final=True)
    h2 = json.loads((tmp_path / "flip" / "tree_history.json").read_text())
    assert len(h2["entries"]) <= 6 and h2["decimated"] > 0
    assert h2["entries"][0][0] == 1 and h2["entries"][-1][0] == 40
