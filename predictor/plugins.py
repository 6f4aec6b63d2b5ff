"""Predictors from outside the project: a plug-in spec ``package.module:name`` names a factory.

    python -m st_sim evaluate --predictor examples.knn_predictor:make
    gym.make("STCrowd-Zara1-v0", predictor="examples.knn_predictor:make")

The factory is called with keyword arguments only, and returns an object with
``predict(obs, group, scene, num_samples) -> (N, S, 12, 2)`` metres (``predictor.protocol.Predictor``)::

    name(task="stochastic", scene="zara1", train=Windows, val=Windows, data_root=Path)

and, if it has a parameter named ``seed``, with ``seed=k`` too: then ``evaluate --seeds 0 1 2`` builds it once
per seed, as it trains SingularTrajectory once per seed (a factory without one gets a single row per scene).
``scene`` is a scene name or a domain pair (``"A2B"``), or None for a simulated env, whose ``train`` and
``val`` are then the windows of all five scenes (the data the universal checkpoint was trained on). Every
failure (a spec that does not import, names nothing callable, a factory that raises or returns no ``predict``,
a ``predict`` that raises or returns anything but (N, S, 12, 2) finite floats) raises ``PluginError`` naming
the spec.
"""

from __future__ import annotations

import importlib
import inspect
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from replays.data_root import data_root
from replays.scenes import Scene
from replays.windows import ALL_SCENES, load_windows
from st_sim.metrics import PredictionError, check_futures

SPEC_PATTERN = re.compile(r"(?P<module>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*):(?P<attr>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)")
SHIPPED_PREFIX = "shipped:"  # ``shipped:<name>`` is a shipped checkpoint, never a plug-in
FACTORY_KEYWORDS = ("task", "scene", "train", "val", "data_root")  # what a factory is called with


class PluginError(ValueError):
    """A plug-in predictor cannot be loaded or gave an unusable prediction (the message names the spec)."""


def is_plugin_spec(text: Any) -> bool:
    """True for a string holding ":" that is neither ``shipped:<name>`` nor an existing file (a checkpoint)."""
    return isinstance(text, str) and ":" in text and not text.startswith(SHIPPED_PREFIX) and not os.path.exists(text)


def describe_error(err: BaseException) -> str:
    """``Type: message`` of an exception, on one line."""
    message = " ".join(str(err).split())
    return f"{type(err).__name__}: {message}" if message else type(err).__name__


def resolve_factory(spec: str, kind: str = "predictor") -> Callable[..., Any]:
    """The callable ``spec`` names, imported. Raises ``PluginError`` if the spec is malformed, does not import
    (module missing, an error inside it) or names something missing or not callable; messages begin with ``kind``
    (what the spec is for: a predictor, a policy)."""
    match = SPEC_PATTERN.fullmatch(spec)
    if match is None:
        raise PluginError(f"{kind} {spec!r}: a plug-in is named package.module:name, a class or factory in an "
                          "importable module")
    module, attr = match["module"], match["attr"]
    try:
        target = importlib.import_module(module)
    except ModuleNotFoundError as err:
        hint = ""
        if err.name is not None and (module == err.name or module.startswith(f"{err.name}.")):
            hint = ("; run from the folder that holds it (`python -m st_sim` puts the working folder on the path) "
                    "or add that folder to PYTHONPATH")
        raise PluginError(f"{kind} {spec!r}: cannot import {module} ({describe_error(err)}){hint}") from err
    except (Exception, SystemExit) as err:
        raise PluginError(f"{kind} {spec!r}: importing {module} raised {describe_error(err)}") from err
    for part in attr.split("."):
        try:
            target = getattr(target, part)
        except Exception as err:
            raise PluginError(f"{kind} {spec!r}: {module} has no {attr} ({describe_error(err)})") from err
    if not callable(target):
        raise PluginError(f"{kind} {spec!r}: {attr} is a {type(target).__name__}, not a callable factory")
    return target


def takes_seed(factory: Callable[..., Any]) -> bool:
    """True if ``factory`` has a parameter named ``seed`` that can be passed by keyword."""
    try:
        parameter = inspect.signature(factory).parameters.get("seed")
    except (TypeError, ValueError):  # a builtin or C callable without a signature
        return False
    return parameter is not None and parameter.kind in (parameter.POSITIONAL_OR_KEYWORD, parameter.KEYWORD_ONLY)


def load_plugin(spec: str, task: str, scene: str | None, root: str | os.PathLike | None = None,
                seed: int = 0) -> PluginPredictor:
    """The predictor that plug-in ``spec`` builds for ``task`` and ``scene`` (None: a simulated env).

    The factory gets ``task``, ``scene``, that task's ``train`` and ``val`` windows (``replays.Windows``;
    all five scenes' for ``scene`` None), the resolved ``data_root`` (``pathlib.Path``) and, if it has a ``seed``
    parameter, ``seed``.
    """
    factory = resolve_factory(spec)
    windows_of = ALL_SCENES if scene is None else scene
    train, val = (load_windows(task, windows_of, split, root) for split in ("train", "val"))
    call = f"{spec.partition(':')[2]}(task={task!r}, scene={scene!r}, ...)"
    extra = {"seed": seed} if takes_seed(factory) else {}
    try:
        model = factory(task=task, scene=scene, train=train, val=val, data_root=data_root(root), **extra)
    except (Exception, SystemExit) as err:
        keywords = f" (it is called with keywords {', '.join(FACTORY_KEYWORDS)})" if isinstance(err, TypeError) else ""
        raise PluginError(f"predictor {spec!r}: {call} raised {describe_error(err)}{keywords}") from err
    try:
        predict = getattr(model, "predict", None)
    except Exception as err:
        raise PluginError(f"predictor {spec!r}: reading {call}.predict raised {describe_error(err)}") from err
    if not callable(predict):
        raise PluginError(f"predictor {spec!r}: {call} returned a {type(model).__name__} without a callable "
                          "predict(obs, group, scene, num_samples)")
    return PluginPredictor(spec, model)


@dataclass(frozen=True)
class PluginPredictor:
    """A plug-in's model behind checks: ``predict`` hands it copies of the inputs and validates what it returns."""

    spec: str
    """``package.module:name``, as given"""
    model: Any = field(repr=False)
    """what the factory returned"""

    @property
    def name(self) -> str:
        return self.spec

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None, num_samples: int) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, S, 12, 2) float32 metres; ``PluginError`` if the model raises or returns
        anything else (a list, None, another shape or S, a non-float dtype, NaN or inf)."""
        obs, group = np.array(obs, np.float32), np.array(group, np.int64)  # copies: the caller's arrays stay intact
        try:
            futures = self.model.predict(obs, group, scene, int(num_samples))
        except (Exception, SystemExit) as err:
            raise PluginError(f"predictor {self.spec!r}: predict raised {describe_error(err)}") from err
        try:
            return check_futures(futures, len(obs), int(num_samples), self.spec)
        except PredictionError as err:
            raise PluginError(str(err)) from err
