"""Hostile deploy-time files (issue 33): ``sensors.yaml``, ``perception.yaml``, ``safety.yaml``,
``llm.yaml`` and ``fleet.yaml`` are strict schemas with ranges, refused with ``file:line``
before anything starts, and never overwritten; a camera the model cannot render and a
model file that is not GGUF are clear errors, not tracebacks."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import typing
from pathlib import Path

import annotated_types as at
import pytest
import yaml
from hostile_tally import counted, tallied
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from phyagentos.deploy_check import check_deploy_files
from phyagentos.errors import DocumentError, FleetError, PhyAgentOSError, TargetError
from phyagentos.fleet.config import FleetConfig
from phyagentos.llm import LLMError, make_client
from phyagentos.llm.config import LLMConfig, LLMFile
from phyagentos.perception.config import PerceptionConfig
from phyagentos.protocol import Workspace
from phyagentos.protocol.schemas import SafetyConfig
from phyagentos.protocol.sensors import SensorsConfig, SensorSpec
from phyagentos.resources import goal_graphs_dir, templates_dir

ROOT = Path(__file__).resolve().parents[1]
HOLD = goal_graphs_dir() / "hold.yaml"

#: Values no range admits (YAML spellings): non-finite, negative, wrong type, absurdly large.
HOSTILE = [".inf", "-.inf", ".nan", "-1", "0", "1e300", "1e12", "'abc'", "[1, 2]", "{a: 1}", "true", "null"]
CAMERA_FIELDS = {"width": "320", "height": "240", "fovy_deg": "55", "rate_hz": "10"}


@pytest.fixture(scope="module")
def base_ws(tmp_path_factory) -> Path:
    return Workspace.create(tmp_path_factory.mktemp("cfg") / "ws").root


def _sensors_yaml(field: str, value: str) -> str:
    fields = {**CAMERA_FIELDS, field: value}
    lines = ["version: 1", "targets:", "  franka_tabletop:", "  - name: overview", "    kind: rgbd_camera",
             "    frame_id: overview_optical"]
    lines += [f"    {k}: {v}" for k, v in fields.items()]
    lines += ["    mount: {body: world, camera: overview}"]
    return "\n".join(lines) + "\n"


def _expect_refused(root: Path, name: str, text: str, error: type[Exception] = DocumentError) -> str:
    path = root / name
    path.write_text(text, encoding="utf-8")
    try:
        with pytest.raises(error) as info:
            check_deploy_files(root)
        message = str(info.value)
        assert re.search(rf"{re.escape(name)}:\d+", message), message  # file:line
        assert path.read_text(encoding="utf-8") == text  # reported, never overwritten
        return message
    finally:
        path.unlink()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(sorted(CAMERA_FIELDS)), value=st.sampled_from(HOSTILE))
def test_a_hostile_camera_value_in_sensors_yaml_is_refused_with_its_line(base_ws, field, value):
    if field == "fovy_deg" and value == "null":
        return  # fovy is optional: null means the model camera's own
    with tallied("sensors.yaml"):
        text = _sensors_yaml(field, value)
        message = _expect_refused(base_ws, "sensors.yaml", text)
        # a camera without a size fails the sensor's own check: the sensor's line
        key = "- name:" if value == "null" and field in ("width", "height") else f"{field}:"
        line = next(i for i, row in enumerate(text.splitlines(), 1) if row.strip().startswith(key))
        assert f"sensors.yaml:{line}" in message, (field, value, message)


@pytest.mark.parametrize("snippet", [
    "    noise: {depth_sigma_per_m2: .nan, rgb_sigma: 1, lighting_jitter: 0}",
    "    noise: {depth_sigma_per_m2: 0, rgb_sigma: .inf, lighting_jitter: 0}",
])
@counted("sensors.yaml")
def test_nan_or_inf_noise_in_sensors_yaml_is_refused(base_ws, snippet):
    _expect_refused(base_ws, "sensors.yaml", _sensors_yaml("rate_hz", "10") + snippet + "\n")


@counted("sensors.yaml")
def test_a_sensor_name_with_a_path_is_refused(base_ws):
    _expect_refused(base_ws, "sensors.yaml", _sensors_yaml("rate_hz", "10").replace("name: overview",
                                                                                   "name: ../../etc/x"))


PERCEPTION = [("cloud:\n  max_depth_m: .inf\n", 2), ("table:\n  ransac_iterations: 1000000000000\n", 2),
              ("fusion:\n  min_confidence: .nan\n", 2), ("clustering:\n  min_points: -3\n", 2),
              ("workspace:\n  x_m: [.nan, 1.0]\n", 2), ("cloud:\n  sample_width_px: 'wide'\n", 2),
              ("nonsense: 1\n", 1)]


@pytest.mark.parametrize("body,line", PERCEPTION)
@counted("perception.yaml")
def test_a_hostile_perception_yaml_is_refused_with_its_line(base_ws, body, line):
    message = _expect_refused(base_ws, "perception.yaml", "version: 1\n" + body)
    assert f"perception.yaml:{line + 1}" in message, message


SAFETY = ["max_command_rate_hz: .inf", "max_command_duration_s: .nan", "max_joint_acceleration_rad_s2: 1e300",
          "joint_position_margin_rad: -1", "workspace_box: {min: [.nan, 0, 0], max: [1, 1, 1]}"]


@pytest.mark.parametrize("override", SAFETY)
@counted("safety.yaml")
def test_a_hostile_safety_yaml_is_refused_with_its_line(base_ws, override):
    original = (base_ws / "safety.yaml").read_text(encoding="utf-8")
    key = override.split(":")[0]
    lines = [override if row.startswith(f"{key}:") else row for row in original.splitlines()]
    if key == "workspace_box":
        start = next(i for i, row in enumerate(lines) if row.startswith("workspace_box:"))
        end = start + 1
        while end < len(lines) and lines[end].startswith(" "):
            end += 1
        lines[start:end] = [override]
    try:
        text = "\n".join(lines) + "\n"
        (base_ws / "safety.yaml").write_text(text, encoding="utf-8")
        with pytest.raises(DocumentError, match=r"safety\.yaml:\d+"):
            check_deploy_files(base_ws)
        assert (base_ws / "safety.yaml").read_text(encoding="utf-8") == text
    finally:
        (base_ws / "safety.yaml").write_text(original, encoding="utf-8")


LLM = ["seed: -1", "seed: 1e9", "threads: 100000", "threads: .inf", "base_url: ftp://host/v1", "provider: magic",
       "model: ''", "api_key_env: 'A B'", "api_key: sk-abcdefghijklmnopqrstuvwx", "colour: red", "seed: '7'"]


@pytest.mark.parametrize("line_text", LLM)
@counted("llm.yaml")
def test_a_hostile_llm_yaml_is_refused_with_its_line(base_ws, line_text):
    message = _expect_refused(base_ws, "llm.yaml", "# the model\n" + line_text + "\n", error=LLMError)
    assert "llm.yaml:2" in message, message
    assert "sk-abcdefghij" not in message


FLEET = ["submit_ttl_s: .inf", "link_timeout_s: .nan", "connect_timeout_s: 1e300", "name: '../x'",
         "connect: [http://x]", "link_loss: explode", "port: 1"]


@pytest.mark.parametrize("line_text", FLEET)
@counted("fleet.yaml")
def test_a_hostile_fleet_yaml_is_refused_with_its_line(base_ws, line_text):
    message = _expect_refused(base_ws, "fleet.yaml", "# the fleet\n" + line_text + "\n", error=FleetError)
    assert "fleet.yaml:2" in message, message


@counted("deploy files: special files")
def test_a_fifo_as_a_deploy_file_is_refused_not_waited_on(base_ws):
    os.mkfifo(base_ws / "sensors.yaml")
    try:
        with pytest.raises(PhyAgentOSError, match="not a regular file"):
            check_deploy_files(base_ws)
    finally:
        (base_ws / "sensors.yaml").unlink()


def _numeric_fields(model: type[BaseModel], seen: set) -> list[tuple[str, object]]:
    if model in seen:
        return []
    seen.add(model)
    out = []
    for name, f in model.model_fields.items():
        flat = [a for arg in (typing.get_args(f.annotation) or (f.annotation,))
                for a in (typing.get_args(arg) or (arg,))]
        for a in flat:
            if isinstance(a, type) and issubclass(a, BaseModel):
                out += _numeric_fields(a, seen)
        if any(a in (int, float) for a in flat) and name != "version":
            out.append((f"{model.__name__}.{name}", f))
    return out


@pytest.mark.parametrize("model", [SensorsConfig, SafetyConfig, PerceptionConfig, FleetConfig, LLMFile])
def test_every_deploy_schema_refuses_non_finite_numbers_and_bounds_every_scalar(model):
    seen: set = set()
    fields = _numeric_fields(model, seen)
    for sub in seen:
        assert sub.model_config.get("allow_inf_nan") is False, sub.__name__
    scalar = [(n, f) for n, f in fields if f.annotation in (int, float, int | None, float | None)]
    unbounded = [n for n, f in scalar
                 if not (any(isinstance(m, (at.Ge, at.Gt)) for m in f.metadata)
                         and any(isinstance(m, (at.Le, at.Lt)) for m in f.metadata))]
    assert not unbounded, unbounded


@counted("sensors.yaml")
def test_run_refuses_a_bad_sensors_yaml_before_anything_starts(tmp_path):
    ws = Workspace.create(tmp_path / "ws").root
    text = _sensors_yaml("width", ".inf")
    (ws / "sensors.yaml").write_text(text, encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "phyagentos.cli", "run", str(HOLD), "--workspace", str(ws)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert re.search(r"sensors\.yaml:\d+", proc.stderr), proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert not list((ws / "runs").glob("*/RUN.md")) and not list((ws / "sessions").glob("*.md"))
    assert (ws / "sensors.yaml").read_text(encoding="utf-8") == text


@pytest.mark.sim
@counted("sensors.yaml")
def test_a_camera_larger_than_the_framebuffer_names_sensors_yaml():
    from phyagentos.targets import MuJoCoTarget, SceneSpec  # noqa: PLC0415

    big = SensorSpec(name="overview", kind="rgbd_camera", frame_id="overview_optical", rate_hz=10, width=4096,
                     height=4096, mount={"body": "world", "camera": "overview"})
    with MuJoCoTarget("franka", SceneSpec(), seed=0) as target:
        with pytest.raises(TargetError, match=r"sensors\.yaml: camera 'overview'.*4096x4096.*framebuffer"):
            target.configure_sensors([big])


@pytest.mark.parametrize("content", [b"", b"not a model at all", b"\x00" * 64, b"GGU", b"PK\x03\x04zip"])
@counted("model file (model_path)")
def test_a_model_path_that_is_not_gguf_is_a_clear_error(tmp_path, content):
    path = tmp_path / "model.gguf"
    path.write_bytes(content)
    with pytest.raises(LLMError, match="not a GGUF model"):
        make_client(LLMConfig(model_path=str(path)))
    with pytest.raises(LLMError, match="does not exist"):
        make_client(LLMConfig(model_path=str(tmp_path / "missing.gguf")))
    os.mkfifo(tmp_path / "fifo.gguf")
    with pytest.raises(LLMError, match="not a regular file"):
        make_client(LLMConfig(model_path=str(tmp_path / "fifo.gguf")))


def test_the_shipped_templates_pass_the_deploy_check(tmp_path):
    ws = Workspace.create(tmp_path / "ws").root
    for name in ("sensors.yaml", "perception.yaml", "llm.yaml"):
        (ws / name).write_bytes((templates_dir() / name).read_bytes())
    check_deploy_files(ws)
    assert math.isfinite(PerceptionConfig.for_workspace(ws).cloud.max_depth_m)
    assert yaml.safe_load((ws / "llm.yaml").read_text())["provider"] == "offline"


@pytest.mark.sim
@counted("sensors.yaml")
def test_a_camera_larger_than_the_framebuffer_fails_the_run_naming_sensors_yaml(tmp_path):
    # Before: the warm-up's error was dropped, the target kept without its sensors and the run exited 0.
    ws = Workspace.create(tmp_path / "ws").root
    text = (ws / "sensors.yaml").read_text(encoding="utf-8").replace(
        "width: 320\n    height: 240\n    fovy_deg: 55\n    mount: {body: world, camera: overview}",
        "width: 4096\n    height: 4096\n    fovy_deg: 55\n    mount: {body: world, camera: overview}", 1)
    assert "4096" in text
    (ws / "sensors.yaml").write_text(text, encoding="utf-8")
    proc = subprocess.run([sys.executable, "-m", "phyagentos.cli", "run", str(HOLD), "--workspace", str(ws)],
                          capture_output=True, text=True, cwd=ROOT, timeout=400, env={**os.environ, "COLUMNS": "300"})
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out[-2000:]
    assert "sensors.yaml: camera 'overview'" in out and "framebuffer" in out, out[-2000:]
    assert "Traceback" not in out
    assert (ws / "sensors.yaml").read_text(encoding="utf-8") == text
