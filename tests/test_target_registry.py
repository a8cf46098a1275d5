"""The target registry (entry points group ``phyagentos.targets``) and the Target contract
every registered built-in driver conforms to."""

from __future__ import annotations

import inspect
import sys
import textwrap
from pathlib import Path

import pytest
import tomllib

from phyagentos.errors import TargetError
from phyagentos.runtime.target_pool import TargetPool
from phyagentos.targets import registry
from phyagentos.targets.contract import (
    ACTION_FORMS,
    SENSOR_KINDS,
    Target,
    TargetCapabilities,
    capabilities_of,
)
from phyagentos.targets.registry import (
    DRIVERS,
    get_target_class,
    register_target,
    registered_targets,
    unregister_target,
)

#: Every built-in driver (the registry's fallback table, kept equal to pyproject.toml's entry points).
BUILTINS = tuple(sorted(registry._BUILTIN_FALLBACK))

_PLUGIN = '''
from phyagentos.targets.contract import Target, TargetCapabilities


class PluginGame(Target):
    KIND = "game"
    TOOLS = ("noop",)
    CAPABILITIES = TargetCapabilities(action_forms=("game_action",))

    def __init__(self, name, scene=None, *, seed=None):
        super().__init__(name, "game")
        self.steps = 0

    def observe(self):
        return {"steps": self.steps}

    def reset(self, *, seed=None):
        self.steps = 0
        return self.observe()

    def step(self, ctrl):
        self.steps += 1

    def execute_trajectory(self, traj, *, tracking_tol_rad):
        raise NotImplementedError

    def query_state(self):
        return self.observe()

    def tools(self):
        return self.TOOLS

    def _tool_noop(self):
        self.step(None)
        return self.observe()
'''


