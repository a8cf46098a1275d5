"""Argument types the CLI's verbs share."""

from __future__ import annotations

import argparse
from pathlib import Path

from phyagentos.resources import ExampleNotFoundError, goal_graph_path

__all__ = ["goal_graph_arg"]


def goal_graph_arg(text: str) -> Path:
    """argparse type of a goal-graph argument: a path, or the name of a shipped example
    (``pick_and_place``; :func:`phyagentos.resources.goal_graph_path`). An unknown bare
    name is an argument error (exit 2) that lists the examples."""
    try:
        return goal_graph_path(text)
    except ExampleNotFoundError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc
