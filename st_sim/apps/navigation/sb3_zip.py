"""A stable-baselines3 model file read without running anything stored in it.

A model SB3 saves is a zip: ``data`` (JSON; the policy class, the spaces, the schedules and buffers are cloudpickled
inside it, and unpickling any of them runs whatever code the file's author put there) and ``policy.pth`` (the
weights), beside the optimizers' files. SB3 writes a plain-text form beside each pickle: the class's module and
``__init__``, a space's shape and dtype, the entries of a dict. ``load_sb3_zip`` reads only those and the weights:

- the policy class by the names ``data`` states in plain text, from an allow-list: the ``MlpPolicy`` and
  ``MultiInputPolicy`` of ``SAFE_ALGORITHMS`` (PPO, A2C, SAC, TD3, DDPG);
- the architecture from ``policy_kwargs``' plain form: ``net_arch`` and the other plain values as written, the
  activation and feature-extractor classes by the names SB3 writes (from allow-lists), the class's defaults for the
  rest; the optimizer settings are not needed to act and are not read;
- the observation space the model was trained on from ``observation_space``'s plain shapes and dtypes (a Box, or
  a Dict of Boxes; unbounded: acting reads no bound of a non-image space); the action space is the caller's (the
  env's), and must be the one the model states in plain text;
- the weights with ``torch.load(weights_only=True)``: exactly the tensors of the policy built from the above, each
  owning the bytes it holds (``held_weights``).

``data`` is parsed within the caps every results file is read within (``replays.bounded_json.parse_json``: its
size, nesting depth and token count bounded before it is parsed, UTF-8, strict JSON: no NaN, no Infinity). Nothing
else in the zip is read. A member that declares more bytes than a model file holds (``MAX_DATA_BYTES``,
``held_weights.MAX_WEIGHTS_BYTES``), or that would expand more than ``held_weights.MAX_RATIO`` times, is refused
before it is decompressed (a zip bomb), in the zip and in the zip that ``policy.pth`` itself is. Weights are counted
from the bytes ``policy.pth`` holds (an expanded view, a slice or a shared storage is refused), and a policy whose
layers are wider or more than ``held_weights`` allows, or that would hold another number of weights than
``policy.pth``, or other names, shapes or dtypes, is refused before it is built (its shapes come from a build on the
meta device, which holds no memory).

    policy = load_sb3_zip(Path("model.zip"), env.action_space)   # an SB3 policy on the CPU
    action, _ = policy.predict(obs, deterministic=True)           # as SB3's PPO.load("model.zip").predict
"""

from __future__ import annotations

import inspect
import math
import re
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces

from predictor.plugins import describe_error
from replays.bounded_json import parse_json
from replays.errors import DataFormatError
from st_sim.apps.navigation.held_weights import (
    MAX_HIDDEN_LAYERS,
    MAX_WEIGHTS_BYTES,
    MAX_WIDTH,
    WeightsError,
    check_expansion,
    check_fits,
    check_implied,
    held_weights,
    is_layers,
    mlp_weights,
    network_state,
    read_torch,
    weights_in,
)

MAX_DATA_BYTES = 16 * 2**20  # the data JSON [bytes] (SB3 writes tens of kilobytes)
MAX_CRITICS = 16  # n_critics [-]
MAX_DIMS = 8  # dimensions of an observation [-]
SAFE_ALGORITHMS = ("PPO", "A2C", "SAC", "TD3", "DDPG")
SAFE_ALIASES = ("MlpPolicy", "MultiInputPolicy")
ACTIVATIONS = ("ReLU", "Tanh", "ELU", "LeakyReLU", "SiLU", "GELU", "Sigmoid", "Softplus", "Mish", "SELU", "CELU",
               "ReLU6", "Hardtanh", "Hardswish", "Softsign")
"""activation_fn classes of torch.nn read by name (``torch.nn.modules.activation``)"""
EXTRACTORS = ("FlattenExtractor", "CombinedExtractor")
"""features_extractor_class values read by name (``stable_baselines3.common.torch_layers``)"""
PLAIN_KWARGS: dict[str, type] = {"ortho_init": bool, "use_sde": bool, "full_std": bool, "use_expln": bool,
                                 "squash_output": bool, "share_features_extractor": bool, "normalize_images": bool,
                                 "log_std_init": float, "clip_mean": float, "n_critics": int}
