"""What the PPO trainer is paid for and where it trains (issue 75): the ``benchmark`` recipe's charges (a collision
by the fault rule, a timeout), and the sub-envs shared among the training envs by their failure rates."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.common.errors import EnvInputError
from st_sim.apps.navigation.failure_sampling import FailureTally, allocate
from st_sim.apps.navigation.fault_constraint import FaultConstraint
from st_sim.apps.navigation.features import FeatureConfig
from st_sim.apps.navigation.train_ppo import RECIPES, cli, main, parse_args
from st_sim.apps.navigation.training_envs import FeatureVecEnv

RATES = st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20)


@settings(max_examples=200, deadline=None)
@given(rates=RATES, spare=st.integers(0, 200), floor=st.integers(0, 3))
def test_allocation_is_whole_keeps_the_floor_and_follows_the_failure_rates(rates: list[float], spare: int,
                                                                           floor: int) -> None:
    num_envs = floor * len(rates) + spare
    counts = allocate(rates, num_envs, floor)
    assert sum(counts) == num_envs and all(type(c) is int and c >= floor for c in counts), counts
    for i, j in np.ndindex(len(rates), len(rates)):
        if rates[i] > rates[j]:
            assert counts[i] >= counts[j], f"scenario {i} fails more often than {j} and got fewer sub-envs: {counts}"
    share = np.asarray(rates) / sum(rates) if sum(rates) > 0 else np.full(len(rates), 1 / len(rates))
    assert np.all(np.abs(np.asarray(counts) - floor - spare * share) < 1.0), "each within one of its quota"


@settings(max_examples=50, deadline=None)
@given(rate=st.floats(0.0, 1.0), k=st.integers(1, 20), spare=st.integers(0, 100))
def test_equal_failure_rates_share_the_sub_envs_evenly(rate: float, k: int, spare: int) -> None:
    counts = allocate([rate] * k, k + spare)
    assert max(counts) - min(counts) <= 1 and counts == sorted(counts, reverse=True), counts


@pytest.mark.parametrize(("rates", "num_envs", "match"), [
    ([], 4, "one rate per scenario"), ([[0.5]], 4, "one rate per scenario"), ([0.5, 1.5], 4, r"rates in \[0, 1\]"),
    ([0.5, float("nan")], 4, r"rates in \[0, 1\]"), ([-0.1], 4, r"rates in \[0, 1\]"),
    ([0.5, 0.5, 0.5], 2, "fewer than floor=1 sub-envs for each of 3"),
])
def test_bad_allocations_are_refused(rates: list, num_envs: int, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        allocate(rates, num_envs)


def test_the_tally_smooths_towards_one_half_and_counts_only_its_window() -> None:
    tally = FailureTally(["a", "b", "c"])
    for failed in (True, True, False):
        tally.add("a", failed)
    tally.add("b", False)
    assert tally.failure_rates() == [3 / 5, 1 / 3, 1 / 2], "(failures + 1) / (episodes + 2); none seen: 1/2"
    assert tally.as_dict()["a"] == {"episodes": 3, "failures": 2}
    with pytest.raises(KeyError):
        tally.add("d", True)
    tally.clear()
    assert tally.failure_rates() == [0.5, 0.5, 0.5]


def test_sub_envs_follow_the_counts_and_bad_counts_are_refused() -> None:
    ids = ["STCrowd-SimCorridor-v1", "STCrowd-Hotel-v0:log"]
    vec = FeatureVecEnv(ids, 4, FeatureConfig(False), counts=[1, 3])
    assert vec.env_of == (ids[0], ids[1], ids[1], ids[1])
    assert vec.get_attr("pedestrians", [1, 2, 3]) == ["log"] * 3
    vec.close()
    for counts in ([2, 1], [0, 4], [4], [1, 2, 1], [True, 3], [1.0, 3]):
        with pytest.raises(EnvInputError, match=r"counts=.*ints >= 1 summing to num_envs=4"):
            FeatureVecEnv(ids, 4, FeatureConfig(False), counts=counts)
    with pytest.raises(EnvInputError, match="timeout_reward"):
        FeatureVecEnv(ids, 4, FeatureConfig(False), timeout_reward=float("nan"))


def rewards_and_ends(env_ids: list[str], seed: int, action: np.ndarray, steps: int, flag: str, kwargs: dict,
                     charge_from: tuple[int, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Four sub-envs of ``env_ids`` (no forecasts, ``FeatureVecEnv(**kwargs)``) stepped ``steps`` times with the
    path-frame ``action``: (steps, 4) rewards, and whether each step ended an episode with ``info[flag]`` true.
    ``charge_from`` (step, charge): ``set_fault_charge(charge)`` before that step."""
    vec = FeatureVecEnv(env_ids, 4, FeatureConfig(False), **kwargs)
    vec.seed(seed)
    vec.reset()
    rewards, ends = [], []
    for t in range(steps):
        if charge_from is not None and t == charge_from[0]:
            vec.set_fault_charge(charge_from[1])
        vec.step_async(np.tile(np.asarray(action, np.float32), (4, 1)))
        _, reward, dones, infos = vec.step_wait()
        rewards.append(reward)
        ends.append([bool(d and info[flag]) for d, info in zip(dones, infos, strict=True)])
    vec.close()
    return np.array(rewards), np.array(ends)


