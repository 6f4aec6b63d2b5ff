"""Which predictor runs inside an environment, and one checked, batched call per step."""

from __future__ import annotations

import os
import sys
from collections import OrderedDict
from collections.abc import Hashable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from predictor.protocol import scenes_of_agents
from replays.constants import T_PRED, TASKS
from replays.scenes import Scene
from st_sim.metrics import check_futures

ENV_TASKS: tuple[str, ...] = ("stochastic", "deterministic", "momentary")  # tasks an env can play


class PredictorUnavailableError(RuntimeError):
    """The requested predictor cannot be loaded in this installation."""


def task_sizes(task: str) -> tuple[int, int]:
    """(T_obs, S) of a task: stochastic (8, 20), deterministic (8, 1), momentary (2, 20)."""
    if task not in ENV_TASKS:
        raise ValueError(f"task={task!r}: an environment plays one of {', '.join(ENV_TASKS)}")
    return TASKS[task]["obs_len"], TASKS[task]["num_samples"]


def shipped_checkpoint(task: str, scene: str | None) -> str:
    """Name of the shipped SingularTrajectory checkpoint an env uses for ``task`` on a real ``scene``.

    A replay gets its scene's leave-one-out model, which never saw that scene: ``stochastic/<scene>``,
    ``deterministic/<scene>`` (one sample) or ``momentary/<scene>`` (2 observed frames). A simulated layout
    (``scene`` None) gets the model trained on all five scenes: ``universal`` (the deterministic task keeps
    its likeliest sample) or ``momentary/universal``.
    """
    if scene is None:
        return "momentary/universal" if task == "momentary" else "universal"
    return f"{task}/{scene}"


def scene_of_checkpoint(pretrained: str) -> str | None:
    """The scene ``shipped_checkpoint`` named ``pretrained`` for: ``"stochastic/zara1"`` -> zara1, a universal
    checkpoint (a simulated layout) -> None."""
    return None if pretrained.endswith("universal") else pretrained.rpartition("/")[2]


def resolve_predictor(spec: Any, task: str = "stochastic", pretrained: str = "universal",
                      root: str | os.PathLike | None = None, device: str = "cpu") -> Any:
    """A predictor object from a name (auto, cvm, cvm-s, linear, singular), a plug-in ``package.module:name``, or
    an object with ``predict``.

    ``singular`` (and ``auto``, its alias) loads the shipped checkpoint ``pretrained`` (see
    ``shipped_checkpoint``) onto ``device`` (``predictor.devices``; "auto": a GPU when torch sees one); torch is only
    imported then. A predictor object runs where it is. A plug-in's factory is called with ``task``, the env's
    scene (None for a simulated layout), that scene's training and validation windows (all five scenes' for
    None) and the env's data root ``root`` (``predictor.plugins.load_plugin``).
    """
    if spec == "auto":
        spec = "singular"
    if isinstance(spec, str):
        from predictor.baselines import BASELINES
        from predictor.plugins import is_plugin_spec, load_plugin

        if spec in BASELINES:
            return BASELINES[spec]()
        if spec == "singular":
            return _load_singular(pretrained).to(device)
        if is_plugin_spec(spec):
            return load_plugin(spec, task, scene_of_checkpoint(pretrained), root)
        raise ValueError(f"predictor={spec!r}: expected one of {', '.join([*BASELINES, 'singular'])}, a plug-in "
                         "package.module:name or an object with predict(obs, group, scene, num_samples)")
    if callable(getattr(spec, "predict", None)):
        return spec
    raise TypeError(f"predictor must be a name or have a predict(obs, group, scene, num_samples) method, "
                    f"got {type(spec).__name__}")


def _load_singular(name: str) -> Any:
    import predictor

    try:
        return predictor.load_pretrained(name)
    except (FileNotFoundError, KeyError) as err:
        raise PredictorUnavailableError(
            f"predictor='singular': the shipped {name!r} SingularTrajectory checkpoint cannot be loaded ({err}); "
            "use predictor='cvm' (or 'cvm-s') or pass an object with predict(obs, group, scene, num_samples)"
        ) from err


@dataclass(frozen=True, eq=False)
class ForecastRequest:
    """What an env asks the predictor for at one moment: the histories (C, T_obs, 2) float32 metres of the agents
    the forecast conditions on, which of them get futures (``targets`` (C,) bool), and whether their anchor paths
    are wanted too (a Rerun recording logs them)."""

    histories_m: np.ndarray
    targets: np.ndarray
    anchors: bool = False


