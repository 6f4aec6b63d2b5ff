"""Device selection (``predictor.devices``) for the predictor's training, the envs' forecasts and PPO: every path on
the CPU here; the GPU path where torch sees a CUDA GPU."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.common.errors import EnvInputError
from predictor import load_pretrained
from predictor.checkpoint import load
from predictor.devices import DEVICE_NAME, DeviceError, check_device_name, resolve_device
from predictor.train import TrainConfig, main
from replays import load_scene, load_windows
from st_sim.apps.navigation import train_ppo

GPU = torch.cuda.is_available()
TINY = {"epochs": 1, "min_steps": 0, "dim": 32, "denoiser_dim": 32, "max_train_windows": 60, "batch_agents": 128,
        "progress": False}


def test_auto_is_a_gpu_when_torch_sees_one_else_the_cpu() -> None:
    assert resolve_device("auto").type == ("cuda" if GPU else "cpu")
    assert resolve_device("cpu") == torch.device("cpu") == resolve_device(torch.device("cpu"))


@settings(max_examples=60, deadline=None)
@given(name=st.one_of(st.text(max_size=12), st.integers(), st.none(), st.floats()))
def test_a_name_that_is_no_device_is_refused_naming_it(name) -> None:
    if isinstance(name, str) and DEVICE_NAME.fullmatch(name):
        assert check_device_name(name) == name
        return
    with pytest.raises(DeviceError, match="device=") as err:
        resolve_device(name)
    assert "expected auto" in str(err.value)


@pytest.mark.skipif(GPU, reason="the refusal of a missing GPU needs a machine without one")
@pytest.mark.parametrize("name", ["cuda", "cuda:0", "cuda:3"])
def test_a_gpu_torch_cannot_see_is_refused_with_the_reason(name: str) -> None:
    with pytest.raises(DeviceError, match="sees no CUDA GPU"):
        resolve_device(name)
    with pytest.raises(EnvInputError, match="sees no CUDA GPU"):
        gym.make("STCrowd-SimCrossing-v1", device=name)
    with pytest.raises(SystemExit):
        train_ppo.parse_args(["--device", name])


@pytest.mark.parametrize("device", ["cpu", "auto"])
def test_envs_forecast_on_the_device_they_are_given(device: str) -> None:
    env = gym.make("STCrowd-SimCrossing-v1", device=device)
    assert env.unwrapped.predictor.device == resolve_device(device)
    obs, _ = env.reset(seed=0)
    for _ in range(8):
        obs, *_ = env.step(np.zeros(2, np.float32))
    assert obs["futures_mask"].any() and np.isfinite(obs["futures"]).all()


def test_the_predictor_trains_on_the_device_it_is_given(tmp_path: Path) -> None:
    best = main(TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path), device="cpu", **TINY))
    assert load(best).device == torch.device("cpu")  # a checkpoint loads on the CPU whatever it trained on


def test_train_ppo_reads_its_device() -> None:
    assert train_ppo.parse_args([]).device == "auto"
    assert train_ppo.parse_args(["--device", "cpu"]).device == "cpu"


@pytest.mark.skipif(not GPU, reason="runs wherever torch sees a CUDA GPU")
def test_the_gpu_path_forecasts_trains_and_steps_as_the_cpu_does(tmp_path: Path) -> None:
    test = load_windows("stochastic", "univ", "test")
    test = test.subset(test.group < 8)
    univ = load_scene("univ")
    on_cpu = load_pretrained("stochastic/univ").predict(test.obs, test.group, univ, 20)
    on_gpu = load_pretrained("stochastic/univ").to("cuda").predict(test.obs, test.group, univ, 20)
    np.testing.assert_allclose(on_gpu, on_cpu, rtol=0, atol=1e-3)
    best = main(TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path / "refiner"), device="cuda", **TINY))
    assert load(best).predict(test.obs, test.group, univ, 20).shape == on_cpu.shape
    train_ppo.main(train_ppo.parse_args(["--timesteps", "64", "--num-envs", "2", "--n-steps", "32", "--device",
                                         "cuda", "--quiet", "--out", str(tmp_path / "ppo")]))
    assert (tmp_path / "ppo" / "policy.pt").is_file()
