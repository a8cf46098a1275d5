"""The policy flow on LIBERO in the conventions of openpi's LIBERO example, checked against openpi's own code.

openpi-client 0.1.2 (installed without its dependencies by scripts/setup.sh: it pins numpy<2)
supplies the reference: its ``msgpack_numpy`` packing, its ``image_tools.resize_with_pad``
and its ``WebsocketClientPolicy``. The policy server here is built as openpi's
``src/openpi/serving/websocket_policy_server.py`` is (metadata first, ``msgpack_numpy.Packer``,
``server_timing``), around a stand-in policy that returns a fixed chunk and records what it
received. No checkpoint is loaded: this machine has no GPU.
"""

from __future__ import annotations

import asyncio
import threading
import time

import numpy as np
import pytest
import yaml

from openpi_client import image_tools, msgpack_numpy
from openpi_client.websocket_client_policy import WebsocketClientPolicy
from websockets.asyncio.server import serve
from websockets.exceptions import ConnectionClosed

from phyagentos.policy.adapter import orient, resize_with_pad
from phyagentos.policy.observation import quat_xyzw_to_axis_angle
from phyagentos.policy.server import PolicyServer
from phyagentos.policy.wire import packb, unpackb

OPENPI_LIBERO_KEYS = {"observation/image", "observation/wrist_image", "observation/state", "prompt"}


class StandInPolicy:
    """A fixed, deterministic chunk of ``horizon`` 7-D OSC actions; records every observation.
    After ``done_after`` inferences it adds ``done: True`` (None: never)."""

    def __init__(self, horizon: int = 10, done_after: int | None = None):
        k = np.arange(horizon, dtype=np.float64)
        self.chunk = np.stack([0.2 * np.cos(k), 0.2 * np.sin(k), -0.1 + 0.01 * k, 0.02 * k, -0.03 * k,
                               0.05 * np.ones(horizon), np.where(k % 2 == 0, -1.0, 1.0)], axis=1)
        self.received: list[dict] = []
        self.done_after = done_after
        self.metadata = {"policy": "stand-in"}

    def infer(self, obs: dict) -> dict:
        self.received.append(obs)
        out = {"actions": self.chunk.copy()}
        if self.done_after is not None and len(self.received) >= self.done_after:
            out["done"] = True
        return out


class OpenpiConventionServer:
    """A websocket server following openpi's ``WebsocketPolicyServer``: on connect it sends
    the metadata packed by ``msgpack_numpy.Packer``; each binary frame is unpacked with
    ``msgpack_numpy.unpackb``, answered with the policy's action map plus ``server_timing``."""

    def __init__(self, policy):
        self.policy = policy
        self.port = None
        self._ready = threading.Event()
        self._loop = None
        self._server = None

    async def _handler(self, ws):
        packer = msgpack_numpy.Packer()
        await ws.send(packer.pack(self.policy.metadata))
        while True:
            try:
                obs = msgpack_numpy.unpackb(await ws.recv())
                t0 = time.monotonic()
                action = self.policy.infer(obs)
                action["server_timing"] = {"infer_ms": (time.monotonic() - t0) * 1000}
                await ws.send(packer.pack(action))
            except ConnectionClosed:
                return

    async def _run(self):
        async with serve(self._handler, "127.0.0.1", 0, compression=None, max_size=None) as server:
            self._server, self._loop = server, asyncio.get_running_loop()
            self.port = server.sockets[0].getsockname()[1]
            self._ready.set()
            await server.serve_forever()

    def __enter__(self):
        threading.Thread(target=lambda: asyncio.run(self._run()), daemon=True).start()
        assert self._ready.wait(10)
        return self

    def __exit__(self, *exc):
        self._loop.call_soon_threadsafe(self._server.close)

    @property
    def uri(self) -> str:
        return f"ws://127.0.0.1:{self.port}"


# -- the wire, against openpi-client's own code ---------------------------------------------------
def test_our_frames_are_byte_identical_to_openpi_clients_msgpack_numpy():
    obs = {"observation/image": np.arange(224 * 224 * 3, dtype=np.uint8).reshape(224, 224, 3),
           "observation/state": np.linspace(-1, 1, 8), "prompt": "put the bowl on the plate",
           "nested": {"x": np.float32(1.5), "ints": np.arange(3, dtype=np.int64)}}
    assert packb(obs) == msgpack_numpy.packb(obs)
    back = msgpack_numpy.unpackb(packb(obs))
    mine = unpackb(msgpack_numpy.packb(obs))
    for decoded in (back, mine):
        assert decoded["prompt"] == obs["prompt"]
        np.testing.assert_array_equal(decoded["observation/image"], obs["observation/image"])
        assert decoded["observation/image"].dtype == np.uint8 and decoded["observation/state"].dtype == np.float64
        assert decoded["nested"]["x"] == np.float32(1.5) and decoded["nested"]["x"].dtype == np.float32