def predict_futures(model: Any, history_m: np.ndarray, scene: Scene | Sequence[Scene | None] | None,
                    num_samples: int, group: np.ndarray | None = None, targets: np.ndarray | None = None,
                    anchors: bool = True) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """One batched call for all agents of one scene moment, or of several (sub-envs, of one scenario or several).

    Args:
        history_m: (P, T_obs, 2) float32 metres, world frame.
        scene: the scene of every agent, or one per group value (moments of several scenes, each forecast on its own
            map: SingularTrajectory takes them in one call, any other predictor gets one call per scene).
        group: (P,) int64 scene moment of each agent (agents interact only within one); None: all in one.
        targets: (P,) bool, the agents to forecast; the others only condition them (a predictor with
            ``predict_detailed`` skips their futures; any other forecasts all P and keeps the targets'); None: all.
        anchors: return the anchor paths of predictors with ``predict_detailed`` (False: None, and cheaper).

    Returns:
        futures: (T, S, 12, 2) float32 metres of the T targets, within +-FORECAST_LIMIT_M.
        anchors: (prototype, adapted), each (T, S, 12, 2) metres, for predictors with
            ``predict_detailed`` (SingularTrajectory) when asked for; None otherwise.

    Raises:
        ValueError: the predictor returned anything but (P, S, 12, 2) finite floats within +-FORECAST_LIMIT_M
            (``st_sim.metrics.PredictionError``; ``predictor.plugins.PluginError`` from a plug-in).
    """
    targets = np.ones(len(history_m), bool) if targets is None else np.asarray(targets, bool)
    if not targets.any():
        return np.zeros((0, num_samples, T_PRED, 2), np.float32), None
    group = np.zeros(len(history_m), np.int64) if group is None else np.asarray(group, np.int64)
    paths = None
    name = getattr(model, "name", type(model).__name__)
    with one_torch_thread():
        if gives_anchors(model):
            detail = model.predict_detailed(history_m, group, scene, num_samples, targets=targets, anchors=anchors)
            futures = check_futures(detail.futures, int(targets.sum()), num_samples, name)
            if anchors:
                paths = (detail.prototype_anchors, detail.adapted_anchors)
        else:
            futures = np.zeros((len(history_m), num_samples, T_PRED, 2), np.float32)
            scenes, scene_index = scenes_of_agents(scene, group)
            for i, one_scene in enumerate(scenes):
                on_it = scene_index == i
                futures[on_it] = check_futures(model.predict(history_m[on_it], group[on_it], one_scene, num_samples),
                                               int(on_it.sum()), num_samples, name)
            futures = futures[targets]
    return futures, paths


def gives_anchors(model: Any) -> bool:
    """True for a predictor with ``predict_detailed`` (SingularTrajectory): it can give its anchor paths."""
    return callable(getattr(model, "predict_detailed", None))


@contextmanager
def one_torch_thread() -> Iterator[None]:
    """Run the block with one torch thread (restored after): an env's forecasts are small batches, which torch's
    thread pool slows down (a second thread costs more than it saves, and far more on a busy machine). More cores
    serve a vector env through its shards (``envs.shards``)."""
    torch = sys.modules.get("torch")  # never imported here: a predictor without torch skips it
    threads = torch.get_num_threads() if torch is not None else 1
    if threads > 1:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        if threads > 1:
            torch.set_num_threads(threads)


Forecast = tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]
"""(futures (P, S, 12, 2), anchors (prototype, adapted) or None), as ``predict_futures`` returns them"""


class Forecasting(Protocol):
    """What ``forecast_all`` asks of an env (``envs.common.crowd_env.CrowdEnv``)."""

    predictor: Any
    num_samples: int
    scene: Scene | None

    def cached_forecast(self) -> Forecast | None: ...
    def forecast_request(self) -> ForecastRequest: ...
    def remember_forecast(self, forecast: Forecast) -> None: ...