def test_a_timeout_is_charged_on_its_step_and_nowhere_else() -> None:
    """The same sub-envs and actions with and without a timeout charge: the rewards differ by the charge exactly on
    the steps that ended an episode by the time limit or the recording's end (``TimeLimit.truncated``)."""
    charge, steps = -7.0, 230
    # standing still: walkers may run in (a collision), else the episode times out
    free, timeouts = rewards_and_ends(["STCrowd-Hotel-v0:log", "STCrowd-SimCorridor-v1"], 5, np.zeros(2), steps,
                                      "TimeLimit.truncated", {})
    charged, same_timeouts = rewards_and_ends(["STCrowd-Hotel-v0:log", "STCrowd-SimCorridor-v1"], 5, np.zeros(2),
                                              steps, "TimeLimit.truncated", {"timeout_reward": charge})
    np.testing.assert_array_equal(timeouts, same_timeouts)
    assert timeouts.sum() >= 2, "a robot standing for 230 steps timed out"
    np.testing.assert_array_equal(charged - free, np.where(timeouts, np.float32(charge), np.float32(0.0)))


def test_the_recipes_set_the_reward_and_the_old_one_stays_the_default() -> None:
    old, new = parse_args([]), parse_args(["--recipe", "benchmark"])
    assert (old.reward, old.timeout_reward) == RECIPES["crowdnav"]
    assert (old.reward.collision, old.reward.discomfort, old.reward.at_fault) == (-20.0, -4.0, 0.0)
    assert (new.reward, new.timeout_reward) == RECIPES["benchmark"]
    assert new.reward.at_fault < 0 and new.timeout_reward < 0, "the fault rule's collisions and timeouts cost"
    assert parse_args(["--recipe", "benchmark", "--prediction-reward", "-2"]).reward.prediction == -2.0


