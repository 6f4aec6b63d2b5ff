"""Errors an environment raises for bad input or misuse; each names the argument, field or option at fault.

Every class takes the message as its only positional argument, so it pickles and survives gymnasium's async
vector env, which re-raises a worker's error as ``type(err)(err)``. ``EnvInputError`` and ``ConfigError`` are the
st_sim core's classes (``st_sim.errors``), so that what the reactive pedestrians (``st_sim.reactive``) raise for a
bad reaction, spread or fit file is a ``ConfigError`` too.
"""

from __future__ import annotations

from gymnasium.error import ResetNeeded

from st_sim import errors as _core

EnvInputError = _core.InputError
"""A constructor argument, config field, reset option or action is of the wrong kind or out of range (a
``ValueError``; the class ``st_sim.errors.InputError``)."""

ConfigError = _core.ConfigError
"""A config dataclass field has the wrong type or a value outside its allowed range (an ``EnvInputError``; the class
``st_sim.errors.ConfigError``, which the reactive pedestrians raise for a bad reaction, spread or fit file)."""


class ResetOptionsError(EnvInputError):
    """``reset(options=...)`` holds an unknown key or a value of the wrong type or range."""


class ActionError(EnvInputError):
    """The action is not an ego velocity: wrong dtype (complex, text, bool, object), shape, or NaN/inf."""


class EgoPlacementError(EnvInputError):
    """The ego starts, or has been put, off the walkable map or off the scene's image."""


class NeedsResetError(ResetNeeded):
    """``step`` before the first ``reset``, or after the episode ended (terminated, or the recording ended)."""


class AutoresetError(RuntimeError):
    """A sub-env of a batch could not start its next episode inside ``step`` (its reset or its seed function
    failed); the message names the sub-envs and their seeds. The batch refuses to step until it is reset."""
