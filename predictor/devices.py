"""Where torch runs: a device name checked and resolved ("auto": a CUDA GPU when torch sees one, else the CPU)."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

DEVICE_HELP = "auto (a CUDA GPU when torch sees one, else the CPU), cpu, cuda, cuda:N or mps"


DEVICE_NAME = re.compile(r"auto|cpu|cuda(:\d+)?|mps")


class DeviceError(ValueError):
    """A device name torch does not know, or a device this machine does not have."""


def check_device_name(name: object) -> str:
    """``name`` if it is one of ``DEVICE_HELP``'s forms (checked without importing torch; ``resolve_device`` then
    checks that the device is here); raises ``DeviceError`` otherwise."""
    if not isinstance(name, str) or not DEVICE_NAME.fullmatch(name):
        raise DeviceError(f"device={name!r}: expected {DEVICE_HELP}")
    return name


def resolve_device(name: str | torch.device) -> torch.device:
    """The torch device for ``name`` (see ``DEVICE_HELP``).

    Raises:
        DeviceError: an unknown name, or a GPU that torch cannot use here (the message says why).
    """
    import torch

    name = check_device_name(str(name) if isinstance(name, torch.device) else name)
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(name)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            built = "a CPU-only build" if not torch.backends.cuda.is_built() else "a build with CUDA, but no GPU here"
            raise DeviceError(f"device={name!r}: torch {torch.__version__} sees no CUDA GPU ({built}); use "
                              "device='cpu' or 'auto'")
        if device.index is not None and device.index >= torch.cuda.device_count():
            raise DeviceError(f"device={name!r}: this machine has {torch.cuda.device_count()} CUDA GPU(s)")
    elif device.type == "mps" and not torch.backends.mps.is_available():
        raise DeviceError(f"device={name!r}: torch sees no Apple GPU (MPS) here; use device='cpu' or 'auto'")
    return device