def test_openpis_client_policy_talks_to_our_policy_server():
    policy = StandInPolicy(horizon=10)
    server = PolicyServer(policy).start()
    try:
        client = WebsocketClientPolicy("127.0.0.1", server.port)
        assert client.get_server_metadata() == {"policy": "stand-in"}
        out = client.infer({"observation/state": np.zeros(8), "prompt": "p"})
    finally:
        server.stop()
    np.testing.assert_array_equal(out["actions"], policy.chunk)
    assert out["server_timing"]["infer_ms"] >= 0
    assert policy.received[0]["prompt"] == "p" and policy.received[0]["observation/state"].shape == (8,)


@pytest.mark.parametrize("shape", [(256, 256, 3), (200, 320, 3), (320, 200, 3), (224, 224, 3)])
def test_resize_with_pad_is_openpi_clients(shape):
    img = np.random.default_rng(sum(shape)).integers(0, 256, shape, dtype=np.uint8)
    np.testing.assert_array_equal(resize_with_pad(img, 224, 224), image_tools.resize_with_pad(img, 224, 224))


def test_the_robosuite_rot180_orientation_flips_robosuites_frame_on_both_axes():
    upright = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)
    raw = upright[::-1]  # robosuite's OpenGL frame: upside down
    np.testing.assert_array_equal(orient(upright, "robosuite"), raw)
    np.testing.assert_array_equal(orient(upright, "robosuite_rot180"), raw[::-1, ::-1])
    np.testing.assert_array_equal(orient(upright, "upright"), upright)


def test_axis_angle_is_robosuites_quat2axisangle():
    from robosuite.utils.transform_utils import quat2axisangle  # noqa: PLC0415

    rng = np.random.default_rng(3)
    quats = [np.array([0.0, 0.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0, 0.0])]
    quats += [q / np.linalg.norm(q) for q in rng.normal(size=(20, 4))]
    for q in quats:
        np.testing.assert_allclose(quat_xyzw_to_axis_angle(q), quat2axisangle(q.copy()), atol=1e-12)


# -- a real LIBERO world -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def libero_world():
    from phyagentos.targets.libero import LiberoScene, LiberoTarget  # noqa: PLC0415

    target = LiberoTarget("libero", LiberoScene(suite="libero_object", task=0, init=0))
    yield target
    target.close()


def _raw_robosuite_frame(target, camera: str) -> np.ndarray:
    """robosuite's own camera observation (``sim.render`` in OpenGL order, as LIBERO's
    OffScreenRenderEnv returns ``<camera>_image`` at 256x256), through robosuite's renderer."""
    from robosuite.utils.binding_utils import MjRenderContextOffscreen  # noqa: PLC0415

    sim = target.env.sim
    if sim._render_context_offscreen is None:
        MjRenderContextOffscreen(sim, device_id=-1)
        sim._render_context_offscreen.vopt.geomgroup[0] = 0  # robosuite: render_collision_mesh=False
        sim._render_context_offscreen.vopt.geomgroup[1] = 1  # render_visual_mesh=True
    return sim.render(camera_name=camera, width=256, height=256)


