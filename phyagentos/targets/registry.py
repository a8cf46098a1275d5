"""The target registry: driver name (TARGETS.md ``driver``) -> :class:`~phyagentos.targets.contract.Target` class.

Drivers come from the Python entry-point group ``phyagentos.targets`` (name ->
``"module:Class"``), so a package adds a robot or a game by declaring, in its own
``pyproject.toml``::

    [project.entry-points."phyagentos.targets"]
    my_arm = "my_package.my_arm:MyArmTarget"

The built-ins are declared the same way in PhyAgentOS's ``pyproject.toml``. A driver's
module is imported only when the driver is first asked for (:func:`get_target_class`),
so a broken or heavy plugin costs nothing until used. :func:`register_target` adds a
class in-process (tests, notebooks); it wins over an entry point of the same name.

Errors: an unknown name raises :class:`~phyagentos.errors.TargetError` listing the
registered names; an entry point that does not import (or does not name a
:class:`Target` subclass) raises one naming the entry point and its value.
"""

from __future__ import annotations

import importlib
import logging
import threading
from collections.abc import Iterator, Mapping
from importlib import metadata

from phyagentos.errors import TargetError, format_choices

from .contract import Target

__all__ = ["ENTRY_POINT_GROUP", "DRIVERS", "get_target_class", "refresh", "register_target", "registered_targets",
           "unregister_target"]

logger = logging.getLogger(__name__)

#: The entry-point group drivers are declared in.
ENTRY_POINT_GROUP = "phyagentos.targets"

# The built-in drivers, as declared in pyproject.toml's [project.entry-points."phyagentos.targets"].
# Used ONLY for a name the installed metadata lacks: an editable install made before the
# entry points were declared (re-running `pip install -e .` refreshes the metadata) or a
# source checkout run without installing. Keep in step with pyproject.toml.
_BUILTIN_FALLBACK: dict[str, str] = {
    "mujoco_franka": "phyagentos.targets.franka_tabletop:MuJoCoTarget",
    "gymnasium_kitchen": "phyagentos.targets.kitchen:FrankaKitchenTarget",
    "mujoco_so101": "phyagentos.targets.so101:SO101Target",
    "crafter": "phyagentos.targets.crafter:CrafterTarget",
    "so101_real": "phyagentos.targets.so101_real.target:SO101RealTarget",
    "libero": "phyagentos.targets.libero:LiberoTarget",
}

_lock = threading.RLock()
_registered: dict[str, type[Target]] = {}  # register_target (in-process)
_loaded: dict[str, type[Target]] = {}  # entry points already imported
_entry_points: dict[str, tuple[str, str]] | None = None  # name -> (value, origin)


def _declared() -> dict[str, tuple[str, str]]:
    """name -> ("module:Class", origin) for every declared driver (entry points, then the
    built-in fallback for names the metadata lacks); read once."""
    global _entry_points
    with _lock:
        if _entry_points is None:
            found: dict[str, tuple[str, str]] = {}
            for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
                dist = getattr(ep, "dist", None)
                origin = f"entry point {ep.name!r} of {dist.name if dist is not None else 'an installed package'}"
                found.setdefault(ep.name, (ep.value, origin))
            for name, value in _BUILTIN_FALLBACK.items():
                found.setdefault(name, (value, f"built-in driver {name!r}"))
            _entry_points = found
        return _entry_points


def _load(name: str, value: str, origin: str) -> type[Target]:
    module_name, _, attr = value.partition(":")
    try:
        obj = importlib.import_module(module_name)
        for part in attr.split(".") if attr else ():
            obj = getattr(obj, part)
    except Exception as exc:  # noqa: BLE001 - any failure of a plugin's import is reported as one error
        raise TargetError(f"target driver {name!r} ({origin}, {value!r}) failed to load: "
                          f"{type(exc).__name__}: {exc}") from exc
    if not attr or not isinstance(obj, type) or not issubclass(obj, Target):
        raise TargetError(f"target driver {name!r} ({origin}, {value!r}) is not a subclass of "
                          f"phyagentos.targets.contract.Target (got {obj!r})")
    return obj


def refresh() -> None:
    """Re-read the entry points (after installing a plugin into the running interpreter);
    drivers already imported stay imported."""
    global _entry_points
    with _lock:
        _entry_points = None


def registered_targets() -> tuple[str, ...]:
    """Sorted names of every registered driver (entry points, built-ins, :func:`register_target`)."""
    with _lock:
        return tuple(sorted(set(_declared()) | set(_registered)))


def get_target_class(name: str) -> type[Target]:
    """The driver class registered as ``name``, imported on first use.

    Raises:
        TargetError: ``name`` is not registered (the message lists the registered names),
            or its entry point fails to import or names no :class:`Target` subclass (the
            message names the entry point).
    """
    with _lock:
        if name in _registered:
            return _registered[name]
        if name in _loaded:
            return _loaded[name]
        declared = _declared().get(name)
        if declared is None:
            raise TargetError(f"unknown target driver {name!r}; valid drivers: {format_choices(registered_targets())}")
        cls = _load(name, *declared)
        _loaded[name] = cls
        return cls


def register_target(name: str, cls: type[Target], *, replace: bool = False) -> None:
    """Register ``cls`` as driver ``name`` in this process (tests, in-process plugins).

    Raises:
        TargetError: an empty name, a class that is not a :class:`Target` subclass, or a
            name already registered in-process with another class (unless ``replace``).
    """
    if not isinstance(name, str) or not name:
        raise TargetError(f"target driver name must be a non-empty string, got {name!r}")
    if not isinstance(cls, type) or not issubclass(cls, Target):
        raise TargetError(f"target driver {name!r}: {cls!r} is not a subclass of phyagentos.targets.contract.Target")
    with _lock:
        old = _registered.get(name)
        if old is not None and old is not cls and not replace:
            raise TargetError(f"target driver {name!r} is already registered ({old.__module__}.{old.__qualname__})")
        _registered[name] = cls


def unregister_target(name: str) -> None:
    """Forget an in-process registration (no-op for a name not registered in-process)."""
    with _lock:
        _registered.pop(name, None)


class _Drivers(Mapping):
    """A read-only, lazily loading view of the registry: ``DRIVERS[name]`` is
    :func:`get_target_class` (a :class:`KeyError` for an unknown name), iteration lists
    :func:`registered_targets` without importing anything."""

    def __getitem__(self, name: str) -> type[Target]:
        if name not in registered_targets():
            raise KeyError(name)
        return get_target_class(name)

    def __contains__(self, name: object) -> bool:
        return name in registered_targets()

    def __iter__(self) -> Iterator[str]:
        return iter(registered_targets())

    def __len__(self) -> int:
        return len(registered_targets())

    def __repr__(self) -> str:
        return f"DRIVERS({', '.join(registered_targets())})"


#: Read-only mapping view of the registry (name -> driver class, loaded on access).
DRIVERS: Mapping[str, type[Target]] = _Drivers()
