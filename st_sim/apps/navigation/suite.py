"""The navigation benchmark's suite: named scenarios (an env id and its ``gym.make`` keywords) and published seeds.

    suite = load_suite()                            # the shipped suite (suites/stcrowd-nav-1.0.json)
    seeds = suite.seeds_of("test", episodes=100)    # episode i of every scenario resets with seeds[i]
    env = gym.make(scenario.env, **scenario.env_kwargs)

A suite file is JSON: ``format``, ``name``, ``version``, ``episodes`` (the default per scenario), ``seeds``
(``{"val": [...], "test": [...]}``: a validation list for tuning and a disjoint test list) and ``scenarios``
(``[{"name", "env", "env_kwargs", "description"}]``). Results carry the suite's name and version, so a figure
names the exact episodes it was measured on; a new scenario or seed list is a new version.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import gymnasium as gym

import envs  # noqa: F401  (registers the ids)

SUITE_FORMAT = "stcrowd-nav-suite/1"
SHIPPED_SUITE = "stcrowd-nav-1.0.json"
SPLITS: tuple[str, ...] = ("val", "test")
"""seed lists of a suite: val for tuning, test for the figures you report"""


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


@dataclass(frozen=True)
class Suite:
    """Scenarios and seed lists of one suite version (``load_suite``)."""

    name: str
    version: str
    scenarios: tuple[Scenario, ...]
    seeds: Mapping[str, tuple[int, ...]]
    episodes: int
    """default episodes per scenario"""
    path: Path
    """the file it was read from"""

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
        if split not in self.seeds:
            raise SuiteError(f"suite {self.name} {self.version} has no seed list {split!r}; it has "
                             f"{', '.join(self.seeds)}")
        episodes = self.episodes if episodes is None else episodes
        available = self.seeds[split]
        if not 1 <= episodes <= len(available):
            raise SuiteError(f"{episodes} episodes asked of the {split} seeds of suite {self.name} {self.version}, "
                             f"which holds {len(available)}: ask 1 to {len(available)}")
        return available[:episodes]


def load_suite(path: str | Path | None = None) -> Suite:
    """The suite in ``path`` (None: the shipped one), checked: ``SuiteError`` naming the file and the field at fault
    (unknown env ids, duplicate names, non-JSON keywords, seeds that are not ints >= 0, repeated, or shared by two
    splits)."""
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
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise fail(f"'episodes' must be an int >= 1, got {episodes!r}")
    seeds = raw.get("seeds")
    if not isinstance(seeds, dict) or set(seeds) != set(SPLITS):
        raise fail(f"'seeds' must hold exactly the lists {', '.join(SPLITS)}")
    seen: dict[int, str] = {}
    for split, values in seeds.items():
        if not isinstance(values, list) or not values or any(
                isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in values):
            raise fail(f"seeds[{split!r}] must be a non-empty list of ints >= 0")
        for value in values:
            if value in seen:
                where = "twice in it" if seen[value] == split else f"in {seen[value]!r} too"
                raise fail(f"seed {value} of seeds[{split!r}] is {where}: the lists must be disjoint, without repeats")
            seen[value] = split
    scenarios = raw.get("scenarios")
    if not isinstance(scenarios, list) or not scenarios:
        raise fail("'scenarios' must be a non-empty list")
    parsed = tuple(_scenario(entry, i, fail) for i, entry in enumerate(scenarios))
    names = [scenario.name for scenario in parsed]
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise fail(f"scenario name {repeated[0]!r} is used twice")
    return Suite(raw["name"], raw["version"], parsed, {k: tuple(v) for k, v in seeds.items()}, episodes, path)


def _scenario(entry: Any, index: int, fail: Any) -> Scenario:
    where = f"scenarios[{index}]"
    if not isinstance(entry, dict):
        raise fail(f"{where} must be an object with name, env, env_kwargs")
    name, env_id, kwargs = entry.get("name"), entry.get("env"), entry.get("env_kwargs", {})
    if not isinstance(name, str) or not name or "/" in name:
        raise fail(f"{where}.name must be a non-empty string without '/', got {name!r}")
    if not isinstance(env_id, str) or env_id not in gym.registry:
        raise fail(f"{where} ({name}): env {env_id!r} is not a registered gym id")
    if not isinstance(kwargs, dict):
        raise fail(f"{where} ({name}): env_kwargs must be an object of gym.make keywords")
    if "predictor" in kwargs:
        raise fail(f"{where} ({name}): env_kwargs must not set the predictor (the benchmark's --predictor does)")
    return Scenario(name, env_id, kwargs, str(entry.get("description", "")))
