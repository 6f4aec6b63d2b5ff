"""The navigation suite: named scenarios (an env id and its ``gym.make`` keywords) and their seeds, by split.

    suite = load_suite()                            # the shipped suite (suites/stcrowd-nav-1.0.json)
    seeds = suite.seeds_of("test", episodes=100)    # episode i of every scenario resets with seeds[i]
    env = make_scenario_env(scenario, "singular")   # gym.make(scenario.env, **scenario.env_kwargs, predictor=...)
    seed = suite.draw_seed("train", rng)            # a training episode's seed, never a val or test one

A suite file is JSON: ``format``, ``name``, ``version``, ``episodes`` (the default per scenario), ``seeds`` and
``scenarios`` (``[{"name", "env", "env_kwargs", "description"}]``). ``seeds`` holds two published lists, ``val``
for tuning and a disjoint ``test`` for the figures you report, and may hold the ``train`` rule
``{"from": A, "below": B}``: every integer seed in [A, B) that is in neither list, in increasing order (so training
never meets an episode that is scored). Results carry the suite's name and version, so a figure names the exact
episodes it was measured on: a new scenario or a new val or test list is a new version; the train rule scores nothing
and leaves the version as it is. They carry its ``content_sha256`` too (a hash of everything that decides an episode:
seeds, scenarios, env ids and keywords), so two files that claim one name and version but differ are told apart.

A suite file may come from anyone, so it names nothing that runs and no path: a scenario's ``env`` is one of
STCrowd's registered ids (never ``module:Id``), and its ``env_kwargs`` are among ``SCENARIO_KEYWORDS``, each a
JSON bool or a plain name (``check_scenario``); outputs (``rerun``) and data roots come from the user's command.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from replays import strict_json

SUITE_FORMAT = "stcrowd-nav-suite/1"
SHIPPED_SUITE = "stcrowd-nav-1.0.json"
LISTED_SPLITS: tuple[str, ...] = ("val", "test")
"""the published seed lists: val for tuning, test for the figures you report"""
SPLITS: tuple[str, ...] = ("train", *LISTED_SPLITS)
"""every split: train (a rule, ``TrainSeeds``) and the published lists"""
SEED_LIMIT = 2**63  # a train rule's range ends at most here [-]
SCENARIO_KEYWORDS: dict[str, type] = {"pedestrians": str, "reaction_traits": str, "task": str, "scene": str,
                                      "layout": str, "encounter": str, "pretrained": str, "ego": bool,
                                      "benchmark_windows": bool, "pedestrians_see_ego": bool}
"""the ``gym.make`` keywords a scenario may set, by the JSON type of their value; everything else (a path such as
``rerun``, ``root`` or ``recording``, a predictor, a config object) is the user's to give, never a file's"""
PLAIN_NAME = re.compile(r"[A-Za-z0-9_-]+(?:/[A-Za-z0-9_-]+)?")
"""a string keyword's value: a name, or ``group/name`` (a shipped checkpoint); never a path or a ``module:name``"""


class SuiteError(ValueError):
    """A suite file is malformed, or a scenario, split or episode count does not exist in it."""


@dataclass(frozen=True)
class Scenario:
    """One named setting of the benchmark.

    Attributes:
        name: unique in its suite (``sim-crossing``, ``univ-reactive``).  env: a registered gym id.
        env_kwargs: keywords for ``gym.make`` (JSON values).  description: what happens in it.
    """

    name: str
    env: str
    env_kwargs: Mapping[str, Any]
    description: str = ""


def check_scenario(env_id: Any, env_kwargs: Any, where: str) -> None:
    """Refuse a scenario that would run code or write where a file says (``SuiteError`` starting with ``where``):
    ``env_id`` must be one of STCrowd's registered ids (``envs.*`` entry points; a ``module:Id`` would make gymnasium
    import ``module``), ``env_kwargs`` a dict of ``SCENARIO_KEYWORDS``, each of its type, strings ``PLAIN_NAME``s."""
    entry = gym.registry.get(env_id) if isinstance(env_id, str) and ":" not in env_id else None
    if entry is None or not str(entry.entry_point).startswith("envs."):
        raise SuiteError(f"{where}: env {_shown(env_id)} is not one of STCrowd's registered env ids (STCrowd-...)")
    if not isinstance(env_kwargs, dict):
        raise SuiteError(f"{where}: env_kwargs must be an object of gym.make keywords")
    for key, value in env_kwargs.items():
        kind = SCENARIO_KEYWORDS.get(key)
        if kind is None:
            raise SuiteError(f"{where}: env_kwargs {_shown(key)} is not a keyword a scenario may set (only "
                             f"{', '.join(SCENARIO_KEYWORDS)}; paths, outputs and predictors come from the command)")
        if type(value) is not kind or (kind is str and not PLAIN_NAME.fullmatch(value)):
            what = "true or false" if kind is bool else "a plain name (letters, digits, _ and -)"
            raise SuiteError(f"{where}: env_kwargs[{key!r}] must be {what}, got {_shown(value)}")


