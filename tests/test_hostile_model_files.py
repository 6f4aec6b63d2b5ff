"""A model file from a stranger cannot make its reader allocate more than the file holds (``held_weights``), in an SB3
zip's ``policy.pth`` (``sb3_zip``) and in a PPO policy file (``ppo.load_policy``): a tensor that does not own the
bytes it stands for is refused in one line naming the file, the tensor and the problem, an honest one still loads
with its values, and a network wider, deeper or bigger than the caps is refused before any of it is built.

Classes of attack: random strides, offsets and storage sizes over any tensor of the network (expanded views, slices
of a bigger storage, overlapping views), other dtypes, two tensors on one storage, tensors without data (meta,
sparse), compressed records, and oversized ``net_arch`` beside weights that are held or only expanded. An SB3 zip's
``data`` member is held to the caps of every results file (``replays.bounded_json``): past its size, nesting depth or
token count, holding NaN or Infinity anywhere, not UTF-8, or not a JSON object, it is refused in one line naming the
zip and the member.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from pathlib import Path
from typing import Any

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sb3_files import ACTIONS, data_of, make_env, outcome, rewrite
from stable_baselines3.common.policies import ActorCriticPolicy

from replays.bounded_json import MAX_DEPTH, MAX_TOKENS
from st_sim.apps.navigation.features import FeatureConfig
from st_sim.apps.navigation.held_weights import MAX_PARAMETERS, network_state
from st_sim.apps.navigation.ppo import (
    EXTRACTORS,
    STATE_DICT,
    PolicyFileError,
    build_policy,
    load_policy,
    policy_kwargs,
    policy_spaces,
    save_policy,
)
from st_sim.apps.navigation.sb3_zip import MAX_DATA_BYTES, load_sb3_zip

HOSTILE = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
NET_ARCH = [16, 16]  # the honest files' layers [-]
FEATURES = FeatureConfig(use_predictions=False)
WIDE = [40000, 40000]  # the red team's net_arch: 6.4 GB of float32 weights if built
OTHER_DTYPES = (torch.float64, torch.float16, torch.bfloat16, torch.int64, torch.int32, torch.uint8, torch.bool,
                torch.complex64)
STORAGE_PROBLEMS = ("is an expanded view (stride 0), not weights held in the file", "is not contiguous",
                    "a slice of a bigger one, not weights of its own", "of its storage's")
"""what a view of a storage that is not its own is refused for"""


def no_learning(progress_remaining: float) -> float:
    """Learning-rate schedule of a policy built only for its shapes."""
    return 0.0


class Built(BaseException):
    """A network was built (no loader catches a BaseException)."""


@pytest.fixture
def nothing_built(monkeypatch: pytest.MonkeyPatch) -> None:
    """From here on, building any linear layer, on any device, fails the test."""

    def refuse(*args: Any, **kwargs: Any) -> None:
        raise Built("a network was built before the file was refused")

    monkeypatch.setattr(torch.nn.Linear, "__init__", refuse)


@pytest.fixture(scope="module")
def sb3_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A PPO MlpPolicy of ``NET_ARCH`` as SB3 saves it."""
    from stable_baselines3 import PPO

    path = tmp_path_factory.mktemp("sb3") / "ppo.zip"
    PPO("MlpPolicy", make_env("MlpPolicy"), n_steps=8, batch_size=8, seed=0, device="cpu",
        policy_kwargs={"net_arch": NET_ARCH}).save(path)
    return path


