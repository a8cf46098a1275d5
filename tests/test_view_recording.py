"""Session recordings: ``phyagentos run ... --record`` writes a playable MP4 and the state per frame."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest
import yaml
from PIL import Image
from test_view_browser import start_view
from test_view_security import request

from phyagentos.errors import RecordingError
from phyagentos.protocol import Workspace
from phyagentos.runtime.recording import ENV_VAR, RecordingConfig

CLI = [sys.executable, "-m", "phyagentos.cli"]
ROOT = Path(__file__).resolve().parents[1]

GRAPH = """\
version: 1
name: record_demo
description: One node that succeeds and one whose acceptance cannot hold.
defaults:
  target: franka_tabletop
scene:
  objects:
    - {name: cube, half_extents: [0.02, 0.02, 0.02], position: [0.5, -0.2], rgba: [0.8, 0.1, 0.1, 1]}
nodes:
  - id: ok
    skill: hold
    params: {duration_s: 1.0}
    accept: {still: {max_joint_motion_rad: 0.01}}
  - id: bad
    skill: hold
    params: {duration_s: 0.5}
    accept: {lifted: {object: cube, min_height: 0.05}}
"""


def _run(tmp_path: Path, *record: str) -> Workspace:
    graph = tmp_path / "record_demo.yaml"
    graph.write_text(GRAPH, encoding="utf-8")
    ws_dir = tmp_path / "ws"
    proc = subprocess.run([*CLI, "run", str(graph), "--workspace", str(ws_dir), *record], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr  # node "bad" fails by design
    return Workspace.open(ws_dir)


def _evidence(ws: Workspace, node: str) -> Path:
    rec = next(s for s in ws.list_sessions() if s.node == node)
    return ws.root / rec.attempts[-1].evidence


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A run recorded at 20 frames per simulated second."""
    return _run(tmp_path_factory.mktemp("recorded"), "--record", "--record-fps", "20")


def test_record_writes_a_playable_mp4_and_qpos_per_frame_listed_in_the_bundle(recorded):
    ws = recorded
    ok = _evidence(ws, "ok")
    bundle = yaml.safe_load((ok / "bundle.yaml").read_text())
    assert bundle["files"]["video"] == "video.mp4" and bundle["files"]["frames"] == "frames.npz"
    frames = np.load(ok / "frames.npz")
    t, qpos = frames["t"], frames["qpos"]
    assert str(frames["camera"]) == "overview" and float(frames["fps"]) == 20.0
    assert qpos.ndim == 2 and qpos.shape[0] == len(t) >= 10 and np.all(np.diff(t) > 0)
    # The hold lasts 1 s of simulated time: the recording covers it.
    assert t[-1] - t[0] >= 1.0
    # The video decodes, at 20 fps, as long as the simulated time it covers (frames repeated over long ticks).
    n_frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(ok / "video.mp4"))
    assert n_frames >= len(t) and abs(seconds - (t[-1] - t[0])) <= 0.2, (n_frames, seconds, t[-1] - t[0])
    reader = imageio_ffmpeg.read_frames(str(ok / "video.mp4"))
    meta = next(reader)
    assert meta["size"] == (320, 240)
    first = np.frombuffer(next(reader), dtype=np.uint8)
    reader.close()
    assert first.size == 320 * 240 * 3 and first.std() > 10  # a rendered scene, not a blank frame
    # The failed node is recorded too.
    assert (_evidence(ws, "bad") / "video.mp4").is_file()


def test_record_failures_keeps_only_the_recordings_of_sessions_that_did_not_succeed(tmp_path):
    ws = _run(tmp_path, "--record", "failures")
    ok, bad = _evidence(ws, "ok"), _evidence(ws, "bad")
    assert not (ok / "video.mp4").exists() and not (ok / "frames.npz").exists()
    assert "video" not in yaml.safe_load((ok / "bundle.yaml").read_text())["files"]
    assert (bad / "video.mp4").stat().st_size > 1000
    assert yaml.safe_load((bad / "bundle.yaml").read_text())["files"]["video"] == "video.mp4"


def test_without_record_nothing_is_recorded_but_the_tree_is_published(tmp_path):
    ws = _run(tmp_path)
    ok = _evidence(ws, "ok")
    assert not (ok / "video.mp4").exists()
    files = yaml.safe_load((ok / "bundle.yaml").read_text())["files"]
    assert "video" not in files and files["tree"] == "tree.json"


