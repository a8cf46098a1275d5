"""Shared test set-up."""

# Imported first so it selects MuJoCo's headless GL backend (see phyagentos/__init__.py)
# before any test module imports mujoco.
import phyagentos  # noqa: F401

# isort: split
from hypothesis import settings

# Property tests check what comes out, not how fast: hypothesis's default 200 ms deadline per
# example is a timing assertion, which fails on a loaded machine (a 20 ms example took 312 ms
# with the suite's workers and a CPU hog sharing two cores). Speed is measured in bench/.
settings.register_profile("suite", deadline=None)
settings.load_profile("suite")
