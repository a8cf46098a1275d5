"""What a simulated robot can measure: cameras (RGB-D, intrinsics, extrinsics, noise),
proprioception with a wrist force-torque sensor, and sensors.yaml."""

from __future__ import annotations

import numpy as np
import pytest

from phyagentos.errors import TargetError
from phyagentos.protocol.sensors import SensorsConfig, SensorSpec, read_sensors
from phyagentos.resources import templates_dir
from phyagentos.targets import MuJoCoTarget, ObjectSpec, SceneSpec

pytestmark = pytest.mark.sim

QUIET = {"depth_sigma_per_m2": 0.0, "rgb_sigma": 0.0, "lighting_jitter": 0.0}


def _camera(name, *, noise=None, width=320, height=240, body=None):
    return SensorSpec(name=name, kind="rgbd_camera", frame_id=f"{name}_optical", rate_hz=10, width=width,
                      height=height, mount={"body": body, "camera": name}, noise=noise or QUIET)


def _project(frame, p_world):
    T_cw = np.linalg.inv(frame.T_world_camera)
    p = T_cw[:3, :3] @ np.asarray(p_world) + T_cw[:3, 3]
    uvw = frame.intrinsics.matrix() @ p
    return uvw[:2] / uvw[2], float(p[2])


def test_a_projected_known_point_lands_on_the_object_at_its_depth():
    scene = SceneSpec(objects=(ObjectSpec(name="cube", half_extents=(0.03, 0.03, 0.03), position=(0.55, 0.1),
                                          rgba=(0.9, 0.1, 0.1, 1.0)),))
    with MuJoCoTarget("franka", scene, seed=0) as t:
        t.configure_sensors([_camera("overview", body="world")])
        f = t.capture("overview")
        assert f.rgb.shape == (240, 320, 3) and f.rgb.dtype == np.uint8
        assert f.depth_m.shape == (240, 320) and f.depth_m.dtype == np.float32
        assert f.sensor == "overview" and f.frame_id == "overview_optical" and f.stamp_s == t.sim_time
        # fovy-derived intrinsics: fy = (H / 2) / tan(fovy / 2)
        fovy = float(t.model.cam_fovy[t.model.camera("overview").id])
        assert f.intrinsics.fy == pytest.approx(120.0 / np.tan(np.radians(fovy) / 2.0))
        top = t.object_pose("cube")[:3, 3] + [0.0, 0.0, 0.03]  # centre of the top face
        (u, v), z = _project(f, top)
        ui, vi = int(round(u)), int(round(v))
        assert 0 <= ui < 320 and 0 <= vi < 240
        r, g, b = (int(c) for c in f.rgb[vi, ui])
        assert r > 2 * g and r > 2 * b, f.rgb[vi, ui]  # red cube there
        assert f.depth_m[vi, ui] == pytest.approx(z, abs=0.01)
        # a table point far from the cube: its depth too
        (u2, v2), z2 = _project(f, [0.45, -0.3, 0.0])
        assert f.depth_m[int(round(v2)), int(round(u2))] == pytest.approx(z2, abs=0.01)


def test_the_wrist_camera_rides_on_the_hand_and_looks_along_the_gripper():
    with MuJoCoTarget("franka", seed=0) as t:
        t.configure_sensors([_camera("wrist", body="panda0_link7")])
        f0 = t.capture("wrist")
        tcp = t.tcp_pose()
        # optical z within 15 deg of the tool axis (the camera is tilted towards it)
        assert float(f0.T_world_camera[:3, 2] @ tcp[:3, 2]) > np.cos(np.radians(15))
        # the tcp-axis point 0.2 m beyond the tcp projects near the image centre
        (u, v), z = _project(f0, tcp[:3, 3] + 0.2 * tcp[:3, 2])
        assert abs(u - 159.5) < 8 and abs(v - 119.5) < 8 and z > 0
        q = t.arm_qpos()
        q[0] += 0.3
        t.hold(q, duration_s=1.0)
        f1 = t.capture("wrist")
        assert not np.allclose(f0.T_world_camera, f1.T_world_camera, atol=1e-3)
        assert f1.stamp_s > f0.stamp_s