@pytest.mark.parametrize(("argv", "match"), [
    (["--sampling", "failures"], "shares the sub-envs among several training envs"),
    (["--sampling", "failures", "--env-ids", "STCrowd-SimCorridor-v1", "STCrowd-SimCrossing-v1", "--num-envs", "1"],
     "leaves some of the 2 training envs without a sub-env"),
    (["--resample-every", "0"], "--resample-every=0: expected an integer >= 1"),
    (["--recipe", "gentle"], "invalid choice"),
])
def test_bad_sampling_flags_are_refused(argv: list[str], match: str, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        parse_args(argv)
    assert match in capsys.readouterr().err


def run_args(out: Path) -> list[str]:
    """A tiny failure-sampled run: three training envs, six sub-envs, a reallocation after every rollout."""
    return ["--no-predictions", "--env-ids", "STCrowd-SimCorridor-v1", "STCrowd-Hotel-v0:log",
            "STCrowd-SimBottleneck-v1", "--num-envs", "6", "--shards", "1", "--n-steps", "16", "--batch-size", "32",
            "--sampling", "failures", "--resample-every", "1", "--recipe", "benchmark", "--save-every", "1",
            "--quiet", "--out", str(out)]


def test_failure_sampling_reallocates_by_each_windows_failures_and_resumes_from_its_last_round(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Each round's counts are ``allocate`` of the window it tallied; a resumed run starts from the last round's
    counts and goes on adding rounds; a damaged ``sampling.json`` is one error line naming it."""
    out = tmp_path / "run"
    main(parse_args([*run_args(out), "--timesteps", "192"]))  # two rollouts of 6 x 16
    rounds = json.loads((out / "sampling.json").read_text())
    assert [r["timesteps"] for r in rounds] == [96, 192]
    for r in rounds:
        tally = FailureTally(list(r["tally"]))
        tally.episodes = {k: v["episodes"] for k, v in r["tally"].items()}
        tally.failures = {k: v["failures"] for k, v in r["tally"].items()}
        assert r["counts"] == allocate(tally.failure_rates(), 6), r
    assert sum(v["episodes"] for r in rounds for v in r["tally"].values()) > 0, "episodes ended and were tallied"
    record = json.loads((out / "training.json").read_text())
    assert record["sampling"]["counts"] == rounds[-1]["counts"] and record["sampling"]["rounds"] == 2

    main(parse_args([*run_args(out), "--timesteps", "288"]))
    resumed = json.loads((out / "sampling.json").read_text())
    assert resumed[:2] == rounds and [r["timesteps"] for r in resumed[2:]] == [288]

    for damage in ("{", "[]x", json.dumps([{"counts": [2, 2]}]), json.dumps([{"counts": [2, 2, True]}]),
                   json.dumps([{"counts": [1, 1, 1]}]), json.dumps({"counts": [2, 2, 2]})):
        (out / "sampling.json").write_text(damage)
        assert cli([*run_args(out), "--timesteps", "384"]) == 1
        assert "sampling.json" in capsys.readouterr().err.splitlines()[-1]


def test_a_shipped_policy_records_the_steps_it_learnt_not_its_budget(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A run cut short by ``--minutes`` learnt fewer steps than its ``--timesteps``: the manifest holds what it learnt
    (``final_training``), the file's SHA-256 and the policy it started from, never the budget."""
    from st_sim.apps.navigation import train_ppo
    from st_sim.apps.navigation.ppo import PRETRAINED_DIR

    out = tmp_path / "run"
    main(parse_args([*run_args(out), "--timesteps", "96"]))
    record = json.loads((out / "training.json").read_text())
    record["config"]["timesteps"] = 20_000_000
    (tmp_path / "package").mkdir()
    monkeypatch.setattr(train_ppo.resources, "files", lambda package: tmp_path / "package")
    target = train_ppo.ship(out / "policy.pt", "mine", record)
    entry = json.loads((tmp_path / "package" / PRETRAINED_DIR / "manifest.json").read_text())["policies"]["mine"]
    assert target.read_bytes() == (out / "policy.pt").read_bytes() and entry["sha256"] == record["sha256"]
    assert entry["final_training"]["timesteps"] == 96 and 20_000_000 not in entry.values()
    assert entry["init_policy_sha256"] == record["init_policy_sha256"] and entry["file"] == "mine.pt"


@settings(max_examples=200, deadline=None)
@given(target=st.floats(0.0, 0.99), step=st.floats(0.01, 1e4), start=st.floats(0.0, 1e4),
       episodes=st.integers(0, 500), share=st.floats(0.0, 1.0))
def test_the_fault_multiplier_rises_above_its_target_falls_below_and_stays_non_negative(
        target: float, step: float, start: float, episodes: int, share: float) -> None:
    at_fault = round(share * episodes)
    constraint = FaultConstraint(target, step, start)
    after = constraint.update(episodes, at_fault)
    assert after == constraint.multiplier >= 0.0
    if episodes == 0:
        assert after == start, "no ended episode moves nothing"
    elif at_fault / episodes > target:
        assert after >= start
    else:
        moved = start + step * (at_fault / episodes - target)
        assert after <= start and (after == 0.0 or after == pytest.approx(moved))


@pytest.mark.parametrize(("target", "step", "multiplier"), [
    (1.0, 1.0, 0.0), (-0.1, 1.0, 0.0), (float("nan"), 1.0, 0.0), (0.1, 0.0, 0.0), (0.1, float("inf"), 0.0),
    (0.1, 1.0, -1.0), (0.1, 1.0, float("nan")),
])
def test_a_bad_constraint_is_refused(target: float, step: float, multiplier: float) -> None:
    with pytest.raises(ValueError, match="FaultConstraint"):
        FaultConstraint(target, step, multiplier)
    with pytest.raises(ValueError, match="at_fault=3 of episodes=2"):
        FaultConstraint(0.1, 1.0, 0.0).update(2, 3)


def test_the_fault_charge_is_paid_on_at_fault_collisions_only_and_moves_when_set() -> None:
    """The same sub-envs and actions (full speed along the path, into whoever is there) with no charge and with
    one that changes half-way: the rewards differ by the charge in force exactly on the steps that ended in a
    collision the fault rule put on the robot."""
    steps, env_ids = 160, ["STCrowd-SimCrossing-v1", "STCrowd-Hotel-v0:log"]
    free, at_fault = rewards_and_ends(env_ids, 2, np.array([1.0, 0.0]), steps, "at_fault", {"fault_charge": 0.0},
                                      (steps // 2, 0.0))
    charged, same = rewards_and_ends(env_ids, 2, np.array([1.0, 0.0]), steps, "at_fault", {"fault_charge": 3.0},
                                     (steps // 2, 11.0))
    np.testing.assert_array_equal(at_fault, same)
    assert at_fault[:steps // 2].any() and at_fault[steps // 2:].any(), "collisions at fault in both halves"
    charge = np.where(np.arange(steps) < steps // 2, 3.0, 11.0)[:, None]
    np.testing.assert_allclose(free - charged, np.where(at_fault, charge, 0.0), rtol=0, atol=1e-5)
    for bad in (-1.0, float("nan"), float("inf"), True, "1"):
        with pytest.raises(EnvInputError, match="fault_charge"):
            FeatureVecEnv(["STCrowd-SimCorridor-v1"], 1, FeatureConfig(False), fault_charge=bad)


def test_a_constrained_run_moves_its_multiplier_by_each_rollout_and_resumes_from_it(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Every rollout's update is the rule applied to that rollout's episodes, from the recipe's at-fault weight; a
    resumed run continues from the last multiplier; a damaged ``constraint.json`` is one error line naming it."""
    out = tmp_path / "run"
    args = [*run_args(out), "--fault-target", "0.05", "--fault-step", "40"]
    main(parse_args([*args, "--timesteps", "192"]))
    updates = json.loads((out / "constraint.json").read_text())
    assert [u["timesteps"] for u in updates] == [96, 192]
    before = -RECIPES["benchmark"][0].at_fault
    for u in updates:
        rate = u["at_fault"] / u["episodes"] if u["episodes"] else 0.05
        assert u["multiplier"] == pytest.approx(max(0.0, before + 40 * (rate - 0.05))), updates
        before = u["multiplier"]
    assert sum(u["episodes"] for u in updates) > 0
    main(parse_args([*args, "--timesteps", "288"]))
    resumed = json.loads((out / "constraint.json").read_text())
    assert resumed[:2] == updates and len(resumed) == 3
    rate = resumed[2]["at_fault"] / resumed[2]["episodes"] if resumed[2]["episodes"] else 0.05
    assert resumed[2]["multiplier"] == pytest.approx(max(0.0, before + 40 * (rate - 0.05)))
    for damage in ("{", json.dumps({"multiplier": 1}), json.dumps([{"multiplier": -2}]),
                   json.dumps([{"multiplier": "x"}])):
        (out / "constraint.json").write_text(damage)
        assert cli([*args, "--timesteps", "384"]) == 1
        assert "constraint.json" in capsys.readouterr().err.splitlines()[-1]