@pytest.fixture(scope="module")
def ppo_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A policy file of ``NET_ARCH`` per extractor, as ``train_ppo`` writes it."""
    folder = tmp_path_factory.mktemp("ppo")
    files = {}
    for extractor in EXTRACTORS:
        files[extractor] = folder / f"{extractor}.pt"
        save_policy(build_policy(FEATURES, NET_ARCH, extractor), FEATURES, NET_ARCH, files[extractor], extractor)
    return files


def torch_bytes(value: Any) -> bytes:
    buffer = io.BytesIO()
    torch.save(value, buffer)
    return buffer.getvalue()


def policy_pth(path: Path) -> dict[str, torch.Tensor]:
    with zipfile.ZipFile(path) as archive:
        return torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=True)


def sb3_file(source: Path, target: Path, weights: dict[str, torch.Tensor], net_arch: list[int] | None = None) -> Path:
    """``source`` with ``weights`` in policy.pth and, if given, ``net_arch`` in its policy_kwargs."""
    members = {"policy.pth": torch_bytes(weights)}
    if net_arch is not None:
        members["data"] = json.dumps({**data_of(source), "policy_kwargs": {"net_arch": net_arch}}).encode()
    return rewrite(source, target, members)


def ppo_file(source: Path, target: Path, weights: dict[str, torch.Tensor], net_arch: list[int] | None = None) -> Path:
    """The policy file ``source`` with ``weights`` and, if given, ``net_arch``."""
    state = torch.load(source, weights_only=True)
    target.write_bytes(torch_bytes({**state, "weights": weights, "net_arch": net_arch or state["net_arch"]}))
    return target


def ppo_outcome(path: Path) -> str:
    """"loaded", or the refusal's message (checked to be one line naming the file)."""
    try:
        load_policy(path)
    except PolicyFileError as err:
        message = str(err)
        assert "\n" not in message and message.startswith(f"{path}: "), message
        return message
    return "loaded"


def owns_its_bytes(tensor: torch.Tensor) -> bool:
    """The definition of an honest tensor: float32, dense, contiguous, no stride 0, its storage exactly its own."""
    return (tensor.dtype == torch.float32 and 0 not in tensor.stride() and tensor.is_contiguous()
            and tensor.storage_offset() == 0 and tensor.untyped_storage().nbytes() == 4 * tensor.numel())


@st.composite
def crafted(draw: st.DrawFn, state: dict[str, torch.Tensor]
            ) -> tuple[dict[str, torch.Tensor], list[str], tuple[str, ...] | None]:
    """``state`` with one tensor replaced (or two put on one storage): (the weights, the keys touched, the problems
    one of which a refusal must name, or None for an honest replacement, which must load)."""
    keys = sorted(state)
    key = draw(st.sampled_from(keys))
    honest = state[key]
    shape = tuple(honest.shape)
    kind = draw(st.sampled_from(["strides", "expanded", "dtype", "shared", "no data"]))
    if kind == "strides":  # any view of a random storage; copied, it owns its bytes
        dense = [math.prod(shape[i + 1:]) for i in range(len(shape))]
        strides = [draw(st.one_of(st.just(step), st.integers(0, 2 * step + 1))) for step in dense]
        offset, extra = (draw(st.one_of(st.just(0), st.integers(1, 8))) for _ in range(2))
        span = offset + sum((n - 1) * step for n, step in zip(shape, strides, strict=True)) + 1 + extra
        generator = torch.Generator().manual_seed(draw(st.integers(0, 2**16)))
        tensor = torch.randn(span, generator=generator).as_strided(shape, strides, offset)
        if draw(st.sampled_from([False, False, True])):
            tensor = tensor.clone(memory_format=torch.contiguous_format)
        return {**state, key: tensor}, [key], None if owns_its_bytes(tensor) else STORAGE_PROBLEMS
    if kind == "expanded":  # the red team's: one number standing for all
        return {**state, key: torch.ones(()).expand(shape)}, [key], STORAGE_PROBLEMS[:1]
    if kind == "dtype":
        dtype = draw(st.sampled_from(OTHER_DTYPES))
        problem = "(needs float32)" if dtype.is_floating_point else "not floating-point weights"
        return {**state, key: honest.to(dtype)}, [key], (problem,)
    if kind == "shared":  # the smaller of two tensors a view of the other's storage
        other = draw(st.sampled_from([name for name in keys if name != key]))
        small, big = sorted([key, other], key=lambda name: state[name].numel())
        view = state[big].flatten()[:state[small].numel()].view(state[small].shape)
        return {**state, small: view}, [small, big], ("shares its storage with tensor", STORAGE_PROBLEMS[3])
    if draw(st.booleans()):
        return {**state, key: torch.empty(shape, device="meta")}, [key], ("is on the meta device",)
    return {**state, key: honest.to_sparse()}, [key], ("is a sparse_coo tensor, not dense weights",)


