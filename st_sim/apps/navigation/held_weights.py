"""The weights a model file holds, counted from the bytes it holds, and the network it states, bounded before it is
built: so that a file from a stranger cannot make its reader allocate more than it holds.

A torch file is a zip of records: a pickle and one record per storage. ``torch.load(weights_only=True)`` runs no
code, but each tensor it rebuilds is a view, of any shape and strides, over a storage: a few bytes can stand for
10^12 weights (an expanded view, stride 0), a tensor can be a slice of a bigger storage, several can share one, and
a record can be compressed to a thousandth. So a model file is read in four steps, each refusing with a
``WeightsError`` that names the problem:

- ``read_torch``: the records, each checked not to expand past the caps before torch reads them;
- ``held_weights``: every tensor a plain dense one that owns its bytes; their bytes within the file's, counted;
- ``is_layers`` and ``check_implied``: the layers the file states at most ``MAX_HIDDEN_LAYERS`` of at most
  ``MAX_WIDTH`` units, and the weights they imply (``mlp_weights``, arithmetic) within ``MAX_PARAMETERS`` and the
  count held, before anything is built;
- ``network_state``: the policy built on the meta device (shapes, no memory), whose names, shapes and dtypes the
  weights must have (``check_fits``) before it is built for real.

    raw = path.read_bytes()
    weights = read_torch(raw, "policy.pth")
    held = held_weights(weights, "policy.pth", len(raw))   # number of weights
"""

from __future__ import annotations

import io
import zipfile
from itertools import pairwise
from pathlib import Path
from typing import Any

import torch

from predictor.plugins import describe_error

MAX_WEIGHTS_BYTES = 512 * 2**20  # a torch file of weights, and each record inside it [bytes]
MAX_RATIO = 100  # a compressed record may expand this many times [-] (torch and SB3 store theirs uncompressed)
SMALL_BYTES = 2**16  # a record this small is never a bomb, whatever its ratio [bytes]
MAX_HIDDEN_LAYERS = 64  # hidden layers of one network [-]
MAX_WIDTH = 4096  # units of one hidden layer [-] (the shipped policies' are 128; SB3's widest default, TD3's, 400)
MAX_PARAMETERS = 2**24  # weights of one policy, all its networks [-] (64 MiB in float32; the shipped hold 148 421)


class WeightsError(ValueError):
    """A model file's weights, or the network it states, refused; the message names the file (when known) and the
    problem, ``problem`` the problem alone."""

    def __init__(self, problem: str, path: Path | None = None):
        super().__init__(problem if path is None else f"{path}: {problem}")
        self.problem = problem


def check_expansion(info: zipfile.ZipInfo, limit_bytes: int, label: str) -> None:
    """Refuse a zip member (named ``label`` in the message) that declares more than ``limit_bytes`` or would expand
    more than ``MAX_RATIO`` times."""
    if info.file_size > limit_bytes:
        raise WeightsError(f"{label} declares {info.file_size} bytes, more than the {limit_bytes} a model file's "
                           "member may hold (a zip bomb?)")
    if info.file_size > max(MAX_RATIO * info.compress_size, SMALL_BYTES):
        raise WeightsError(f"{label} would expand from {info.compress_size} to {info.file_size} bytes, more than "
                           f"{MAX_RATIO} times (a zip bomb?)")


def read_torch(raw: bytes, label: str) -> Any:
    """What the torch file ``raw`` (named ``label``) holds, read with ``torch.load(weights_only=True)`` on the CPU.
    Torch's zip format is the only one taken, and its records are checked (``check_expansion``) before torch reads
    them."""
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as inner:
            records = inner.infolist()
    except (OSError, EOFError, RuntimeError, NotImplementedError, zipfile.BadZipFile) as err:
        raise WeightsError(f"{label} is not a torch file in its zip format ({describe_error(err)})") from None
    for info in records:
        check_expansion(info, MAX_WEIGHTS_BYTES, f"{label}'s record {info.filename[:60]!r}")
    if sum(info.file_size for info in records) > MAX_WEIGHTS_BYTES:
        raise WeightsError(f"{label}'s records declare more than {MAX_WEIGHTS_BYTES} bytes (a zip bomb?)")
    try:
        return torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as err:  # weights_only loads tensors and plain containers and refuses anything else, each its way
        raise WeightsError(f"{label} is not plain weights: torch.load(weights_only=True) refuses it "
                           f"({_torch_problem(err)})") from None


def _torch_problem(err: Exception) -> str:
    """The first sentence of what torch.load says is wrong (its messages run to paragraphs of advice)."""
    text = " ".join(str(err).split("WeightsUnpickler error:")[-1].split())
    return f"{type(err).__name__}: {text.split('. ')[0][:160]}"


def held_weights(state: Any, label: str, file_bytes: int) -> int:
    """Number of weights in the state dict ``state`` (name -> tensor) read from ``label``, a torch file of
    ``file_bytes`` bytes. Refused unless every tensor is a dense floating-point one on the CPU that owns its storage
    (contiguous, no stride 0, at offset 0, its storage exactly its elements' bytes, shared with no other tensor), and
    the bytes they hold are within the file's, ``MAX_WEIGHTS_BYTES`` and ``MAX_PARAMETERS`` weights."""
    if not (isinstance(state, dict) and all(isinstance(k, str) and isinstance(v, torch.Tensor)
                                            for k, v in state.items())):
        raise WeightsError(f"{label} holds a {type(state).__name__}, not a state dict of named tensors")
    owners: dict[int, str] = {}
    held_bytes = 0
    for key, tensor in state.items():
        problem = _not_own(tensor)
        storage = tensor.untyped_storage() if problem is None else None
        if storage is not None and storage.nbytes() and storage.data_ptr() in owners:
            problem = f"shares its storage with tensor {owners[storage.data_ptr()][:60]!r}, not weights of its own"
        if problem is not None:
            raise WeightsError(f"{label}: tensor {key[:60]!r} {problem}")
        owners[storage.data_ptr()] = key
        held_bytes += storage.nbytes()
    if held_bytes > min(file_bytes, MAX_WEIGHTS_BYTES):
        raise WeightsError(f"{label}'s tensors hold {held_bytes} bytes, more than its own {file_bytes} (or the "
                           f"{MAX_WEIGHTS_BYTES} a model file's weights may hold)")
    count = weights_in(state)
    if count > MAX_PARAMETERS:
        raise WeightsError(f"{label} holds {count} weights, more than the {MAX_PARAMETERS} a policy may hold")
    return count