def _shown(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def env_kwargs_of(scenario: Scenario, predictor: Any) -> dict[str, Any]:
    """Every keyword the benchmark passes to ``gym.make`` for ``scenario`` (the data root aside)."""
    return {**scenario.env_kwargs, "predictor": predictor}


def make_scenario_env(scenario: Scenario, predictor: Any, data_root: str | None = None, **extra: Any) -> gym.Env:
    """``gym.make(scenario.env, **env_kwargs_of(scenario, predictor))``, with ``root`` when a data root is given and
    ``extra`` keywords (``render_mode``, ``device``)."""
    root = {} if data_root is None else {"root": data_root}
    return gym.make(scenario.env, **env_kwargs_of(scenario, predictor), **root, **extra)


@dataclass(frozen=True)
class TrainSeeds:
    """The train split's seeds: every integer in [first, below) that is in no published list, in increasing order.

    Attributes:
        first, below: the range.  listed: the published seeds inside it, sorted.
    """

    first: int
    below: int
    listed: tuple[int, ...] = field(repr=False)

    @property
    def count(self) -> int:
        """How many seeds the rule holds."""
        return self.below - self.first - len(self.listed)

    def nth(self, index: np.ndarray) -> np.ndarray:
        """(...) int64 indices in [0, count) -> (...) the seeds of those ranks: the k-th integer of the range that is
        in no list."""
        free_below = np.asarray(self.listed, np.int64) - self.first - np.arange(len(self.listed))  # non-decreasing
        index = np.asarray(index, np.int64)
        return self.first + index + np.searchsorted(free_below, index, side="right")


@dataclass(frozen=True)
class Suite:
    """Scenarios and seeds of one suite version (``load_suite``)."""

    name: str
    version: str
    scenarios: tuple[Scenario, ...]
    seeds: Mapping[str, tuple[int, ...]]
    """the published lists, by split (val, test)"""
    episodes: int
    """default episodes per scenario"""
    path: Path
    """the file it was read from"""
    train: TrainSeeds | None = None
    """the train split's rule (None: the file states none)"""
    content_sha256: str = ""
    """hex SHA-256 of what decides the suite's episodes (``content_hash``)"""

    def __repr__(self) -> str:
        return f"Suite({self.name} {self.version}: {len(self.scenarios)} scenarios)"

    def select(self, names: Sequence[str] | None) -> tuple[Scenario, ...]:
        """The scenarios called ``names`` in suite order (None: all); ``SuiteError`` naming an unknown one."""
        if names is None:
            return self.scenarios
        known = {scenario.name for scenario in self.scenarios}
        unknown = [name for name in names if name not in known]
        if unknown:
            raise SuiteError(f"suite {self.name} {self.version} has no scenario {unknown[0]!r}; it has "
                             f"{', '.join(sorted(known))}")
        return tuple(scenario for scenario in self.scenarios if scenario.name in set(names))

    def seeds_of(self, split: str, episodes: int | None = None) -> tuple[int, ...]:
        """The first ``episodes`` (default: the suite's) seeds of ``split``; ``SuiteError`` if the split is unknown
        or holds fewer."""
        self.check_split(split)
        episodes = self.episodes if episodes is None else episodes
        available = self.train.count if split == "train" else len(self.seeds[split])
        if not 1 <= episodes <= available:
            raise SuiteError(f"{episodes} episodes asked of the {split} seeds of suite {self.name} {self.version}, "
                             f"which holds {available}: ask 1 to {available}")
        if split == "train":
            return tuple(self.train.nth(np.arange(episodes)).tolist())
        return self.seeds[split][:episodes]

    def draw_seed(self, split: str, rng: np.random.Generator) -> int:
        """A seed of ``split`` drawn uniformly with ``rng`` (train: among every seed of its rule); ``SuiteError`` if
        the split is unknown."""
        self.check_split(split)
        if split == "train":
            return int(self.train.nth(rng.integers(self.train.count)))
        return self.seeds[split][int(rng.integers(len(self.seeds[split])))]

    def check_split(self, split: Any) -> None:
        """Refuse a split the suite does not have (``SuiteError``): not one of ``SPLITS``, or train without a rule."""
        if split not in SPLITS:
            raise SuiteError(f"suite {self.name} {self.version} has no split {split!r}; the splits are "
                             f"{', '.join(SPLITS)}")
        if split == "train" and self.train is None:
            raise SuiteError(f"suite {self.name} {self.version} ({self.path}) states no train seeds (seeds.train: "
                             "{\"from\": A, \"below\": B})")


def load_suite(path: str | Path | None = None) -> Suite:
    """The suite in ``path`` (None: the shipped one), checked: ``SuiteError`` naming the file and the field at fault
    (unknown env ids, duplicate names, non-JSON keywords, seeds that are not ints >= 0, repeated, or shared by two
    lists, a train rule that is not a range holding a seed outside the lists)."""
    if path is None:
        text = resources.files(__package__).joinpath("suites", SHIPPED_SUITE).read_text()
        path = Path(str(resources.files(__package__).joinpath("suites", SHIPPED_SUITE)))
    else:
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as err:
            raise SuiteError(f"{path}: cannot read the suite file ({err.strerror or err})") from err
    try:
        raw = json.loads(text)
    except json.JSONDecodeError as err:
        raise SuiteError(f"{path}: not JSON ({err})") from err
    return _parse(raw, path)


def _parse(raw: Any, path: Path) -> Suite:
    def fail(message: str) -> SuiteError:
        return SuiteError(f"{path}: {message}")

    if not isinstance(raw, dict) or raw.get("format") != SUITE_FORMAT:
        raise fail(f"not a navigation suite (expected \"format\": \"{SUITE_FORMAT}\")")
    for key in ("name", "version"):
        if not isinstance(raw.get(key), str) or not raw[key]:
            raise fail(f"{key!r} must be a non-empty string")
    episodes = raw.get("episodes")
    if not _is_int(episodes) or episodes < 1:
        raise fail(f"'episodes' must be an int >= 1, got {episodes!r}")
    seeds = raw.get("seeds")
    if not isinstance(seeds, dict) or not set(LISTED_SPLITS) <= set(seeds) or not set(seeds) <= set(SPLITS):
        raise fail(f"'seeds' must hold the lists {', '.join(LISTED_SPLITS)} and may hold the train rule, nothing else")
    lists = {split: _seed_list(seeds[split], split, fail) for split in LISTED_SPLITS}
    _check_disjoint(lists, fail)
    train = _train_rule(seeds["train"], lists, fail) if "train" in seeds else None
    scenarios = raw.get("scenarios")
    if not isinstance(scenarios, list) or not scenarios:
        raise fail("'scenarios' must be a non-empty list")
    parsed = tuple(_scenario(entry, i, fail) for i, entry in enumerate(scenarios))
    names = [scenario.name for scenario in parsed]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise fail(f"scenario name {repeated[0]!r} is used twice")
    content = {"name": raw["name"], "version": raw["version"], "episodes": episodes, "seeds": seeds,
               "scenarios": [{"name": sc.name, "env": sc.env, "env_kwargs": dict(sc.env_kwargs)} for sc in parsed]}
    return Suite(raw["name"], raw["version"], parsed, lists, episodes, path, train, content_hash(content))


def content_hash(content: dict[str, Any]) -> str:
    """Hex SHA-256 of a suite's content as canonical JSON (sorted keys, no spaces): name, version, default episodes,
    seeds (the lists and the train rule) and each scenario's name, env id and keywords; descriptions and notes are
    left out, so rewording one changes nothing."""
    text = strict_json.dumps(content, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _seed_list(values: Any, split: str, fail: Any) -> tuple[int, ...]:
    if not isinstance(values, list) or not values or any(not _is_int(v) or v < 0 for v in values):
        raise fail(f"seeds[{split!r}] must be a non-empty list of ints >= 0")
    return tuple(values)


def _check_disjoint(lists: dict[str, tuple[int, ...]], fail: Any) -> None:
    seen: dict[int, str] = {}
    for split, values in lists.items():
        for value in values:
            if value in seen:
                where = "twice in it" if seen[value] == split else f"in {seen[value]!r} too"
                raise fail(f"seed {value} of seeds[{split!r}] is {where}: the lists must be disjoint, without repeats")
            seen[value] = split


def _train_rule(rule: Any, lists: dict[str, tuple[int, ...]], fail: Any) -> TrainSeeds:
    """The train rule ``{"from": A, "below": B}`` of disjoint ``lists``; it must hold a seed outside them."""
    if not isinstance(rule, dict) or set(rule) != {"from", "below"} or not all(map(_is_int, rule.values())) or \
            not 0 <= rule["from"] < rule["below"] <= SEED_LIMIT:
        shown = repr(rule) if len(repr(rule)) <= 80 else repr(rule)[:80] + "..."
        raise fail(f"seeds['train'] must be {{\"from\": A, \"below\": B}} with ints 0 <= A < B <= 2^63 (every seed "
                   f"in [A, B) in neither list), got {shown}")
    first, below = rule["from"], rule["below"]
    listed = tuple(sorted(v for values in lists.values() for v in values if first <= v < below))
    train = TrainSeeds(first, below, listed)
    if train.count < 1:
        raise fail(f"seeds['train'] [{first}, {below}) holds no seed outside the val and test lists")
    return train


def _scenario(entry: Any, index: int, fail: Any) -> Scenario:
    where = f"scenarios[{index}]"
    if not isinstance(entry, dict):
        raise fail(f"{where} must be an object with name, env, env_kwargs")
    name, env_id, kwargs = entry.get("name"), entry.get("env"), entry.get("env_kwargs", {})
    if not isinstance(name, str) or not PLAIN_NAME.fullmatch(name) or "/" in name:
        raise fail(f"{where}.name must be a plain name (letters, digits, _ and -), got {_shown(name)}")
    if isinstance(kwargs, dict) and "predictor" in kwargs:
        raise fail(f"{where} ({name}): env_kwargs must not set the predictor (the benchmark's --predictor does)")
    try:
        check_scenario(env_id, kwargs, f"{where} ({name})")
    except SuiteError as err:
        raise fail(str(err)) from None
    return Scenario(name, env_id, kwargs, str(entry.get("description", "")))