def check(message: str, touched: list[str], problems: tuple[str, ...] | None, loaded: dict[str, torch.Tensor] | None,
          weights: dict[str, torch.Tensor], label: str) -> None:
    """A hostile file refused naming ``label``, a touched tensor and one of ``problems``; an honest one loaded with
    the values it holds (a tensor the network shares under several names excepted: the last name's value wins)."""
    if problems is None:
        assert message == "loaded", message
        assert all(torch.equal(loaded[key], weights[key]) for key in touched if "features_extractor." not in key)
        return
    assert label in message, message
    assert any(repr(key) in message or f"{key} " in message for key in touched), (touched, message)
    assert any(problem in message for problem in problems), (problems, message)


@HOSTILE
@given(data=st.data())
def test_a_tensor_of_policy_pth_that_does_not_own_its_bytes_is_refused_and_an_honest_one_loads(
        sb3_zip: Path, tmp_path: Path, data: st.DataObject) -> None:
    weights, touched, problems = data.draw(crafted(policy_pth(sb3_zip)))
    path = sb3_file(sb3_zip, tmp_path / "crafted.zip", weights)
    message = outcome(path)
    loaded = load_sb3_zip(path, ACTIONS).state_dict() if message == "loaded" else None
    check(message, touched, problems, loaded, weights, "policy.pth")


@HOSTILE
@given(data=st.data(), extractor=st.sampled_from(EXTRACTORS))
def test_a_tensor_of_a_ppo_policy_file_that_does_not_own_its_bytes_is_refused_and_an_honest_one_loads(
        ppo_files: dict[str, Path], tmp_path: Path, data: st.DataObject, extractor: str) -> None:
    source = ppo_files[extractor]
    weights, touched, problems = data.draw(crafted(torch.load(source, weights_only=True)["weights"]))
    path = ppo_file(source, tmp_path / "crafted.pt", weights)
    message = ppo_outcome(path)
    loaded = load_policy(path)[0].state_dict() if message == "loaded" else None
    check(message, touched, problems, loaded, weights, STATE_DICT)


def expanded_network(policy_class: type, *args: Any, **kwargs: Any) -> dict[str, torch.Tensor]:
    """The weights of the policy ``policy_class(*args, **kwargs)``, each one number expanded to its shape."""
    return {key: torch.zeros(()).expand(tensor.shape)
            for key, tensor in network_state(policy_class, *args, **kwargs).items()}


OVERSIZED: dict[str, tuple[list[int], str, str]] = {
    "red team: wide, weights expanded": (WIDE, "expanded", "is an expanded view (stride 0), not weights held"),
    "red team: one expanded tensor": (WIDE, "one", "tensor 'x' is an expanded view (stride 0), not weights held"),
    "wide, weights held": (WIDE, "held", "layer widths from 1 to 4096"),
    "too many layers": ([8] * 65, "held", "at most 64 layer widths"),
    "over the parameter cap": ([4096] * 8, "held", f"more than the {MAX_PARAMETERS} a policy may hold"),
    "more than held": ([1024, 1024], "held", "needs at least"),
}
"""net_arch, the weights beside it (the honest file's, expanded views of the net_arch's network, or one expanded
tensor of 10^12 weights) and the problem named"""


