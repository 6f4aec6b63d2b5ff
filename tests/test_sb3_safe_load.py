"""``sb3:`` model files are read without running anything stored in them (``sb3_zip``): a pickle in any field SB3
would unpickle never runs, a zip bomb, a truncated zip or weights of the wrong shapes are refused with one line
naming the file, and a plain PPO/A2C/SAC/TD3/DDPG model acts exactly as SB3's own loader makes it act;
``--trust-policy-file`` is the opt-in to SB3's own loader."""

from __future__ import annotations

import base64
import io
import json
import pickle
import struct
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sb3_files import ACTIONS, ENV, KEYS, data_of, make_env, outcome, rewrite, with_data
from stable_baselines3.common.policies import MultiInputActorCriticPolicy

import envs  # noqa: F401  (registers the ids)
from st_sim.apps.cli import main
from st_sim.apps.navigation.policies import PolicyError, load_policy
from st_sim.apps.navigation.sb3_zip import Sb3ZipError, load_sb3_zip
from st_sim.apps.navigation.world import world_of

TRAIN_STEPS = 64  # env steps of training per model [-]
OFF_POLICY = {"learning_starts": 16, "batch_size": 16, "buffer_size": 1000}
KINDS: dict[str, tuple[str, str, dict[str, Any]]] = {
    "ppo-multi": ("PPO", "MultiInputPolicy", {"n_steps": 32, "batch_size": 32}),
    "ppo-mlp": ("PPO", "MlpPolicy", {"n_steps": 32, "batch_size": 32}),
    "sac-multi": ("SAC", "MultiInputPolicy", OFF_POLICY),
    "sac-mlp": ("SAC", "MlpPolicy", OFF_POLICY),
    "td3-multi": ("TD3", "MultiInputPolicy", OFF_POLICY),
    "td3-mlp": ("TD3", "MlpPolicy", OFF_POLICY),
    "a2c-multi": ("A2C", "MultiInputPolicy", {"n_steps": 8}),  # its policy_kwargs hold a class: pickled
    "ddpg-mlp": ("DDPG", "MlpPolicy", {**OFF_POLICY, "policy_kwargs": {"net_arch": [64, 64]}}),
    "ppo-relu": ("PPO", "MultiInputPolicy", {"n_steps": 32, "batch_size": 32, "use_sde": True, "policy_kwargs": {
        "activation_fn": torch.nn.ReLU, "net_arch": {"pi": [32, 32], "vf": [16]}, "log_std_init": -1.0}}),
    "sac-sde": ("SAC", "MlpPolicy", {**OFF_POLICY, "use_sde": True, "policy_kwargs": {
        "activation_fn": torch.nn.Tanh, "net_arch": [32], "n_critics": 3}}),
}
"""model files the tests train: algorithm, policy, keywords"""
HOSTILE = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


class Payload:
    """What a hostile model file carries: unpickled, it writes ``marker``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return exec, (f"open({str(self.marker)!r}, 'w').write('ran')",)


class CustomPolicy(MultiInputActorCriticPolicy):
    """A policy class of the user's own: only SB3's loader (--trust-policy-file) builds it."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)


