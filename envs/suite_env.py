"""The navigation suite as one env: a scenario drawn per episode, every one seen through the same fixed-size view."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from numbers import Real
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from envs.common.errors import EnvInputError, NeedsResetError, ResetOptionsError
from envs.common.predictors import task_sizes
from envs.suite import Scenario, SuiteError, load_suite, make_scenario_env
from envs.view import NEAREST, RAY_COUNT, FixedView, check_view_sizes, view_space
from replays.constants import STEP_S
from st_sim.perception import SensingSpec, SensingSpecError, sensing_spec
from st_sim.sim.robot import RobotSpec, RobotSpecError, robot_spec

WHERE = "STCrowd-Suite-v1"


class SuiteEnv(gym.Env):
    """The scenarios of the navigation suite (``envs.suite``), one drawn per episode, seen through ``envs.view``.

    ## Description
    Each ``reset`` draws a scenario (with probability proportional to its weight) and a seed of the split
    (``Suite.draw_seed``: a train seed is never a val or test seed), both from ``np_random``, and resets that
    scenario's env with that seed. A scenario's env is the benchmark's (``make_scenario_env``: its id and keywords,
    with this env's predictor), behind ``FixedView``; it is made the first time the scenario is drawn and kept.

    ## Observation Space
    The fixed-size view (``envs.view``: robot, walls, people, people_mask, futures, futures_mask; float32, metres,
    the robot's frame) with K = ``nearest`` pedestrians, R = ``rays`` wall readings, T_obs = 8 and S = 20: the same
    space for every scenario.

    ## Action Space
    The robot's (``robot``: "holonomic" (default), "diff-drive" or a ``st_sim.sim.robot.RobotSpec``, the same in every
    scenario). Holonomic: Box(-1.5, 1.5, (2,), float32), the robot's velocity [m/s] in its frame (x along the shortest
    walkable path to the goal, y to its left), scaled down to 1.5 m/s if faster. Differential drive: (v [m/s], w
    [rad/s]) as the scenario env takes it.

    ## Rewards
    The scenario env's (``ReplayCrowdEnv``, ``SimCrowdEnv``).

    ## Starting State
    The scenario env's, reset with the drawn seed.

    ## Episode End
    The scenario env's: terminated at the goal or on a collision; truncated by its registered time limit (200 steps)
    or at the end of a replay's recording.

    ## Info
    The scenario env's (its per-row arrays on the view's rows, ``envs.view.ROW_INFO_KEYS``), plus ``scenario`` (its
    name) and ``scenario_seed`` (the seed its env was reset with: ``make_scenario_env(scenario, predictor)`` reset
    with that seed starts the same episode).

    ## Reset Options
    ``{"scenario": NAME}``: reset that scenario (one of this env's) instead of drawing one; the seed is drawn as ever.
    None or ``{}``: draw one.

    ## Arguments
    split ("train" (default), "val" or "test": whose seeds the episodes take), scenarios (names of the suite's
    scenarios; None (default): all), weights (one number >= 0 per scenario, not all 0; None: equal), predictor
    (as the crowd envs', "auto" by default; "cvm" or "none" train fastest), nearest (K, 8), rays (R, 16),
    suite_file (a suite file; None: the shipped one), root (ETH/UCY data root for the replays), device (as the crowd
    envs'), render_mode (None or "rgb_array": the scenario env's picture), robot and sensing (as the crowd envs': the
    robot and what it senses, the same in every scenario).

    ## Version History
    - v1: first version, over suite stcrowd-nav 1.0 (its scenarios' envs are the v0 replays and v1 simulated crowds).
      2026-12-02, same id: ``robot=`` and ``sensing=``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": round(1 / STEP_S, 1)}

    def __init__(self, split: str = "train", scenarios: Sequence[str] | None = None,
                 weights: Sequence[float] | None = None, predictor: Any = "auto", nearest: int = NEAREST,
                 rays: int = RAY_COUNT, suite_file: str | os.PathLike | None = None,
                 root: str | os.PathLike | None = None, device: str = "auto", render_mode: str | None = None,
                 robot: str | RobotSpec | None = None, sensing: str | SensingSpec | None = None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise EnvInputError(f"{WHERE}: render_mode={render_mode!r}: expected None or 'rgb_array'")
        check_view_sizes(nearest, rays, WHERE)
        try:
            self.suite = load_suite(suite_file)
            self.suite.check_split(split)
        except SuiteError as err:
            raise EnvInputError(f"{WHERE}: {err}") from None
        self.split, self.render_mode = split, render_mode
        self.scenarios = self._scenarios(scenarios)
        self.probabilities = self._probabilities(weights)
        try:
            self.robot = robot_spec(robot)
            """the robot of every scenario (``st_sim.sim.robot.RobotSpec``)"""
            self.sensing = sensing_spec(sensing)
            """what the robot senses in every scenario (``st_sim.perception.SensingSpec``)"""
        except (RobotSpecError, SensingSpecError) as err:
            raise EnvInputError(f"{WHERE}: {err}") from None
        self._make_kwargs = {"predictor": predictor, "data_root": None if root is None else os.fspath(root),
                             "device": device, "render_mode": render_mode, "robot": self.robot,
                             "sensing": self.sensing}
        self._view_sizes = (int(nearest), int(rays))
        self.observation_space = view_space(*self._view_sizes, *task_sizes("stochastic"),
                                            turning=self.robot.kind == "diff-drive")
        self.action_space = gym.spaces.Box(self.robot.command_low.astype(np.float32),
                                           self.robot.command_high.astype(np.float32), dtype=np.float32)
        self._envs: dict[str, FixedView] = {}  # scenario name -> its env, made on first draw
        self._current: tuple[Scenario, int] | None = None  # the episode's scenario and seed

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        chosen = self._chosen(options)
        if seed is not None and (isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer)
                                 or seed < 0):
            raise EnvInputError(f"{WHERE}: seed={seed!r}: expected None or an int >= 0")
        super().reset(seed=None if seed is None else int(seed))
        if chosen is None:
            chosen = self.scenarios[int(self.np_random.choice(len(self.scenarios), p=self.probabilities))]
        scenario_seed = self.suite.draw_seed(self.split, self.np_random)
        self._current = None
        obs, info = self._env(chosen).reset(seed=scenario_seed)
        self._current = (chosen, scenario_seed)
        return obs, self._info(info)

    def step(self, action: Any):
        if self._current is None:
            raise NeedsResetError(f"{WHERE}: call reset() before step()")
        obs, reward, terminated, truncated, info = self._envs[self._current[0].name].step(action)
        return obs, reward, terminated, truncated, self._info(info)

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        if self._current is None:
            raise NeedsResetError(f"{WHERE}: call reset() before render()")
        return self._envs[self._current[0].name].render()

    def close(self) -> None:
        for env in self._envs.values():
            env.close()

    # helpers -----------------------------------------------------------------------------------------

    def _scenarios(self, names: Any) -> tuple[Scenario, ...]:
        """The scenarios called ``names``, in the order given (None: the whole suite); ``EnvInputError`` for a name
        the suite lacks, a repeated one, an empty list or a bare string."""
        if names is None:
            return self.suite.scenarios
        if isinstance(names, str) or not isinstance(names, Sequence) or not names:
            raise EnvInputError(f"{WHERE}: scenarios={names!r}: expected None or a non-empty list of scenario names")
        repeated = sorted({name for name in names if list(names).count(name) > 1}, key=str)
        if repeated:
            raise EnvInputError(f"{WHERE}: scenarios: {repeated[0]!r} is named twice")
        try:
            by_name = {scenario.name: scenario for scenario in self.suite.select(list(names))}
        except SuiteError as err:
            raise EnvInputError(f"{WHERE}: {err}") from None
        return tuple(by_name[name] for name in names)

    def _probabilities(self, weights: Any) -> np.ndarray:
        """(number of scenarios,) float64 drawing probabilities from ``weights`` (None: equal)."""
        count = len(self.scenarios)
        if weights is None:
            return np.full(count, 1.0 / count)
        numbers = isinstance(weights, Sequence | np.ndarray) and not isinstance(weights, str | bytes) and all(
            isinstance(w, Real) and not isinstance(w, bool | np.bool_) for w in weights)
        if not numbers:
            raise EnvInputError(f"{WHERE}: weights={weights!r}: expected None or {count} numbers >= 0, one per "
                                "scenario")
        values = [float(w) for w in weights]
        if len(values) != count:
            raise EnvInputError(f"{WHERE}: weights has {len(values)} numbers for {count} scenarios "
                                f"({', '.join(s.name for s in self.scenarios)}): give one per scenario")
        if not all(math.isfinite(w) and w >= 0 for w in values) or sum(values) <= 0:
            raise EnvInputError(f"{WHERE}: weights={values}: expected finite numbers >= 0, not all 0")
        return np.asarray(values) / sum(values)

    def _chosen(self, options: Any) -> Scenario | None:
        """The scenario ``options`` names (None or {}: draw one); ``ResetOptionsError`` for any other option."""
        if options is None or options == {}:
            return None
        if not isinstance(options, dict) or set(options) != {"scenario"}:
            raise ResetOptionsError(f"{WHERE}: reset options must be None or {{'scenario': NAME}}, got {options!r}")
        for scenario in self.scenarios:
            if scenario.name == options["scenario"]:
                return scenario
        raise ResetOptionsError(f"{WHERE}: reset option scenario={options['scenario']!r} is not one of this env's "
                                f"scenarios ({', '.join(s.name for s in self.scenarios)})")

    def _env(self, scenario: Scenario) -> FixedView:
        """The scenario's env behind the view, made on first use; ``EnvInputError`` if its spaces are not this
        env's."""
        if scenario.name not in self._envs:
            kwargs = dict(self._make_kwargs)
            env = FixedView(make_scenario_env(scenario, kwargs.pop("predictor"), kwargs.pop("data_root"), **kwargs),
                            *self._view_sizes)
            if env.observation_space != self.observation_space or env.action_space != self.action_space:
                env.close()
                raise EnvInputError(f"{WHERE}: scenario {scenario.name!r} ({scenario.env}, {scenario.env_kwargs}) "
                                    f"gives {env.observation_space} and actions {env.action_space}, not this env's "
                                    f"{self.observation_space} and {self.action_space}")
            self._envs[scenario.name] = env
        return self._envs[scenario.name]

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        scenario, seed = self._current
        return {**info, "scenario": scenario.name, "scenario_seed": seed}