def oversized_weights(kind: str, honest: dict[str, torch.Tensor], network: dict[str, torch.Tensor]
                      ) -> dict[str, torch.Tensor]:
    """The weights an ``OVERSIZED`` case puts beside its net_arch: "one" expanded tensor, the ``network`` "expanded",
    or the ``honest`` file's "held"."""
    if kind == "one":
        return {"x": torch.zeros(1).expand(10**6, 10**6)}
    return network if kind == "expanded" else honest


@pytest.mark.parametrize("case", list(OVERSIZED))
def test_an_oversized_sb3_network_is_refused_before_anything_is_built(case: str, sb3_zip: Path, tmp_path: Path,
                                                                     request: pytest.FixtureRequest) -> None:
    net_arch, kind, problem = OVERSIZED[case]
    network = expanded_network(ActorCriticPolicy, make_env("MlpPolicy").observation_space, ACTIONS, no_learning,
                               net_arch=WIDE) if kind == "expanded" else {}
    path = sb3_file(sb3_zip, tmp_path / "oversized.zip", oversized_weights(kind, policy_pth(sb3_zip), network),
                    net_arch)
    request.getfixturevalue("nothing_built")
    message = outcome(path)
    assert problem in message, message


@pytest.mark.parametrize("extractor", EXTRACTORS)
@pytest.mark.parametrize("case", list(OVERSIZED))
def test_an_oversized_ppo_network_is_refused_before_anything_is_built(case: str, extractor: str,
                                                                     ppo_files: dict[str, Path], tmp_path: Path,
                                                                     request: pytest.FixtureRequest) -> None:
    net_arch, kind, problem = OVERSIZED[case]
    network = expanded_network(ActorCriticPolicy, *policy_spaces(FEATURES), no_learning,
                               **policy_kwargs(FEATURES, WIDE, extractor)) if kind == "expanded" else {}
    honest = torch.load(ppo_files[extractor], weights_only=True)["weights"]
    path = ppo_file(ppo_files[extractor], tmp_path / "oversized.pt", oversized_weights(kind, honest, network),
                    net_arch)
    request.getfixturevalue("nothing_built")
    message = ppo_outcome(path)
    assert problem in message, message