@pytest.fixture
def plugin_dist(tmp_path, monkeypatch):
    """An installed distribution on sys.path declaring three entry points in the group:
    a working plugin, one whose module fails to import and one naming a non-Target."""
    (tmp_path / "regplugin_ok.py").write_text(textwrap.dedent(_PLUGIN))
    (tmp_path / "regplugin_broken.py").write_text("import a_module_that_is_not_installed_anywhere\n")
    (tmp_path / "regplugin_notarget.py").write_text("class NotATarget:\n    pass\n")
    dist = tmp_path / "regplugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: regplugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent("""\
        [phyagentos.targets]
        plugin_game = regplugin_ok:PluginGame
        plugin_broken = regplugin_broken:Broken
        plugin_notarget = regplugin_notarget:NotATarget
        """))
    monkeypatch.syspath_prepend(str(tmp_path))
    registry.refresh()
    yield tmp_path
    for mod in ("regplugin_ok", "regplugin_broken", "regplugin_notarget"):
        sys.modules.pop(mod, None)
    registry._loaded.pop("plugin_game", None)
    registry.refresh()


def test_builtin_drivers_are_registered():
    assert set(BUILTINS) == {"crafter", "gymnasium_kitchen", "libero", "mujoco_franka", "mujoco_so101", "so101_real"}
    assert set(BUILTINS) <= set(registered_targets())
    assert set(BUILTINS) <= set(DRIVERS)


def test_the_builtin_fallback_table_equals_the_declared_entry_points():
    with open(Path(__file__).resolve().parent.parent / "pyproject.toml", "rb") as f:
        declared = tomllib.load(f)["project"]["entry-points"][registry.ENTRY_POINT_GROUP]
    assert declared == registry._BUILTIN_FALLBACK


def test_an_installed_entry_point_is_found_and_loaded_lazily(plugin_dist):
    assert {"plugin_game", "plugin_broken", "plugin_notarget"} <= set(registered_targets())
    assert "regplugin_ok" not in sys.modules  # listed without importing
    cls = get_target_class("plugin_game")
    assert cls.__name__ == "PluginGame" and issubclass(cls, Target)
    assert DRIVERS["plugin_game"] is cls
    with cls("g") as t:
        assert t.invoke_tool("noop") == {"steps": 1}


def test_an_unknown_driver_lists_the_registered_names():
    with pytest.raises(TargetError) as exc:
        get_target_class("no_such_robot")
    msg = str(exc.value)
    assert "unknown target driver 'no_such_robot'" in msg
    for name in BUILTINS:
        assert repr(name) in msg
    assert "no_such_robot" not in DRIVERS and DRIVERS.get("no_such_robot") is None


def test_the_target_pool_rejects_an_unknown_driver_listing_the_choices(tmp_path):
    from phyagentos.protocol import TargetSpec

    pool = TargetPool(tmp_path / "targets")
    spec = TargetSpec(name="arm", kind="simulation", driver="no_such_robot", capabilities=[], observations=[],
                      action={"space": "joint"})
    with pytest.raises(TargetError, match=r"valid drivers: .*'mujoco_franka'"):
        pool.warm(spec, None)


def test_a_plugin_that_fails_to_import_names_its_entry_point(plugin_dist):
    with pytest.raises(TargetError) as exc:
        get_target_class("plugin_broken")
    msg = str(exc.value)
    assert "'plugin_broken'" in msg and "regplugin" in msg and "'regplugin_broken:Broken'" in msg
    assert "ModuleNotFoundError" in msg and "a_module_that_is_not_installed_anywhere" in msg


def test_an_entry_point_naming_a_non_target_is_refused(plugin_dist):
    with pytest.raises(TargetError, match=r"'plugin_notarget'.*not a subclass of phyagentos.targets.contract.Target"):
        get_target_class("plugin_notarget")


def test_register_target_adds_and_removes_an_in_process_driver():
    class InProcess(get_target_class("crafter")):
        pass

    register_target("in_process_game", InProcess)
    try:
        assert "in_process_game" in registered_targets()
        assert get_target_class("in_process_game") is InProcess
        register_target("in_process_game", InProcess)  # same class again: fine
        with pytest.raises(TargetError, match="already registered"):
            register_target("in_process_game", get_target_class("crafter"))
    finally:
        unregister_target("in_process_game")
    assert "in_process_game" not in registered_targets()
    with pytest.raises(TargetError, match="not a subclass"):
        register_target("x", object)  # type: ignore[arg-type]
    with pytest.raises(TargetError, match="non-empty"):
        register_target("", InProcess)


def test_capabilities_reject_unknown_forms_and_sensors_listing_the_valid_ones():
    with pytest.raises(TargetError, match=r"unknown 'teleport'; valid: .*'joint_trajectory'"):
        TargetCapabilities(action_forms=("teleport",))
    with pytest.raises(TargetError, match=r"unknown 'smell'; valid: .*'rgb'"):
        TargetCapabilities(sensors=("smell",))
    assert capabilities_of(object()) == TargetCapabilities()


_REQUIRED = ("observe", "reset", "step", "execute_trajectory", "query_state", "tools", "save_state", "load_state")


@pytest.mark.parametrize("driver", BUILTINS)
def test_every_builtin_driver_conforms_to_the_target_contract(driver):
    cls = get_target_class(driver)
    assert issubclass(cls, Target) and not inspect.isabstract(cls)
    caps = cls.CAPABILITIES
    assert isinstance(caps, TargetCapabilities)
    assert caps.action_forms and set(caps.action_forms) <= set(ACTION_FORMS)
    assert set(caps.sensors) <= set(SENSOR_KINDS)
    assert cls.ACTION_FORMS == caps.action_forms
    assert cls.KIND in ("simulation", "real_robot", "game")
    assert cls.TOOLS
    for method in _REQUIRED:  # implemented by the driver, not the contract's defaults
        assert getattr(cls, method) is not getattr(Target, method), f"{driver} lacks {method}"
    params = inspect.signature(cls.__init__).parameters
    assert list(params)[:3] == ["self", "name", "scene"] and params["seed"].kind is inspect.Parameter.KEYWORD_ONLY
    assert ("game_action" in caps.action_forms) == (cls.KIND == "game")
    if caps.accepts("joint_trajectory"):
        assert caps.has_sensor("proprioception")
    if caps.has_sensor("perception"):
        assert getattr(cls, "perceive") is not None


@pytest.mark.parametrize("driver", ("crafter", "mujoco_franka"))
def test_a_built_driver_keeps_its_contract_promises(driver, tmp_path):
    cls = get_target_class(driver)
    with cls("t", seed=3) as target:  # the driver's default scene
        assert target.capabilities is cls.CAPABILITIES
        obs = target.reset(seed=3)
        assert isinstance(obs, dict)
        assert set(target.tools()) == set(cls.TOOLS)
        assert isinstance(target.query_state(), dict)
        truth = target.ground_truth()
        assert isinstance(truth, dict) == cls.CAPABILITIES.simulated_ground_truth
        digest = target.world_digest()
        path = target.save_state(tmp_path / "state.npz")
        target.load_state(path)
        assert target.world_digest() == digest
    assert target.closed