def test_camera_noise_follows_the_episode_seed():
    noisy = {"depth_sigma_per_m2": 0.002, "rgb_sigma": 3.0, "lighting_jitter": 0.1}
    frames = {}
    for seed in (1, 1, 2):
        with MuJoCoTarget("franka", seed=seed) as t:
            t.configure_sensors([_camera("overview", noise=noisy)])
            frames.setdefault(seed, []).append(t.capture("overview"))
    a, b = frames[1]
    (c,) = frames[2]
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.depth_m, b.depth_m)
    assert not np.array_equal(a.rgb, c.rgb) and not np.array_equal(a.depth_m, c.depth_m)
    # depth noise grows with z^2: residual spread against a quiet capture
    with MuJoCoTarget("franka", seed=1) as t:
        t.configure_sensors([_camera("overview")])
        quiet = t.capture("overview").depth_m
    valid = quiet > 0
    rel = (a.depth_m[valid] - quiet[valid]) / (quiet[valid] ** 2)
    assert np.std(rel) == pytest.approx(0.002, rel=0.1)


def test_a_target_opens_one_gl_context_for_every_image_size_and_renders_the_same_pixels(monkeypatch):
    # every mujoco.Renderer opens a GL context and uploads the model's textures (a LIBERO
    # world: about 0.5 GB each under OSMesa); the 256x256 cameras and the 320x240 evidence
    # images of one target share one, and draw exactly what renderers of their own draw
    import mujoco

    from phyagentos.targets.mujoco_arm import sensors as target_sensors

    opened = []
    real = target_sensors.Renderer  # the project's renderer (phyagentos.renderer), as the target opens it

    def counting(*args, **kwargs):
        opened.append(kwargs.get("width"))
        return real(*args, **kwargs)

    frames = {}
    for order in ("capture_first", "render_first"):
        with MuJoCoTarget("franka", seed=0) as t:
            t.configure_sensors([_camera("overview", width=256, height=256)])
            monkeypatch.setattr(target_sensors, "Renderer", counting)
            if order == "render_first":
                image = t.render("overview", width=320, height=240, shadows=False)
                frame = t.capture("overview")
            else:
                frame = t.capture("overview")
                image = t.render("overview", width=320, height=240, shadows=False)
            t.capture("overview")
            monkeypatch.setattr(target_sensors, "Renderer", real)
            assert len(t._renderers) == 2
            reference = real(t.model, height=240, width=320)  # a renderer of its own
            reference.update_scene(t.data, camera="overview", scene_option=t._render_scene_option())
            reference.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
            np.testing.assert_array_equal(image, reference.render())
            reference.close()
            frames[order] = (frame, image)
        assert len(opened) == 1, opened
        opened.clear()
    (a, image_a), (b, image_b) = frames["capture_first"], frames["render_first"]
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.depth_m, b.depth_m)
    np.testing.assert_array_equal(image_a, image_b)


def test_wrist_force_sensor_weighs_the_hand_and_the_gripper_reports_its_squeeze():
    with MuJoCoTarget("franka", seed=0) as t:
        p = t.proprioception()
        m = t.model
        hand_kg = float(m.body_subtreemass[m.body("panda0_link7").id])
        # at rest the wrist carries everything distal to it: |f| = m g
        assert np.linalg.norm(p.wrist_force_n) == pytest.approx(hand_kg * 9.81, rel=0.03)
        assert p.joint_positions.shape == (7,) and p.joint_efforts.shape == (7,) and p.tcp_pose.shape == (4, 4)
        assert p.gripper_opening_m == pytest.approx(0.04, abs=1e-3) and p.gripper_effort_n < 1.0
        t.set_gripper(opening_m=0.0, force_n=30.0)  # closes on nothing: fingers touch their stop
        p2 = t.proprioception()
        assert p2.gripper_opening_m < 1e-3


def test_sensors_yaml_template_declares_the_tabletop_cameras_and_a_bad_camera_is_refused(tmp_path):
    cfg = read_sensors()
    assert isinstance(cfg, SensorsConfig)
    names = {s.name: s for s in cfg.for_target("franka_tabletop")}
    assert {"overview", "wrist", "joints", "gripper", "wrist_ft"} <= set(names)
    assert names["wrist"].kind == "rgbd_camera" and names["wrist_ft"].kind == "force_torque"
    assert (templates_dir() / "sensors.yaml").is_file()
    with MuJoCoTarget("franka", seed=0) as t:
        assert set(t.camera_names()) == {"overview", "wrist"}  # installed from the template
        with pytest.raises(TargetError, match="no camera 'ceiling'"):
            t.configure_sensors([_camera("ceiling")])
        with pytest.raises(TargetError, match="mounted on body"):
            t.configure_sensors([_camera("wrist", body="world")])
        with pytest.raises(TargetError, match="no camera sensor 'joints'"):
            t.capture("joints")
    with pytest.raises(ValueError, match="width and height"):
        SensorSpec(name="c", kind="rgb_camera", frame_id="c", rate_hz=10)