def _run_policy(target, tmp_path, endpoint, **params):
    """Preflight (the real endpoint) then the PolicySkillRuntime on ``target``."""
    from phyagentos.bench.libero import target_entry  # noqa: PLC0415
    from phyagentos.primitives import PRIMITIVES  # noqa: PLC0415
    from phyagentos.primitives.context import SkillContext, TraceRecorder  # noqa: PLC0415
    from phyagentos.protocol import SessionRecord, Workspace  # noqa: PLC0415
    from phyagentos.protocol.lifecycle import utc_now  # noqa: PLC0415
    from phyagentos.protocol.schemas import TargetSpec  # noqa: PLC0415
    from phyagentos.resources import skills_dir, trees_dir  # noqa: PLC0415
    from phyagentos.runtime.policy_runtime import PolicySkillRuntime  # noqa: PLC0415
    from phyagentos.runtime.preflight import run_preflight  # noqa: PLC0415
    from phyagentos.runtime.safety_guard import EStopLatch, SafetyGuard  # noqa: PLC0415
    from phyagentos.runtime.skills import SkillRegistry  # noqa: PLC0415
    from phyagentos.runtime.trees import TreeLibrary  # noqa: PLC0415
    from phyagentos.targets.registry import DRIVERS  # noqa: PLC0415

    ws = Workspace.create(tmp_path / "ws")
    ws.update("TARGETS", lambda doc: doc.targets.append(TargetSpec.model_validate(target_entry())))
    skills = SkillRegistry(skills_dir())
    now = utc_now()
    parameters = {"prompt": target.task.language, "policy_preset": "pi05_libero", "policy_endpoint": endpoint, **params}
    rec = SessionRecord(session_id="s1", run_id="r1", node="do_task", skill="libero_policy", skill_runtime="policy",
                        target="libero", parameters=parameters, accept={}, scene={"suite": "libero_object", "task": 0},
                        seed=0, created_at=now, updated_at=now)
    result = run_preflight(rec, targets=ws.read("TARGETS").data, runtimes=ws.read("SKILLRUNTIME").data, skills=skills,
                           trees=TreeLibrary(trees_dir(), PRIMITIVES), drivers=DRIVERS, safety=ws.read_safety())
    assert result.ok, result.rejections
    ctx = SkillContext(target=target, params=parameters, plan=result.plan.to_dict(), trace=TraceRecorder())
    ctx.guard = SafetyGuard.for_target(target, ws.read_safety(), events=ctx.events, flow="policy", estop=EStopLatch())
    outcome = PolicySkillRuntime(skills).run("libero_policy", ctx, deadline=time.monotonic() + 300)
    return outcome, ctx, result


def test_the_policy_flow_sends_openpis_libero_observation_and_steps_the_chunk_through_liberos_osc(
        libero_world, tmp_path, monkeypatch):
    target = libero_world
    target.reset(seed=0)
    # What openpi's example would send now (after the 10 wait steps of the target's reset).
    raw = {cam: _raw_robosuite_frame(target, cam) for cam in ("agentview", "robot0_eye_in_hand")}
    robo = target.env.env._get_observations(force_update=True)
    want_state = np.concatenate((robo["robot0_eef_pos"], quat_xyzw_to_axis_angle(robo["robot0_eef_quat"]),
                                 robo["robot0_gripper_qpos"]))
    stepped, arm_goals = [], []
    env_step = target.env.step
    monkeypatch.setattr(target.env, "step", lambda a: (stepped.append(np.array(a, dtype=float)), env_step(a))[1])
    controller = target.env.env.robots[0].controller
    set_goal = controller.set_goal
    monkeypatch.setattr(controller, "set_goal", lambda a, **kw: (arm_goals.append(np.array(a)), set_goal(a, **kw))[1])

    policy = StandInPolicy(horizon=10)
    with OpenpiConventionServer(policy) as server:
        outcome, ctx, result = _run_policy(target, tmp_path, server.uri, max_steps=12)

    assert outcome.status == "completed" and "step budget spent: 12 of 12" in outcome.message, outcome
    plan = result.plan.to_dict()
    assert plan["action_form"] == "osc_pose_delta_chunk" and plan["target_adapter"] == "libero"
    assert plan["policy"]["preset"] == "pi05_libero" and plan["action_bridges"] == []
    assert set(result.manifest.operations) == {"observe", "render", "stream_osc_pose_delta", "halt"}
    # exactly openpi's LIBERO observation
    first = policy.received[0]
    assert set(first) == OPENPI_LIBERO_KEYS
    for key, cam in (("observation/image", "agentview"), ("observation/wrist_image", "robot0_eye_in_hand")):
        img = first[key]
        assert img.shape == (224, 224, 3) and img.dtype == np.uint8
        expected = image_tools.convert_to_uint8(image_tools.resize_with_pad(
            np.ascontiguousarray(raw[cam][::-1, ::-1]), 224, 224))
        np.testing.assert_array_equal(img, expected)
        unrotated = image_tools.resize_with_pad(np.ascontiguousarray(raw[cam]), 224, 224)
        assert np.abs(img.astype(int) - unrotated.astype(int)).mean() > 5  # the rotation matters
    assert first["observation/state"].shape == (8,) and first["observation/state"].dtype == np.float64
    np.testing.assert_allclose(first["observation/state"], want_state, atol=1e-9)
    assert first["prompt"] == target.task.language == "pick up the alphabet soup and place it in the basket"
    # the first replan_steps = 5 actions of each chunk, in order, through env.step, within the budget
    assert len(policy.received) == 3
    expected_steps = np.concatenate([policy.chunk[:5], policy.chunk[:5], policy.chunk[:2]])
    np.testing.assert_array_equal(np.array(stepped), expected_steps)
    np.testing.assert_array_equal(np.array(arm_goals)[:, :6], expected_steps[:, :6])  # LIBERO's OSC got them
    assert target.observe()["env_steps"] == 12 * 25  # 12 control steps of 25 physics steps
    chunks = [r for r in ctx.trace.records if r["kind"] == "policy_chunk"]
    assert [c["executed"] for c in chunks] == [5, 5, 2] and all(c["horizon"] == 10 for c in chunks)
    assert ctx.events == []  # the guard admitted every chunk
    # the state the policy saw second is the state after five OSC steps (closed loop per chunk)
    assert not np.allclose(policy.received[1]["observation/state"][:3], first["observation/state"][:3])