def forecast_all(envs: Sequence[Forecasting]) -> list[Forecast]:
    """Every env's forecast of its ``forecast_request()``, in order: the kept one where an env has it
    (``ForecastCache``), else one ``predict_futures`` call per predictor object and sample count for all the
    others' agents, each env's moment a group of its own on its own scene. Anchors go to the envs that ask for them
    (None to the others)."""
    forecasts: list[Forecast | None] = [env.cached_forecast() for env in envs]
    models: dict[tuple[int, int], list[int]] = {}
    for i, forecast in enumerate(forecasts):
        if forecast is None:
            models.setdefault((id(envs[i].predictor), envs[i].num_samples), []).append(i)
    for missing in models.values():
        first = envs[missing[0]]
        requests = [envs[i].forecast_request() for i in missing]
        sizes = [len(request.histories_m) for request in requests]
        wanted = any(request.anchors for request in requests)
        futures, anchors = predict_futures(first.predictor, np.concatenate([r.histories_m for r in requests]),
                                           [envs[i].scene for i in missing], first.num_samples,
                                           np.repeat(np.arange(len(missing)), sizes),
                                           np.concatenate([r.targets for r in requests]), anchors=wanted)
        cuts = np.cumsum([int(request.targets.sum()) for request in requests])[:-1]
        prototypes, adapted = [None] * len(missing), [None] * len(missing)
        if anchors is not None:
            prototypes, adapted = np.split(anchors[0], cuts), np.split(anchors[1], cuts)
        for i, request, own, prototype, own_adapted in zip(missing, requests, np.split(futures, cuts), prototypes,
                                                            adapted, strict=True):
            forecasts[i] = (own, (prototype, own_adapted) if request.anchors and anchors is not None else None)
            envs[i].remember_forecast(forecasts[i])
    return forecasts


class ForecastCache:
    """Forecasts of recorded scene moments, kept for reuse: (moment, agent ids) -> each agent's futures (and anchors).

    A log-mode replay shows the same agents with the same histories whenever it reaches the same frame, so their
    forecasts need computing once. Entries are stored by agent id, so a later visit that lists the same agents in
    other observation rows gets them in its own order. Least recently used entries go beyond ``budget_bytes``.
    """

    def __init__(self, budget_bytes: int = 256 * 2**20):
        self.budget_bytes, self.used_bytes = budget_bytes, 0
        self._entries: OrderedDict[tuple, tuple[np.ndarray, Forecast]] = OrderedDict()
        self.hits = self.misses = 0

    def get(self, moment: Hashable, ids: np.ndarray, context: np.ndarray | None = None, anchors: bool = False
            ) -> Forecast | None:
        """The forecast of agents ``ids`` (P,) at ``moment`` conditioned on agents ``context`` (C,) (None: on ``ids``
        alone), in the order of ``ids``, or None if not kept (with ``anchors``: if kept without anchor paths)."""
        key = self._key(moment, ids, context)
        entry = self._entries.get(key)
        if entry is None or (anchors and entry[1][1] is None):
            self.misses += 1
            return None
        self.hits += 1
        self._entries.move_to_end(key)
        stored_ids, (futures, paths) = entry
        order = np.searchsorted(stored_ids, ids)
        return futures[order], None if paths is None else (paths[0][order], paths[1][order])

    def put(self, moment: Hashable, ids: np.ndarray, forecast: Forecast, context: np.ndarray | None = None) -> None:
        """Keep the forecast of agents ``ids`` (P,) at ``moment`` conditioned on agents ``context`` (C,); one with
        anchor paths replaces a kept one without."""
        key = self._key(moment, ids, context)
        if key in self._entries:
            if self._entries[key][1][1] is not None or forecast[1] is None:
                return
            self.used_bytes -= _nbytes(self._entries.pop(key)[1])
        order = np.argsort(ids)
        futures, anchors = forecast
        kept = (futures[order], None if anchors is None else (anchors[0][order], anchors[1][order]))
        self._entries[key] = (ids[order], kept)
        self.used_bytes += _nbytes(kept)
        while self.used_bytes > self.budget_bytes and len(self._entries) > 1:
            _, (_, dropped) = self._entries.popitem(last=False)
            self.used_bytes -= _nbytes(dropped)

    @staticmethod
    def _key(moment: Hashable, ids: np.ndarray, context: np.ndarray | None) -> tuple:
        context_key = None if context is None or np.array_equal(np.sort(context), np.sort(ids)) else \
            tuple(sorted(context.tolist()))
        return (moment, context_key, *sorted(ids.tolist()))


def _nbytes(forecast: Forecast) -> int:
    futures, anchors = forecast
    return futures.nbytes + (0 if anchors is None else anchors[0].nbytes + anchors[1].nbytes)
