"""Shared test set-up."""

# Imported first so it selects MuJoCo's headless GL backend (see phyagentos/__init__.py)
# before any test module imports mujoco.
import phyagentos  # noqa: F401

# isort: split
import json
from pathlib import Path

from hypothesis import settings

# Property tests check what comes out, not how fast: hypothesis's default 200 ms deadline per
# example is a timing assertion, which fails on a loaded machine (a 20 ms example took 312 ms
# with the suite's workers and a CPU hog sharing two cores). Speed is measured in bench/.
settings.register_profile("suite", deadline=None)
settings.load_profile("suite")

# `make test` hands whole files to its workers (`--dist loadfile --no-loadscope-reorder`) in
# collection order. Longest first (tests/durations.json, scripts/update_test_durations.py):
# a long file that starts last keeps one worker busy while the others sit idle.
_DURATIONS = Path(__file__).with_name("durations.json")


def pytest_collection_modifyitems(session, config, items):
    try:
        seconds = json.loads(_DURATIONS.read_text())
    except (OSError, ValueError):
        return
    # A stable sort keeps each file's tests together and in their written order.
    items.sort(key=lambda item: -float(seconds.get(item.path.name, 0.0)))