"""policy_kwargs read as the JSON value they are, by the type they must have"""
UNUSED_KWARGS = ("optimizer_class", "optimizer_kwargs", "device")
"""policy_kwargs for training only (SB3's loader drops ``device`` too): never read"""
DTYPES = ("float16", "float32", "float64", "bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32",
          "uint64")
BOX_TYPE = "<class 'gymnasium.spaces.box.Box'>"
DICT_TYPE = "<class 'gymnasium.spaces.dict.Dict'>"
DICT_ENTRY = re.compile(r"'(?P<key>[^'\\]*)': Box\((?P<low>[^(),]*), (?P<high>[^(),]*), \((?P<shape>[0-9, ]*)\), "
                        r"(?P<dtype>\w+)\)")
"""one entry of a Dict space's plain text, ``'key': Box(low, high, (shape), dtype)``"""
INIT_NAME = re.compile(r"<function (?P<name>\w+)\.__init__ at 0x[0-9a-fA-F]+>")
CLASS_NAME = re.compile(r"<class '(?P<module>[\w.]+)\.(?P<name>\w+)'>")
NUMBERS = re.compile(r"\[(?P<numbers>[-+.\w\s]*)\]")


class Sb3ZipError(WeightsError):
    """A model file that ``load_sb3_zip`` refuses; the message names the file (when known) and the problem."""


def load_sb3_zip(path: Path, action_space: spaces.Box) -> Any:
    """The policy saved in the SB3 model file ``path``, for an env whose actions are ``action_space``: a
    ``stable_baselines3`` ``BasePolicy`` on the CPU, its ``observation_space`` the one the model was trained on
    (see the module docstring). Raises ``Sb3ZipError`` naming the file and the problem."""
    try:
        data, weights, weights_size = _read(path)
        policy_class, on_policy = _policy_class(data.get("policy_class"))
        observation_space = _observation_space(data.get("observation_space"), weights_size)
        _check_actions(data.get("action_space"), action_space)
        kwargs = _policy_kwargs(data.get("policy_kwargs"), policy_class)
        if on_policy:  # built with the algorithm's own use_sde (SB3's loader fails on a second one too)
            if "use_sde" in kwargs:
                raise Sb3ZipError("policy_kwargs: use_sde is the algorithm's own setting, not a policy keyword")
            kwargs["use_sde"] = _plain("use_sde", data.get("use_sde", False))
        with torch.random.fork_rng(devices=[]):  # building draws initial weights: keep the caller's random state
            _check_network(policy_class, kwargs, observation_space, action_space, weights, on_policy)
            policy = _build(policy_class, observation_space, action_space, kwargs)
        _load_weights(policy, weights)
    except WeightsError as err:
        raise Sb3ZipError(err.problem, path) from None
    policy.set_training_mode(False)
    return policy


def _read(path: Path) -> tuple[dict[str, Any], dict[str, torch.Tensor], int]:
    """``data`` as JSON, ``policy.pth`` as tensors that own their bytes, and the number of weights they hold."""
    try:
        with zipfile.ZipFile(path) as archive:
            data_bytes = _member(archive, "data", MAX_DATA_BYTES)
            weights_bytes = _member(archive, "policy.pth", MAX_WEIGHTS_BYTES)
    except (OSError, EOFError, RuntimeError, NotImplementedError, zipfile.BadZipFile, zlib.error) as err:
        raise Sb3ZipError(f"not a stable-baselines3 model file: not a readable zip ({describe_error(err)})") from None
    try:
        data = parse_json(data_bytes, "data", "stable-baselines3 model's data member")
    except DataFormatError as err:  # past a cap of replays.bounded_json, not UTF-8 or not strict JSON
        raise Sb3ZipError(str(err)) from None
    if not isinstance(data, dict):
        raise Sb3ZipError(f"data is a JSON {type(data).__name__}, not an object")
    weights = read_torch(weights_bytes, "policy.pth")
    return data, weights, held_weights(weights, "policy.pth", len(weights_bytes))


def _member(archive: zipfile.ZipFile, name: str, limit_bytes: int) -> bytes:
    """The bytes of member ``name``, refused unread if it declares more than ``limit_bytes`` or expands too much."""
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise Sb3ZipError(f"no {name} in it: not a stable-baselines3 model file") from None
    check_expansion(info, limit_bytes, name)
    with archive.open(info) as member:
        raw = member.read(limit_bytes + 1)
    if len(raw) != info.file_size:
        raise Sb3ZipError(f"{name} holds {len(raw)} bytes, its header says {info.file_size}")
    return raw


