"""The 3D view's overlays of the robot's own data: the planned path, camera frustums and
the perceived point cloud (``phyagentos/view/scene3d.py``), and the evidence they come
from (the ``plan`` trace entry's ``path_rad``, ``frames/<tag>_cloud.npz``)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from phyagentos.perception.cloud import Cloud
from phyagentos.primitives.motion import MAX_TRACED_WAYPOINTS, traced_path
from phyagentos.primitives.observation import MAX_SAVED_CLOUD_POINTS, save_cloud
from phyagentos.protocol.sensors import SensorSpec
from phyagentos.targets import DEFAULT_SCENE, MuJoCoTarget
from phyagentos.view.scene3d import (
    FRUSTUM_DEPTH_M,
    MAX_CLOUD_POINTS,
    camera_frustums,
    cloud_file_at,
    cloud_markers,
    plan_segments,
    planned_paths,
)

pytestmark = pytest.mark.sim


@pytest.fixture(scope="module")
def franka():
    with MuJoCoTarget("sim", DEFAULT_SCENE, seed=0) as t:
        yield t


def test_a_planned_path_is_traced_bounded_with_its_ends_kept():
    long = np.linspace([0.0] * 7, [1.0] * 7, 500)
    kept = traced_path(long)
    assert len(kept) == MAX_TRACED_WAYPOINTS and len(kept[0]) == 7
    assert kept[0] == [0.0] * 7 and kept[-1] == [1.0] * 7
    short = np.array([[0.123456] * 7, [0.5] * 7])
    assert traced_path(short) == [[0.1235] * 7, [0.5] * 7]


def test_the_planned_path_is_drawn_through_the_tool_positions_forward_kinematics_gives(franka):
    model = franka.model
    adr = [int(model.joint(n).qposadr[0]) for n in franka.arm_joint_names]
    site = int(model.site(franka.tcp_site).id)
    q0 = franka.home_qpos
    q1 = q0 + np.array([0.6, 0.2, 0.0, -0.3, 0.0, 0.4, 0.0])
    trace = [{"kind": "plan", "waypoints": 2, "path_rad": [q0.tolist(), q1.tolist()]},
             {"kind": "plan", "waypoints": 0, "collision_at_goal": True},  # a failed plan: nothing to draw
             {"kind": "plan", "path_rad": [[0.0] * 6, [0.1] * 6]}]         # another arm's path: skipped
    paths = planned_paths(trace, len(adr))
    assert len(paths) == 1
    segs = plan_segments(model, adr, site, paths)
    assert all(s["kind"] == "planned_path" for s in segs)
    assert len(segs) == 12  # 0.6 rad at most 0.05 rad a step
    for a, b in zip(segs, segs[1:]):
        assert a["line"][1] == b["line"][0]  # one connected polyline
    # the ends are the tool centre point at the first and the last waypoint
    for q, point in ((q0, segs[0]["line"][0]), (q1, segs[-1]["line"][1])):
        franka.data.qpos[adr] = q
        mujoco.mj_kinematics(model, franka.data)
        np.testing.assert_allclose(point, franka.data.site_xpos[site], atol=1e-9)
    # the rendered state is untouched: FK ran on a scratch MjData
    before = franka.data.qpos.copy()
    plan_segments(model, adr, site, paths)
    np.testing.assert_array_equal(before, franka.data.qpos)
    # bounded: many long plans share MAX_PLAN_POINTS
    many = [np.linspace(q0, q0 + 2.0, 10) for _ in range(8)]
    assert len(plan_segments(model, adr, site, many, max_points=400)) <= 400


def test_a_camera_frustum_starts_at_the_camera_and_opens_by_the_declared_field_of_view(franka):
    mujoco.mj_forward(franka.model, franka.data)
    sensors = [SensorSpec(name="overview", kind="rgbd_camera", frame_id="overview_optical", rate_hz=10, width=320,
                          height=240, fovy_deg=55, mount={"body": "world", "camera": "overview"}),
               SensorSpec(name="joints", kind="joint_state", frame_id="panda0_link0", rate_hz=500),
               SensorSpec(name="nowhere", kind="rgb_camera", frame_id="x", rate_hz=10, width=64, height=48,
                          fovy_deg=40)]  # no model camera of that name: skipped
    segs = camera_frustums(franka.model, franka.data, sensors)
    assert len(segs) == 8 and {s["camera"] for s in segs} == {"overview"}
    cam = franka.model.camera("overview").id
    apex = franka.data.cam_xpos[cam]
    rays = [np.subtract(s["line"][1], s["line"][0]) for s in segs[:4]]
    for s in segs[:4]:
        np.testing.assert_allclose(s["line"][0], apex, atol=1e-12)
    # the optical axis is the camera's -z; every corner lies at the drawing depth along it
    axis = -franka.data.cam_xmat[cam].reshape(3, 3)[:, 2]
    assert all(abs(r @ axis - FRUSTUM_DEPTH_M) < 1e-9 for r in rays)
    # the far rectangle: height / depth = 2 tan(fovy / 2), width / height = 320 / 240
    corners = [np.asarray(s["line"][1]) for s in segs[:4]]
    width, height = np.linalg.norm(corners[1] - corners[0]), np.linalg.norm(corners[2] - corners[1])
    assert height == pytest.approx(2 * FRUSTUM_DEPTH_M * np.tan(np.radians(55) / 2))
    assert width / height == pytest.approx(320 / 240)
    # a real camera: its calibrated optical frame and intrinsics, no model camera needed
    real = SensorSpec(name="cam", kind="rgb_camera", frame_id="cam_optical", rate_hz=30, width=640, height=480,
                      real={"device": 0, "fx": 600.0, "fy": 600.0, "cx": 319.5, "cy": 239.5,
                            "position_m": (1.0, 0.0, 0.5), "quat_wxyz": (1.0, 0.0, 0.0, 0.0)})
    segs = camera_frustums(franka.model, franka.data, [real])
    assert segs[0]["line"][0] == [1.0, 0.0, 0.5]
    far = np.mean([s["line"][1] for s in segs[:4]], axis=0)
    np.testing.assert_allclose(far, [1.0, 0.0, 0.5 + FRUSTUM_DEPTH_M], atol=1e-12)  # optical z forward


def test_the_saved_cloud_is_bounded_and_the_one_in_force_follows_the_observations(tmp_path):
    rng = np.random.default_rng(1)
    n = 3 * MAX_SAVED_CLOUD_POINTS
    cloud = Cloud(points=rng.uniform(-1, 1, (n, 3)), rgb=rng.integers(0, 255, (n, 3), dtype=np.uint8),
                  range_m=np.ones(n), camera=np.arange(n) % 2)
    frames = tmp_path / "frames"
    assert save_cloud(cloud, ["overview", "wrist"], frames / "initial_cloud.npz") == MAX_SAVED_CLOUD_POINTS
    with np.load(frames / "initial_cloud.npz") as d:
        assert d["points"].shape == (MAX_SAVED_CLOUD_POINTS, 3) and d["points"].dtype == np.float32
        assert d["sensors"].tolist() == ["overview", "wrist"] and set(d["camera"].tolist()) == {0, 1}
        # a subset of the cloud's own points, not new ones
        assert np.isin(d["points"][:, 0], cloud.points[:, 0].astype(np.float32)).all()
    assert len(cloud_markers(frames / "initial_cloud.npz")) == MAX_CLOUD_POINTS
    small = cloud.select(np.arange(10))
    for tag in ("01_ObserveScene", "02_ObserveAfterPick", "terminal"):
        save_cloud(small, ["overview"], frames / f"{tag}_cloud.npz")
    trace = [{"kind": "observe", "stamp_s": 1.0}, {"kind": "proprio", "stamp_s": 2.0},
             {"kind": "observe", "stamp_s": 3.0}]
    at = {t: cloud_file_at(tmp_path, trace, t, t_last=5.0).name for t in (0.0, 0.99, 1.0, 2.5, 3.0, 4.9, 5.0)}
    assert at == {0.0: "initial_cloud.npz", 0.99: "initial_cloud.npz", 1.0: "01_ObserveScene_cloud.npz",
                  2.5: "01_ObserveScene_cloud.npz", 3.0: "02_ObserveAfterPick_cloud.npz",
                  4.9: "02_ObserveAfterPick_cloud.npz", 5.0: "terminal_cloud.npz"}
    # live (no recording): the terminal cloud only once nothing else is in force later
    assert cloud_file_at(tmp_path, trace, 4.0, t_last=None).name == "02_ObserveAfterPick_cloud.npz"
    assert cloud_file_at(tmp_path / "none", trace, 1.0, t_last=None) is None


def test_a_saved_cloud_linked_from_outside_the_workspace_or_a_fifo_draws_nothing(tmp_path):
    import os

    ws = tmp_path / "ws"
    frames = ws / "evidence" / "s1" / "frames"
    frames.mkdir(parents=True)
    outside = tmp_path / "outside_cloud.npz"
    np.savez(outside, points=np.zeros((5, 3)))
    (frames / "initial_cloud.npz").symlink_to(outside)
    os.mkfifo(frames / "terminal_cloud.npz")
    np.savez(frames / "01_observe_cloud.npz", points=np.ones((5, 3)))
    assert cloud_markers(frames / "initial_cloud.npz", root=ws) == []  # a link out of the workspace
    assert cloud_markers(frames / "terminal_cloud.npz", root=ws) == []  # a FIFO: refused, never waited on
    assert len(cloud_markers(frames / "01_observe_cloud.npz", root=ws)) == 5


def test_a_timelines_joint_layout_does_not_wait_behind_queued_scene_renders(tmp_path):
    """The compare page's two timelines ask for their sessions' joint layouts while the
    render thread may still be busy with scene images other pages (or tabs since closed)
    asked for: the layout is built on its own thread and does not wait for them."""
    import threading
    import time

    from supervisor_util import make_workspace, submit

    from phyagentos.view.scene3d import SceneRenderer

    ws = make_workspace(tmp_path / "ws")
    sid = submit(ws, "s-layout").session_id
    renderer = SceneRenderer(ws)
    busy = threading.Event()
    release = threading.Event()
    try:
        renderer._pool.submit(lambda: (busy.set(), release.wait(60)))  # a long render holds the render thread
        assert busy.wait(10)
        t0 = time.monotonic()
        layout = renderer.joint_layout(sid)
        assert time.monotonic() - t0 < 30 and not release.is_set()  # answered while the render still ran
        assert [name for name, _ in layout["arm"]] == [f"joint{i}" for i in range(1, 8)]
        assert len(layout["fingers"]) == 2
        assert renderer.joint_layout(sid) is layout  # kept: a reload asks nothing of the threads
    finally:
        release.set()
        renderer.close()