def test_a_recording_without_a_camera_named_takes_the_targets_own_view():
    """LIBERO's world has no ``overview`` camera: ``--record`` alone records its agentview."""
    from phyagentos.runtime.recording import default_camera
    from phyagentos.targets.libero.sensing import LiberoSensing
    from phyagentos.targets.mujoco_arm.sensors import ArmSensors

    assert RecordingConfig.parse("all").camera == "" and RecordingConfig.parse(RecordingConfig().to_env()) == RecordingConfig()
    assert default_camera(LiberoSensing) == "agentview"
    assert default_camera(ArmSensors) == "overview"
    assert default_camera(object()) == "overview"  # nothing to render by default: the tabletops' name


def test_recording_configuration_round_trips_and_rejects_bad_values():
    cfg = RecordingConfig.parse("failures,camera=top,fps=5,width=640,height=480")
    assert cfg == RecordingConfig(mode="failures", camera="top", fps=5.0, width=640, height=480)
    assert RecordingConfig.from_env({ENV_VAR: cfg.to_env()}) == cfg
    assert not RecordingConfig.from_env({}).enabled
    for bad in ("sometimes", "all,fps=0", "all,width=100", "all,colour=red", "all,fps=fast"):
        with pytest.raises(RecordingError):
            RecordingConfig.parse(bad)


def test_the_view_re_renders_any_recorded_instant_from_a_free_camera(recorded):
    ws = recorded
    sid = _evidence(ws, "bad").name
    before = _tree_state(ws.root)
    proc, url, _ = start_view(ws.root)
    try:
        run_id = next(p.name for p in (ws.root / "runs").iterdir() if not p.name.startswith("."))
        for page in ("/", f"/run/{run_id}", f"/session/{sid}", "/memory", "/fragment/overview", "/fragment/runs",
                     f"/fragment/run/{run_id}", f"/fragment/session/{sid}", f"/fragment/tree/{sid}", "/fragment/memory",
                     f"/api/tree/{sid}", f"/api/scene/{sid}.png?frame=live", f"/files/evidence/{sid}/video.mp4"):
            assert request(url, "GET", page)[0] in (200, 404), page
        frames = json.loads(request(url, "GET", f"/api/frames/{sid}")[1])
        assert frames["count"] >= 5 and frames["camera"] == "overview"
        status, first = request(url, "GET", f"/api/scene/{sid}.png?frame=0&az=140&el=-25&dist=1.9")
        assert status == 200 and first.startswith(b"\x89PNG")
        _, turned = request(url, "GET", f"/api/scene/{sid}.png?frame=0&az=40&el=-25&dist=1.9")
        _, last = request(url, "GET", f"/api/scene/{sid}.png?frame={frames['count'] - 1}&az=140&el=-25&dist=1.9")
        img = [np.asarray(Image.open(io.BytesIO(b)).convert("RGB"), dtype=float) for b in (first, turned, last)]
        assert img[0].shape == (360, 480, 3) and img[0].std() > 10
        assert np.abs(img[0] - img[1]).mean() > 5  # the camera orbits
        assert np.abs(img[0] - img[2]).mean() < 2  # a hold: the first and last instants look alike
        status, body = request(url, "GET", f"/api/scene/{sid}.png?frame={frames['count'] + 5}")
        assert status == 404 and b"out of range" in body
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    assert _tree_state(ws.root) == before  # the view wrote nothing (no hint repair, no lock file, no mkdir)


def _tree_state(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_mtime_ns, p.stat().st_size) if p.is_file() else (0, 0)
            for p in sorted(root.rglob("*"))}


def test_closing_a_recorder_keeps_the_heartbeat_fresh_while_the_video_is_encoded(tmp_path):
    from phyagentos.runtime.recording import SessionRecorder  # noqa: PLC0415
    from phyagentos.targets import MuJoCoTarget  # noqa: PLC0415

    target = MuJoCoTarget("franka_tabletop", seed=0)
    target.reset(seed=0)
    recorder = SessionRecorder(target, tmp_path, RecordingConfig(mode="all", fps=10.0), seed=0)
    for _ in range(20):
        target.step_for(0.1)
        recorder.tick()
    beats = []
    files = recorder.close(heartbeat=lambda: beats.append(1))
    target.close()
    assert files == {"frames": "frames.npz", "video": "video.mp4"}
    # Starting the render process and rendering 21 frames takes well over 0.5 s here.
    assert beats and recorder.frames == 21 and recorder.result["written"] >= 21