@pytest.fixture(scope="module")
def zips(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Every kind of ``KINDS`` trained ``TRAIN_STEPS`` steps and saved."""
    import stable_baselines3

    folder = tmp_path_factory.mktemp("models")
    saved = {}
    for kind, (algorithm, policy, keywords) in KINDS.items():
        model = getattr(stable_baselines3, algorithm)(policy, make_env(policy), seed=0, device="cpu", **keywords)
        model.learn(TRAIN_STEPS)
        saved[kind] = folder / f"{kind}.zip"
        model.save(saved[kind])
    return saved


@pytest.fixture(scope="module")
def observations() -> dict[str, list[Any]]:
    """Observations, Dict and flattened: along random walks, and drawn from the spaces at random."""
    env = make_env("MultiInputPolicy")
    flat = gym.wrappers.FlattenObservation(make_env("MultiInputPolicy")).observation_space
    env.action_space.seed(0)
    env.observation_space.seed(0)
    seen = []
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        for _ in range(20):
            seen.append(obs)
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                break
    seen += [env.observation_space.sample() for _ in range(20)]
    return {"dict": seen, "flat": [gym.spaces.flatten(env.observation_space, obs).astype(flat.dtype) for obs in seen]}


def sb3_load(kind: str, path: Path) -> Any:
    import stable_baselines3

    return getattr(stable_baselines3, KINDS[kind][0]).load(path, device="cpu")


def pickled(marker: Path) -> str:
    """A payload as SB3 stores a pickled field (base64)."""
    return base64.b64encode(pickle.dumps(Payload(marker))).decode()


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_plain_model_acts_exactly_as_sb3s_own_loader_makes_it_act(kind: str, zips: dict[str, Path],
                                                                     observations: dict[str, list[Any]]) -> None:
    ours, theirs = load_sb3_zip(zips[kind], ACTIONS), sb3_load(kind, zips[kind])
    assert type(ours) is type(theirs.policy)
    for obs in observations["flat" if KINDS[kind][1] == "MlpPolicy" else "dict"]:
        expected, _ = theirs.predict(obs, deterministic=True)
        actual, _ = ours.predict(obs, deterministic=True)
        assert np.array_equal(actual, expected), (kind, actual, expected)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.sampled_from([1e-3, 1.0, 1e3]))
def test_the_env_facing_policy_acts_as_sb3s_loader_on_any_observation(benchmark_loaded, seed: int,
                                                                      scale: float) -> None:
    checked, theirs, env_space = benchmark_loaded
    rng = np.random.default_rng(seed)
    obs = {key: (rng.normal(size=space.shape) * scale).astype(space.dtype) if space.dtype != bool
           else rng.random(space.shape) < 0.5 for key, space in env_space.spaces.items()}
    expected, _ = theirs.predict({key: obs[key] for key in KEYS}, deterministic=True)
    assert np.array_equal(checked.act(obs), np.asarray(expected, np.float32))


@pytest.fixture(scope="module")
def benchmark_loaded(zips: dict[str, Path]) -> tuple[Any, Any, gym.spaces.Dict]:
    """The PPO MultiInputPolicy as the benchmark loads it (``sb3:``), SB3's own, and the env's whole space."""
    env = gym.make(ENV, predictor="none")
    checked = load_policy(f"sb3:{zips['ppo-multi']}", world_of(env))
    checked.check_fits(env.observation_space, "frontal-approach")
    return checked, sb3_load("ppo-multi", zips["ppo-multi"]), env.observation_space


@pytest.mark.parametrize("kind", ["ppo-multi", "a2c-multi", "sac-sde", "ddpg-mlp"])
def test_a_payload_in_any_field_sb3_would_unpickle_never_runs(kind: str, zips: dict[str, Path],
                                                            tmp_path: Path) -> None:
    from stable_baselines3.common.save_util import json_to_data

    marker = tmp_path / "ran"
    data = data_of(zips[kind])
    read = {"policy_class", "observation_space", "action_space", "policy_kwargs"} | (
        {"use_sde"} if kind.startswith(("ppo", "a2c")) else set())
    for key, value in data.items():
        whole = {**data, key: {":type:": "<class 'object'>", ":serialized:": pickled(marker)}}
        json_to_data(json.dumps(whole))  # what SB3's load does with the file's data
        assert marker.exists(), f"{key}: SB3's loader would run the payload"
        marker.unlink()
        message = outcome(with_data(zips[kind], tmp_path / "whole.zip", whole))
        assert not marker.exists(), f"{key}: the payload ran"
        assert (message != "loaded") == (key in read), (key, message)
        if isinstance(value, dict) and ":serialized:" in value:  # the plain text kept, the pickle replaced
            beside = {**data, key: {**value, ":serialized:": pickled(marker)}}
            assert outcome(with_data(zips[kind], tmp_path / "beside.zip", beside)) == "loaded", key
            assert not marker.exists(), f"{key}: the payload ran"


@pytest.mark.parametrize(("member", "legacy"), [("policy.pth", False), ("policy.pth", True),
                                                ("pytorch_variables.pth", False), ("policy.optimizer.pth", False)])
def test_a_payload_in_a_torch_file_never_runs(member: str, legacy: bool, zips: dict[str, Path],
                                             tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    buffer = io.BytesIO()
    torch.save({"weight": Payload(marker)}, buffer, _use_new_zipfile_serialization=not legacy)
    torch.load(io.BytesIO(buffer.getvalue()), weights_only=False)
    assert marker.exists(), "the payload is live"
    marker.unlink()
    message = outcome(rewrite(zips["ppo-multi"], tmp_path / "m.zip", {member: buffer.getvalue()}))
    assert not marker.exists()
    if legacy:
        assert "policy.pth is not a torch file in its zip format" in message
    elif member == "policy.pth":
        assert "policy.pth is not plain weights: torch.load(weights_only=True) refuses it" in message
        assert "exec" in message, "names what it refused"
    else:
        assert message == "loaded", "a file not needed to act is never read"


def declared(path: Path, member: str, size_bytes: int) -> Path:
    """``path`` with the central directory stating ``size_bytes`` for ``member``."""
    raw = bytearray(path.read_bytes())
    at = 0
    while (at := raw.find(b"PK\x01\x02", at + 1)) >= 0:
        name_bytes = struct.unpack_from("<H", raw, at + 28)[0]
        if raw[at + 46:at + 46 + name_bytes] == member.encode():
            struct.pack_into("<I", raw, at + 24, size_bytes)
    path.write_bytes(bytes(raw))
    return path


def deflated(members: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, content in members.items():
            archive.writestr(name, content)
    return buffer.getvalue()


@pytest.mark.parametrize("bomb", ["data-expands", "weights-declare", "torch-record-expands"])
def test_a_zip_bomb_is_refused(bomb: str, zips: dict[str, Path], tmp_path: Path) -> None:
    source, target = zips["ppo-multi"], tmp_path / "bomb.zip"
    if bomb == "data-expands":
        with zipfile.ZipFile(source) as original, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as copy:
            for info in original.infolist():
                copy.writestr(info.filename, original.read(info.filename) + (b" " * 2**23
                                                                              if info.filename == "data" else b""))
        expected = "data would expand from"
    elif bomb == "weights-declare":
        declared(rewrite(source, target, {}), "policy.pth", 0xFFFFFFF0)
        expected = "policy.pth declares 4294967280 bytes, more than"
    else:
        torch_file = deflated({"archive/data.pkl": bytes(64 * 2**20), "archive/version": b"3\n"})
        rewrite(source, target, {"policy.pth": torch_file})
        expected = "policy.pth's record 'archive/data.pkl' would expand from"
    message = outcome(target)
    assert expected in message and "zip bomb" in message, message


def test_a_truncated_or_corrupt_zip_is_refused_in_one_line(zips: dict[str, Path], tmp_path: Path) -> None:
    raw = zips["ppo-multi"].read_bytes()

    @HOSTILE
    @given(cut=st.integers(0, len(raw) - 1))
    def truncated(cut: int) -> None:
        path = tmp_path / "cut.zip"
        path.write_bytes(raw[:cut])
        assert outcome(path) != "loaded"

    @HOSTILE
    @given(at=st.one_of(st.integers(0, len(raw) - 1), st.integers(len(raw) - 4096, len(raw) - 1)),
           flip=st.integers(1, 255))
    def corrupt(at: int, flip: int) -> None:
        path = tmp_path / "flip.zip"
        path.write_bytes(raw[:at] + bytes([raw[at] ^ flip]) + raw[at + 1:])
        outcome(path)  # loaded (a byte no reader reads) or refused in one line; nothing else

    truncated()
    corrupt()
    path = tmp_path / "cut.zip"
    path.write_bytes(raw[:len(raw) // 2])
    assert "not a readable zip" in outcome(path)


def test_weights_of_the_wrong_shapes_are_refused(zips: dict[str, Path], tmp_path: Path) -> None:
    with zipfile.ZipFile(zips["ppo-relu"]) as other:
        message = outcome(rewrite(zips["ppo-multi"], tmp_path / "other.zip", {"policy.pth": other.read("policy.pth")}))
    assert "policy.pth holds" in message and "a MultiInputActorCriticPolicy with these policy_kwargs" in message
    with zipfile.ZipFile(zips["ppo-multi"]) as archive:
        state = torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=True)
    name = "mlp_extractor.policy_net.0.weight"
    rows, columns = state[name].shape
    buffer = io.BytesIO()
    torch.save({**state, name: state[name].reshape(columns, rows)}, buffer)
    message = outcome(rewrite(zips["ppo-multi"], tmp_path / "shape.zip", {"policy.pth": buffer.getvalue()}))
    assert f"{name} ({columns}, {rows}) (needs ({rows}, {columns}))" in message
    buffer = io.BytesIO()
    torch.save([state[name]], buffer)
    message = outcome(rewrite(zips["ppo-multi"], tmp_path / "list.zip", {"policy.pth": buffer.getvalue()}))
    assert "policy.pth holds a list, not a state dict" in message


def test_a_model_trained_for_other_actions_is_refused(zips: dict[str, Path]) -> None:
    with pytest.raises(Sb3ZipError, match=r"it acts in Box\(\[-1.5 -1.5\], \[1.5 1.5\], \[2\], float32\), the env "
                                          r"takes Box\(-1.0, 1.0, \(2,\), float32\)"):
        load_sb3_zip(zips["ppo-multi"], gym.spaces.Box(-1.0, 1.0, (2,), np.float32))


FIELDS = ("policy_class", "observation_space", "action_space", "policy_kwargs", "use_sde")
NASTY = [10**400, -1, 0, float("nan"), float("inf"), "a\nb", "<class 'torch.nn.modules.activation.ReLU'>",
         "{'ego': Box(-inf, inf, (" + "9" * 5000 + ",), float32)}", "{'ego': Box(0, 255, (8, 8, 3), uint8)}",
         "<function ActorCriticPolicy.__init__ at 0x1>", [1] * 100, {"pi": [2**40] * 3}]
"""values a hostile file may hold where a plain one is read"""
JSON = st.recursive(st.none() | st.booleans() | st.integers(-2**40, 2**40) | st.floats() | st.text(max_size=12)
                    | st.sampled_from(NASTY),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                  max_size=4), max_leaves=8)


def test_any_plain_value_in_the_fields_read_loads_or_is_refused_in_one_line(zips: dict[str, Path],
                                                                          tmp_path: Path) -> None:
    data = data_of(zips["ppo-relu"])

    @HOSTILE
    @given(draw=st.data())
    def hostile(draw: st.DataObject) -> None:
        key = draw.draw(st.sampled_from(FIELDS))
        field = data.get(key)
        entry = draw.draw(st.sampled_from([None, *field])) if isinstance(field, dict) else None
        original = field if entry is None else field[entry]
        value = draw.draw(st.one_of(JSON, mutated(original)) if isinstance(original, str) else JSON)
        crafted = {**data, key: value if entry is None else {**field, entry: value}}
        outcome(with_data(zips["ppo-relu"], tmp_path / "hostile.zip", crafted))

    @HOSTILE
    @given(net_arch=st.one_of(st.lists(st.integers(-3, 2**40), max_size=4),
                              st.dictionaries(st.sampled_from(["pi", "vf", "qf"]),
                                              st.lists(st.integers(1, 2**40), max_size=70), max_size=3)))
    def wide(net_arch: Any) -> None:
        kwargs = {**data["policy_kwargs"], "net_arch": net_arch}
        message = outcome(with_data(zips["ppo-relu"], tmp_path / "wide.zip", {**data, "policy_kwargs": kwargs}))
        assert message == "loaded" or "net_arch" in message or "policy.pth" in message, message

    hostile()
    wide()


def mutated(text: str) -> st.SearchStrategy[str]:
    """``text`` with a few characters inserted, deleted or replaced."""
    return st.tuples(st.integers(0, len(text)), st.integers(0, 3), st.text(max_size=3)).map(
        lambda cut: text[:cut[0]] + cut[2] + text[cut[0] + cut[1]:])


def test_a_custom_policy_class_needs_the_opt_in_which_runs_sb3s_loader(tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    PPO(CustomPolicy, make_env("MultiInputPolicy"), n_steps=8, batch_size=8, device="cpu").save(tmp_path / "own.zip")
    env = gym.make(ENV, predictor="none")
    spec = f"sb3:{tmp_path / 'own.zip'}"
    with pytest.raises(PolicyError) as refused:
        load_policy(spec, world_of(env))
    message = str(refused.value)
    assert message.startswith(f"policy {spec!r}: its policy class ") and "--trust-policy-file" in message
    trusted = load_policy(spec, world_of(env), trust_file=True)
    assert isinstance(trusted.policy.model.policy, CustomPolicy)
    obs, _ = env.reset(seed=0)
    assert trusted.act(obs).shape == (2,)
    with pytest.raises(PolicyError, match=r"--trust-policy-file is for an sb3:PATH\.zip model file"):
        load_policy("straight", world_of(env), trust_file=True)


def test_the_world_states_the_envs_action_space() -> None:
    for env_id in (ENV, "STCrowd-SimCorridor-v1", "STCrowd-Zara1-v0"):
        env = gym.make(env_id, predictor="none")
        assert world_of(env).action_space == env.action_space, env_id


def test_the_benchmark_refuses_a_hostile_file_in_one_line_and_the_opt_in_runs_it(zips: dict[str, Path],
                                                                                 tmp_path: Path, capsys) -> None:
    marker = tmp_path / "ran"
    data = data_of(zips["ppo-multi"])
    evil = with_data(zips["ppo-multi"], tmp_path / "evil.zip",
                     {**data, "policy_class": {":type:": "<class 'abc.ABCMeta'>", ":serialized:": pickled(marker)}})
    args = ["benchmark", "--policy", f"sb3:{evil}", "--predictor", "none", "--suite", "val", "--episodes", "1",
            "--scenarios", "frontal-approach", "--workers", "1", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "safe")]) == 1
    err = capsys.readouterr().err.strip()
    assert not marker.exists(), "nothing in the file ran"
    assert len(err.splitlines()) == 1 and str(evil) in err and "names no policy class in plain text" in err
    assert "--trust-policy-file" in err
    assert main([*args, "--trust-policy-file", "--out", str(tmp_path / "trusted")]) == 1
    assert marker.exists(), "the opt-in is SB3's loader, which runs what the file holds"
    assert "derives from none of SB3's" in capsys.readouterr().err


def test_navigate_refuses_a_model_that_does_not_fit_its_env_and_the_opt_in_for_other_policies(
        zips: dict[str, Path], capsys) -> None:
    args = ["navigate", "--predictor", "none", "--episodes", "1", "--quiet"]
    assert main([*args, "--env", "STCrowd-Zara1-v0", "--policy", f"sb3:{zips['ppo-multi']}"]) == 1
    err = capsys.readouterr().err
    assert "does not fit scenario 'STCrowd-Zara1-v0'" in err and "(20, 8, 2)" in err and "(40, 8, 2)" in err
    assert main([*args, "--env", ENV, "--policy", "straight", "--trust-policy-file"]) == 1
    assert "--trust-policy-file is for an sb3:PATH.zip model file" in capsys.readouterr().err