def deflated(raw: bytes) -> bytes:
    """The zip ``raw`` (a torch file) with every record compressed."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(raw)) as original, zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as copy:
        for info in original.infolist():
            copy.writestr(info.filename, original.read(info.filename))
    return buffer.getvalue()


def compressed(weights: dict[str, torch.Tensor], padding: bool) -> dict[str, torch.Tensor]:
    """``weights`` as zeros (each record under 64 KiB: never a bomb, whatever its ratio), and with ``padding`` one
    more record of 16 MiB of zeros (a bomb)."""
    zeros = {key: torch.zeros_like(tensor) for key, tensor in weights.items()}
    return {**zeros, "padding": torch.zeros(2**22)} if padding else zeros


@pytest.mark.parametrize(("padding", "problem"), [(False, "tensors hold"), (True, "would expand from")])
def test_compressed_records_are_refused_in_both_file_kinds(padding: bool, problem: str, sb3_zip: Path,
                                                           ppo_files: dict[str, Path], tmp_path: Path) -> None:
    """Torch reads compressed records too: under the ratio their tensors hold more bytes than the file; over it, the
    record is a zip bomb."""
    state = torch.load(ppo_files["flat"], weights_only=True)
    ppo = tmp_path / "deflated.pt"
    ppo.write_bytes(deflated(torch_bytes({**state, "weights": compressed(state["weights"], padding)})))
    assert problem in ppo_outcome(ppo)
    pth = deflated(torch_bytes(compressed(policy_pth(sb3_zip), padding)))
    assert problem in outcome(rewrite(sb3_zip, tmp_path / "deflated.zip", {"policy.pth": pth}))


DATA_ATTACKS = ("nested", "tokens", "non-finite", "not an object", "not UTF-8", "declares too much")
"""how a hostile ``data`` member breaks the bounds of ``replays.bounded_json`` (or SB3's own shape)"""
MARK = "HOSTILE-VALUE"


def with_raw(honest: dict[str, Any], key: str, raw: str) -> bytes:
    """``honest`` as JSON with the text ``raw`` as the value of ``key``."""
    return json.dumps({**honest, key: MARK}).replace(f'"{MARK}"', raw).encode()


@st.composite
def hostile_data(draw: st.DrawFn, honest: dict[str, Any]) -> tuple[bytes, str]:
    """A ``data`` member built from the ``honest`` one, and the words its refusal must hold."""
    attack = draw(st.sampled_from(DATA_ATTACKS))
    key = draw(st.sampled_from(sorted(honest)) | st.just("extra"))  # a field the loader reads, or one it never does
    if attack == "nested":  # past the cap, however deep; the object itself is one level
        pairs = draw(st.lists(st.sampled_from([("[", "]"), ('{"k":', "}")]), min_size=MAX_DEPTH,
                              max_size=20 * MAX_DEPTH))
        raw = "".join(opening for opening, _ in pairs) + "0" + "".join(closing for _, closing in reversed(pairs))
        return with_raw(honest, key, raw), f"JSON nested more than {MAX_DEPTH} levels deep"
    if attack == "tokens":  # a flat list of more values than the cap (a comma is a token, a number is not)
        raw = "[" + "0," * (MAX_TOKENS + draw(st.integers(0, 1000))) + "0]"
        return with_raw(honest, key, raw), f"more than {MAX_TOKENS:,} JSON tokens"
    if attack == "non-finite":  # Python's json writes them; no strict reader reads them
        constant = draw(st.sampled_from(["NaN", "Infinity", "-Infinity"]))
        where = draw(st.sampled_from(["{}", "[{}]", '{"a": [1, {}]}']))
        return with_raw(honest, key, where.replace("{}", constant)), "not strict JSON"
    if attack == "not an object":
        value = draw(st.sampled_from([[honest], list(honest), 1, 2.5, "data", True, None]))
        return json.dumps(value).encode(), f"data is a JSON {type(value).__name__}, not an object"
    if attack == "not UTF-8":  # a byte sequence no UTF-8 text holds, inside a string or as the value itself
        bad = draw(st.sampled_from([b"\xff", b"\xc3\x28", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80", b"\x80"]))
        raw = draw(st.sampled_from([b'"va' + bad + b'lue"', bad]))
        return with_raw(honest, key, "BAD").replace(b"BAD", raw), "not UTF-8 text"
    return b" " * (MAX_DATA_BYTES + draw(st.integers(1, 4096))), "data declares"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_data_member_past_the_bounds_of_every_results_file_is_refused_naming_the_zip_and_the_member(
        sb3_zip: Path, tmp_path: Path, data: st.DataObject) -> None:
    member, problem = data.draw(hostile_data(data_of(sb3_zip)))
    path = tmp_path / "crafted.zip"
    with zipfile.ZipFile(sb3_zip) as original, zipfile.ZipFile(path, "w") as copy:  # stored: the sizes as they are
        for info in original.infolist():
            copy.writestr(info.filename, member if info.filename == "data" else original.read(info.filename))
    message = outcome(path)
    assert message.startswith(f"{path}: data") and problem in message, message


def test_a_data_member_within_the_bounds_loads(sb3_zip: Path, tmp_path: Path) -> None:
    """The deepest nesting the caps allow, in a field the loader never reads: the honest file still loads."""
    deepest = with_raw(data_of(sb3_zip), "extra", "[" * (MAX_DEPTH - 1) + "0" + "]" * (MAX_DEPTH - 1))
    assert outcome(rewrite(sb3_zip, tmp_path / "deep.zip", {"data": deepest})) == "loaded"