def _shown(value: Any, limit: int = 80) -> str:
    """``value`` as one line of at most ``limit`` characters, for a message."""
    return " ".join(str(value).split())[:limit]


def safe_policies() -> dict[tuple[str, str], tuple[type, bool]]:
    """(module, class) of each policy read without running the file -> (the class, True if an on-policy algorithm
    builds it with its own ``use_sde``): the ``SAFE_ALIASES`` of each of ``SAFE_ALGORITHMS``."""
    import stable_baselines3
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    table = {}
    for name in SAFE_ALGORITHMS:
        algorithm = getattr(stable_baselines3, name)
        for alias in SAFE_ALIASES:
            policy_class = algorithm.policy_aliases[alias]
            key = (policy_class.__module__, policy_class.__init__.__qualname__.removesuffix(".__init__"))
            table[key] = (policy_class, issubclass(algorithm, OnPolicyAlgorithm))
    return table


def _policy_class(field: Any) -> tuple[type, bool]:
    """The policy class ``data`` names by its plain module and ``__init__``, if allowed; and whether on-policy."""
    module, init = (field.get("__module__"), field.get("__init__")) if isinstance(field, dict) else (None, None)
    named = INIT_NAME.fullmatch(init) if isinstance(init, str) else None
    if named is None or not isinstance(module, str):
        raise Sb3ZipError("data names no policy class in plain text (its module and __init__)")
    key = (module, named["name"])
    allowed = safe_policies()
    if key not in allowed:
        raise Sb3ZipError(f"its policy class {_shown(module)}.{key[1]} is not one read without running the file "
                          f"(read are the {' and '.join(SAFE_ALIASES)} of {', '.join(SAFE_ALGORITHMS)})")
    return allowed[key]


def _observation_space(field: Any, weights_size: int) -> spaces.Space:
    """The observation space the model was trained on, from its plain shapes and dtypes: a Box, or a Dict of Boxes
    in the order written. Refused if it has more inputs than ``weights_size`` weights could read."""
    kind = field.get(":type:") if isinstance(field, dict) else None
    if kind == BOX_TYPE:
        shape, dtype = field.get("_shape"), field.get("dtype")
        if not (isinstance(shape, list) and all(isinstance(n, int) and not isinstance(n, bool) for n in shape)):
            raise Sb3ZipError(f"observation_space: shape {_shown(shape)} is not a list of sizes")
        entries = [(None, _checked_shape(shape), dtype)]
    elif kind == DICT_TYPE:
        entries = _dict_entries(field.get("spaces"))
    else:
        raise Sb3ZipError(f"observation_space is a {_shown(kind)}; read without running the file are a Box and a "
                          "Dict of Boxes")
    inputs = sum(math.prod(shape) for _, shape, _ in entries)
    if inputs > weights_size:
        raise Sb3ZipError(f"observation_space has {inputs} inputs, more than policy.pth's {weights_size} weights "
                          "could read")
    boxes = [(key, _box(shape, dtype)) for key, shape, dtype in entries]
    return boxes[0][1] if kind == BOX_TYPE else spaces.Dict(boxes)


def _dict_entries(text: Any) -> list[tuple[str, tuple[int, ...], Any]]:
    """(key, shape, dtype) of each Box in a Dict space's plain text, which must be exactly such entries."""
    matches = list(DICT_ENTRY.finditer(text)) if isinstance(text, str) else []
    if not matches or text != "{" + ", ".join(match[0] for match in matches) + "}":
        raise Sb3ZipError(f"observation_space: {_shown(text)!r} is not a Dict of Boxes in plain text")
    keys = [match["key"] for match in matches]
    if len(set(keys)) != len(keys):
        raise Sb3ZipError(f"observation_space: keys {keys} repeat")
    shapes = [match["shape"].replace(",", " ").split() for match in matches]
    if any(len(size) > 18 for sizes in shapes for size in sizes):
        raise Sb3ZipError(f"observation_space: a shape in {_shown(text)} has sizes of more than 18 digits")
    return [(match["key"], _checked_shape([int(size) for size in sizes]), match["dtype"])
            for match, sizes in zip(matches, shapes, strict=True)]


def _checked_shape(shape: list[int]) -> tuple[int, ...]:
    """``shape`` if it is an array's: at most ``MAX_DIMS`` sizes, each at least 1."""
    if len(shape) > MAX_DIMS or any(n < 1 for n in shape):
        raise Sb3ZipError(f"observation_space: shape {_shown(shape)} is not an observation's (at most {MAX_DIMS} "
                          "sizes of at least 1)")
    return tuple(shape)