def test_an_out_of_range_osc_chunk_is_stopped_before_liberos_controller(libero_world, tmp_path, monkeypatch):
    target = libero_world
    target.reset(seed=0)
    stepped = []
    env_step = target.env.step
    monkeypatch.setattr(target.env, "step", lambda a: (stepped.append(a), env_step(a))[1])
    policy = StandInPolicy(horizon=10)
    policy.chunk[3, 1] = 4.0  # four times the controller's input range
    with OpenpiConventionServer(policy) as server:
        outcome, ctx, _ = _run_policy(target, tmp_path, server.uri, max_steps=20)
    assert outcome.status == "failed" and outcome.error_code == "safety.velocity", outcome
    assert stepped == [] and ctx.events[0]["code"] == "safety.velocity" and ctx.events[0]["joint"] == "dy"


# -- the ordinary session path: supervisor, verifier, recovery within the budget -------------------------
def test_a_libero_policy_node_runs_through_sessions_to_the_verifiers_verdict_within_liberos_budget(tmp_path):
    from phyagentos.app.orchestrator import run_goal_graph  # noqa: PLC0415
    from phyagentos.bench.libero import target_entry  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415
    from phyagentos.protocol.schemas import TargetSpec  # noqa: PLC0415
    from phyagentos.targets.libero import resolve_task  # noqa: PLC0415

    ws = Workspace.create(tmp_path / "ws")
    ws.update("TARGETS", lambda doc: doc.targets.append(TargetSpec.model_validate(target_entry())))
    policy = StandInPolicy(horizon=10, done_after=2)  # the first session stops itself after 10 steps
    language = resolve_task("libero_object", 0).language
    with OpenpiConventionServer(policy) as server:
        graph = tmp_path / "g.yaml"
        graph.write_text(yaml.safe_dump({
            "version": 1, "name": "libero_policy_t0", "defaults": {"target": "libero"},
            "scene": {"suite": "libero_object", "task": 0, "init": 0},
            "nodes": [{"id": "do_task", "skill": "libero_policy", "runtime": "policy",
                       "params": {"prompt": language, "policy_preset": "pi05_libero", "policy_endpoint": server.uri,
                                  "max_steps": 15,
                                  # the stand-in server answers pings from this worker's threads: on a
                                  # loaded machine its pong can miss the presets' 1 s (policy.stalled
                                  # after one chunk, found beside a busy loop); the budget is the point here
                                  "heartbeat_timeout_s": 30},
                       "accept": [{"holding": "alphabet_soup_1"}],
                       # as `phyagentos bench libero_*` runs it: a LIBERO world takes seconds to build
                       "limits": {"heartbeat_timeout_s": 120, "execution_timeout_s": 600}}]}))
        report = run_goal_graph(graph, tmp_path / "ws", seed=0, use_memory=False, consolidate=False)
    assert not report.succeeded  # a fixed chunk does not pick the soup up
    sessions = report.sessions
    # the policy ladder's first rung: the same prompt again, from the current state; the retry
    # spends what is left of the budget, and its failure ends the ladder (a child would end at once)
    assert [s.verdict for s in sessions] == ["replan", "failure"], report.to_dict()
    assert sessions[1].strategy == "retry_from_current_state" and "no recovery strategy left" in sessions[1].reason
    ws = Workspace.open(tmp_path / "ws")
    steps = []
    for s in sessions:
        rec = ws.load_session(s.session_id)
        if not rec.attempts:
            continue
        assert rec.skill_runtime == "policy" and rec.adapter_plan["action_form"] == "osc_pose_delta_chunk"
        gt = yaml.safe_load((tmp_path / "ws" / rec.attempts[-1].evidence / "ground_truth.yaml").read_text())
        steps.append(gt["benchmark"]["control_steps"])
        assert gt["benchmark"]["success"] is False
    # the first session ran its two chunks; the retry continued from that state and the
    # episode never went past LIBERO's budget of 15 control steps
    assert steps == [10, 15]
    assert len(policy.received) == 3 and {p["prompt"] for p in policy.received} == {language}