def _not_own(tensor: torch.Tensor) -> str | None:
    """Why ``tensor`` is not dense floating-point weights that own their storage, or None if it is."""
    if tensor.layout != torch.strided:
        return f"is a {str(tensor.layout).removeprefix('torch.')} tensor, not dense weights"
    if tensor.device.type != "cpu":
        return f"is on the {tensor.device.type} device, not weights held in the file"
    if not tensor.is_floating_point():
        return f"is {_name(tensor.dtype)}, not floating-point weights"
    if 0 in tensor.stride():
        return "is an expanded view (stride 0), not weights held in the file"
    if not tensor.is_contiguous():
        return f"is not contiguous (strides {tensor.stride()} for shape {tuple(tensor.shape)}), not weights as " \
               "torch.save writes them"
    if tensor.storage_offset():
        return f"starts {tensor.storage_offset()} elements into its storage: a slice of a bigger one, not weights " \
               "of its own"
    own_bytes, storage_bytes = tensor.numel() * tensor.element_size(), tensor.untyped_storage().nbytes()
    if storage_bytes != own_bytes:
        return f"views {own_bytes} of its storage's {storage_bytes} bytes, not weights of its own"
    return None


def weights_in(state: dict[str, torch.Tensor]) -> int:
    """Number of numbers in a state dict (a tensor shared by two names counts twice, as a file holds it)."""
    return sum(tensor.numel() for tensor in state.values())


def is_layers(value: Any) -> bool:
    """Whether ``value`` is a network's hidden layers a file may state: a list of at most ``MAX_HIDDEN_LAYERS``
    widths from 1 to ``MAX_WIDTH``."""
    return (isinstance(value, list) and len(value) <= MAX_HIDDEN_LAYERS
            and all(isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_WIDTH for n in value))


def mlp_weights(inputs: int, widths: list[int]) -> int:
    """Weights and biases of a chain of linear layers of ``widths`` units on ``inputs`` numbers."""
    return sum((a + 1) * b for a, b in pairwise([inputs, *widths]))


def check_implied(implied: int, held: int, net_arch: Any, label: str) -> None:
    """Refuse a network whose layers ``net_arch`` imply (arithmetically, before anything is built) ``implied``
    weights, a lower bound of the whole policy's: more than ``MAX_PARAMETERS``, or than the ``held`` of ``label``."""
    shown = " ".join(str(net_arch).split())[:80]
    if implied > MAX_PARAMETERS:
        raise WeightsError(f"net_arch {shown} implies at least {implied} weights, more than the {MAX_PARAMETERS} a "
                           "policy may hold")
    if implied > held:
        raise WeightsError(f"net_arch {shown} needs at least {implied} weights, {label} holds {held}")


def network_state(policy_class: type, *args: Any, **kwargs: Any) -> dict[str, torch.Tensor]:
    """The state dict of the stable-baselines3 policy ``policy_class(*args, **kwargs)`` built on the meta device:
    names, shapes and dtypes, and no memory. (The policy's ``device`` is the meta one, where SB3 moves its parts;
    torch's distributions do not check arguments, which have no values there, while it is built.)"""
    meta = type(policy_class.__name__, (policy_class,), {"device": property(lambda _: torch.device("meta"))})
    validating = torch.distributions.Distribution._validate_args
    torch.distributions.Distribution.set_default_validate_args(False)
    try:
        with torch.device("meta"):
            return meta(*args, **kwargs).state_dict()
    finally:
        torch.distributions.Distribution.set_default_validate_args(validating)


def check_fits(weights: dict[str, torch.Tensor], network: dict[str, torch.Tensor], label: str, name: str) -> None:
    """Refuse the state dict ``weights`` (of ``label``) unless it holds as many weights as ``network`` (the state dict
    of the network ``name`` describes, from ``network_state``) with exactly its names, shapes and dtypes (at most
    three of each kind of difference named)."""
    held, needed = weights_in(weights), weights_in(network)
    if held != needed:
        raise WeightsError(f"{label} holds {held} weights, {name} holds {needed}")
    missing, extra = sorted(network.keys() - weights.keys()), sorted(weights.keys() - network.keys())
    common = [key for key in network if key in weights]
    shapes = [f"{key} {tuple(weights[key].shape)} (needs {tuple(network[key].shape)})" for key in common
              if weights[key].shape != network[key].shape]
    dtypes = [f"{key} {_name(weights[key].dtype)} (needs {_name(network[key].dtype)})" for key in common
              if weights[key].dtype != network[key].dtype]
    problems = ([f"missing {', '.join(missing[:3])}"] if missing else []) + (
        [f"unknown {', '.join(repr(key[:60]) for key in extra[:3])}"] if extra else []) + shapes[:3] + dtypes[:3]
    if problems:
        raise WeightsError(f"{label} does not fit {name}: {'; '.join(problems)}")


def _name(dtype: torch.dtype) -> str:
    """"float32" for torch.float32."""
    return str(dtype).removeprefix("torch.")
