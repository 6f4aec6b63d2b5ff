"""The predictors a planner can be run with: by name, "none" (pedestrians assumed to stand still), or a plug-in
``package.module:name`` (``predictor.plugins``)."""

from __future__ import annotations

import argparse
from typing import Any

from predictor.plugins import is_plugin_spec, resolve_factory

PREDICTORS: tuple[str, ...] = ("none", "cvm", "cvm-s", "singular")
"""predictor names of the navigation benchmark's table, no prediction first"""
NAMES: tuple[str, ...] = (*PREDICTORS, "linear")
"""every predictor name a planner takes (the least-squares line too)"""


def env_predictor(name: str) -> Any:
    """The env's ``predictor=`` argument for a predictor name (see ``NAMES``) or a plug-in spec.

    A spec is checked here (it must import and name a callable: ``PluginError`` otherwise) and passed on as
    given: the env calls the factory with ``task``, its scene (None for a simulated layout) and that scene's
    training and validation windows.
    """
    if is_plugin_spec(name):
        resolve_factory(name)
        return name
    if name not in NAMES:
        raise ValueError(f"predictor={name!r}: expected one of {', '.join(NAMES)} or a plug-in "
                         "package.module:name")
    return name


def predictor_argument(text: str) -> str:
    """argparse type of ``--predictor``: a name of ``NAMES`` or anything with ":" (a plug-in, checked later)."""
    if text in NAMES or ":" in text:
        return text
    raise argparse.ArgumentTypeError(f"{text!r}: expected one of {', '.join(NAMES)} or a plug-in "
                                     "package.module:name")
