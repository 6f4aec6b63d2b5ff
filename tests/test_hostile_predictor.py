"""Hostile inputs to the predictor: configurations and damaged checkpoints either work or raise the project's own
error naming the field or file; never a crash from deep inside torch, never a silently different model."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from predictor.checkpoint import CheckpointError, load
from predictor.model import ModelConfig
from predictor.train import TrainConfig

ANY_VALUE = st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=True),
                      st.text(max_size=8), st.lists(st.integers(), max_size=2))


@pytest.mark.parametrize("config", [TrainConfig, ModelConfig])
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_any_config_value_works_or_names_the_field(config, data):
    name = data.draw(st.sampled_from([f.name for f in fields(config)]))
    value = data.draw(ANY_VALUE)
    try:
        cfg = config(**{name: value})
    except ValueError as err:
        assert f"{config.__name__}.{name}=" in str(err)
        return
    checked = getattr(cfg, name)
    assert not isinstance(checked, float) or math.isfinite(checked)
    if config is ModelConfig:
        cfg.refiner_config()  # an accepted configuration builds


def test_a_width_that_the_heads_do_not_divide_names_both_fields():
    """Found by the property test above: heads=3 was refused naming only dim."""
    for kwargs in ({"heads": 3}, {"dim": 30}):
        with pytest.raises(ValueError, match=r"ModelConfig\.dim=\d+, ModelConfig\.heads=\d+"):
            ModelConfig(**kwargs)


@pytest.fixture(scope="module")
def shipped_bytes() -> bytes:
    from predictor.checkpoint import pretrained_manifest

    entry = pretrained_manifest()["checkpoints"]["stochastic/hotel"]
    from importlib import resources

    return resources.files("predictor").joinpath("pretrained", entry["file"]).read_bytes()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_damaged_checkpoint_bytes_are_refused_or_load_the_same_model(shipped_bytes, tmp_path_factory, data):
    damaged = bytearray(shipped_bytes)
    how = data.draw(st.sampled_from(["flip", "truncate", "zero-block"]))
    if how == "truncate":
        damaged = damaged[: data.draw(st.integers(0, len(damaged) - 1))]
    elif how == "flip":
        for _ in range(data.draw(st.integers(1, 8))):
            at = data.draw(st.integers(0, len(damaged) - 1))
            damaged[at] ^= 1 << data.draw(st.integers(0, 7))
    else:
        at = data.draw(st.integers(0, len(damaged) - 64))
        damaged[at:at + 64] = bytes(64)
    path = tmp_path_factory.mktemp("damaged") / "model.pt"
    path.write_bytes(bytes(damaged))
    try:
        model = load(path)
    except CheckpointError as err:
        assert str(path) in str(err)
        return
    original = tmp_path_factory.mktemp("original") / "model.pt"
    original.write_bytes(shipped_bytes)
    obs = np.cumsum(np.full((3, 8, 2), 0.4, np.float32), axis=1)
    group = np.zeros(3, np.int64)
    np.testing.assert_array_equal(model.predict(obs, group, None, 20), load(original).predict(obs, group, None, 20))
