"""Errors for bad input that the core raises and the layers above share; each names the argument, field or file at
fault.

The environments raise these same classes: ``envs.common.errors.EnvInputError`` is ``InputError`` and
``envs.common.errors.ConfigError`` is ``ConfigError``, so ``except envs.common.errors.ConfigError`` catches what the
reactive pedestrians (``st_sim.reactive``) raise for a bad reaction, spread or fit file, and every one is a
``ValueError``. Every class takes the message as its only positional argument, so it pickles and survives
gymnasium's async vector env, which re-raises a worker's error as ``type(err)(err)``.
"""

from __future__ import annotations


class InputError(ValueError):
    """A constructor argument, config field, option, file or action is of the wrong kind or out of range (the base of
    the environments' errors: ``envs.common.errors.EnvInputError``)."""


class ConfigError(InputError):
    """A config dataclass field has the wrong type or a value outside its allowed range, or a fit file cannot be
    read (``envs.common.errors.ConfigError``)."""
