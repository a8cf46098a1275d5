"""Shared test set-up."""

# Imported first so it selects MuJoCo's headless GL backend (see phyagentos/__init__.py)
# before any test module imports mujoco.
import phyagentos  # noqa: F401