def _box(shape: tuple[int, ...], dtype: Any) -> spaces.Box:
    """An unbounded Box of ``shape`` and ``dtype`` (a bool or integer one spans its dtype); images are refused."""
    from stable_baselines3.common.preprocessing import is_image_space

    if dtype not in DTYPES:
        raise Sb3ZipError(f"observation_space: dtype {_shown(dtype, 40)!r} is not one of {', '.join(DTYPES)}")
    kind = np.dtype(dtype)
    low, high = ((-np.inf, np.inf) if kind.kind == "f" else (0, 1) if kind.kind == "b"
                 else (np.iinfo(kind).min, np.iinfo(kind).max))
    box = spaces.Box(low, high, shape, kind)
    if is_image_space(box, check_channels=False):
        raise Sb3ZipError(f"observation_space: {box} is an image, which only SB3's loader reads")
    return box


def _check_actions(field: Any, action_space: spaces.Box) -> None:
    """The model's action space, in plain text, must be the env's: shape, dtype and bounds."""
    if not isinstance(field, dict) or field.get(":type:") != BOX_TYPE:
        raise Sb3ZipError("action_space is not a Box in plain text")
    shape, dtype = field.get("_shape"), field.get("dtype")
    low, high = _numbers(field.get("low")), _numbers(field.get("high"))
    fits = (shape == list(action_space.shape) and dtype == str(action_space.dtype) and low is not None
            and high is not None and low.shape == high.shape == action_space.shape
            and np.allclose(low, action_space.low, rtol=1e-6, atol=0)
            and np.allclose(high, action_space.high, rtol=1e-6, atol=0))
    if not fits:
        stated = f"Box({_shown(field.get('low'), 40)}, {_shown(field.get('high'), 40)}, {_shown(shape, 40)}, " \
                 f"{_shown(dtype, 20)})"
        raise Sb3ZipError(f"it acts in {stated}, the env takes {action_space}")


def _numbers(text: Any) -> np.ndarray | None:
    """A 1-D array's plain text, "[-1.5 -1.5]", as float64 numbers; None if it is not one."""
    found = NUMBERS.fullmatch(text) if isinstance(text, str) else None
    try:
        return None if found is None else np.array([float(n) for n in found["numbers"].split()])
    except ValueError:
        return None


def _policy_kwargs(field: Any, policy_class: type) -> dict[str, Any]:
    """The keywords the policy was built with, from ``policy_kwargs``' plain form (a dict SB3 had to pickle is
    written beside the pickle entry by entry, a class as its name)."""
    if field is None:
        return {}
    if not isinstance(field, dict):
        raise Sb3ZipError(f"policy_kwargs is a JSON {type(field).__name__}, not an object")
    if ":serialized:" in field:
        if field.get(":type:") != "<class 'dict'>":
            raise Sb3ZipError("policy_kwargs is stored only as a pickle")
        field = {key: value for key, value in field.items() if key not in (":type:", ":serialized:")}
    accepted = inspect.signature(policy_class).parameters
    kwargs = {}
    for key, value in field.items():
        if key in UNUSED_KWARGS:
            continue
        if key not in accepted or key in ("observation_space", "action_space", "lr_schedule"):
            raise Sb3ZipError(f"policy_kwargs: {key[:40]!r} is not a keyword of {policy_class.__name__}")
        kwargs[key] = _keyword(key, value)
    return kwargs


def _keyword(key: str, value: Any) -> Any:
    """One policy keyword from its plain form, or refused."""
    import stable_baselines3.common.torch_layers as torch_layers

    if key == "net_arch":
        return _net_arch(value)
    if key == "activation_fn":
        return _named_class(key, value, "torch.nn.modules.activation", ACTIVATIONS, torch.nn)
    if key == "features_extractor_class":
        return _named_class(key, value, torch_layers.__name__, EXTRACTORS, torch_layers)
    if key == "features_extractor_kwargs":
        if not (isinstance(value, dict) and all(isinstance(v, bool | int | float | str) for v in value.values())):
            raise Sb3ZipError(f"policy_kwargs: features_extractor_kwargs {_shown(value)} are not plain values")
        return value
    if key in PLAIN_KWARGS:
        return _plain(key, value)
    raise Sb3ZipError(f"policy_kwargs: {key} = {_shown(value)} is rebuilt only by running the file's pickles")


def _plain(key: str, value: Any) -> Any:
    """A plain keyword of the type ``PLAIN_KWARGS`` gives (use_sde of an on-policy algorithm is a bool too)."""
    kind = PLAIN_KWARGS[key]
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if kind is bool:
        fits = isinstance(value, bool)
    elif kind is float:
        fits = number and abs(value) < 1e6  # also refuses NaN and inf; compares a huge int without overflow
    else:
        fits = number and isinstance(value, int) and 1 <= value <= MAX_CRITICS
    if not fits:
        raise Sb3ZipError(f"{key} = {_shown(value, 40)} is not a {kind.__name__}"
                          + (f" from 1 to {MAX_CRITICS}" if kind is int else ""))
    return value


def _net_arch(value: Any) -> list[int] | dict[str, list[int]]:
    """net_arch as SB3 reads it: a list of layer widths, or a dict of them per network (an old file's [dict])."""
    if isinstance(value, list) and value and isinstance(value[0], dict):
        value = value[0]  # as SB3's loader reads files of SB3 < 1.8
    widths = value.values() if isinstance(value, dict) else [value]
    if not all(is_layers(layers) for layers in widths):
        raise Sb3ZipError(f"policy_kwargs: net_arch {_shown(value)} is not lists of at most {MAX_HIDDEN_LAYERS} layer "
                          f"widths from 1 to {MAX_WIDTH}")
    return value


def _named_class(key: str, value: Any, module: str, names: tuple[str, ...], source: Any) -> type:
    """The class ``value`` names as "<class 'module.Name'>", if it is one of ``names`` in ``module``."""
    named = CLASS_NAME.fullmatch(value) if isinstance(value, str) else None
    if named is None or named["module"] != module or named["name"] not in names:
        raise Sb3ZipError(f"policy_kwargs: {key} = {_shown(value)} is not one read by name (read are "
                          f"{', '.join(names)} of {module})")
    return getattr(source, named["name"])


def _no_learning(progress_remaining: float) -> float:
    """Learning-rate schedule of a policy that only acts (its optimizer is never stepped)."""
    return 0.0


def _build(policy_class: type, observation_space: spaces.Space, action_space: spaces.Box, kwargs: dict[str, Any],
           on_meta: bool = False) -> Any:
    """The policy; ``on_meta``: its state dict on the meta device, no memory (``held_weights.network_state``)."""
    try:
        if on_meta:
            return network_state(policy_class, observation_space, action_space, _no_learning, **kwargs)
        return policy_class(observation_space, action_space, _no_learning, **kwargs)
    except Exception as err:  # SB3's own checks of its keywords, each its way
        raise Sb3ZipError(f"policy_kwargs {_shown(kwargs, 120)} do not build a {policy_class.__name__} "
                          f"({describe_error(err)})") from None


def _check_network(policy_class: type, kwargs: dict[str, Any], observation_space: spaces.Space,
                   action_space: spaces.Box, weights: dict[str, torch.Tensor], on_policy: bool) -> None:
    """Refuse a policy that would hold other weights than policy.pth, before building it: the weights net_arch
    implies on these spaces (the actor's layers from the inputs to the actions, each critic's to one value: fewer
    than the whole policy's) must be within the caps and those held; then the policy built on the meta device must
    hold as many, with policy.pth's names, shapes and dtypes."""
    net_arch = kwargs.get("net_arch") or []
    pi, others = ((net_arch, net_arch) if isinstance(net_arch, list)
                  else (net_arch.get("pi", []), net_arch.get("vf" if on_policy else "qf", [])))
    copies = 1 if on_policy else kwargs.get("n_critics", 2)
    inputs, actions = spaces.flatdim(observation_space), spaces.flatdim(action_space)
    held = weights_in(weights)
    check_implied(mlp_weights(inputs, [*pi, actions]) + copies * mlp_weights(inputs, [*others, 1]), held, net_arch,
                  "policy.pth")
    network = _build(policy_class, observation_space, action_space, kwargs, on_meta=True)
    check_fits(weights, network, "policy.pth", f"a {policy_class.__name__} with these policy_kwargs on "
               f"{observation_space}")


def _load_weights(policy: Any, weights: dict[str, torch.Tensor]) -> None:
    """Load a state dict that has exactly the policy's names, shapes and dtypes (``_check_network``)."""
    try:
        policy.load_state_dict(weights)
    except (RuntimeError, TypeError, ValueError) as err:
        raise Sb3ZipError(f"policy.pth does not load ({describe_error(err)})") from None
