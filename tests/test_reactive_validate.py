"""``python -m st_sim reactive-validate``: the JSON the issue asks for, the same intents for every model, blind
pedestrians walking exactly their intents, reactive ones never walking into a vehicle's body, seeded rollouts that
differ by pace and reaction, and one error line for bad flags and data."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from replays.citr import PED_SUFFIX, VEH_SUFFIX, find_experiments, on_grid
from replays.data_root import CITR, data_root
from st_sim.apps.cli import main
from st_sim.apps.reactive_validate import validate
from st_sim.apps.vehicle_cases import INTENT_STEPS, PACE_RANGE, Case, Variety, intents, rollout, score, walk
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import Spread, fitted_reaction

CITR_ROOT = data_root(dataset=CITR)  # $STCROWD_CITR in CI; missing: a failure
CART = Body(2.4, 1.2)
DRAWS = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def write_experiment(folder: Path, name: str, walkers: np.ndarray, vehicle: np.ndarray, heading: float,
                     speed: float, fps: float = 10.0) -> None:
    """An experiment in CITR's layout: walkers (F, W, 2) [m] and a vehicle (F, 2) [m] at every frame."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = [f"{w + 1},{f},ped,{float(x)!r},{float(y)!r},0,0" for w in range(walkers.shape[1])
            for f, (x, y) in enumerate(walkers[:, w])]
    (folder / f"{name}{PED_SUFFIX}").write_text("id,frame,label,x_est,y_est,vx_est,vy_est\n" + "\n".join(rows) + "\n")
    rows = [f"1,{f},veh,{float(x)!r},{float(y)!r},{float(heading)!r},{float(speed)!r}"
            for f, (x, y) in enumerate(vehicle)]
    (folder / f"{name}{VEH_SUFFIX}").write_text("id,frame,label,x_est,y_est,psi_est,vel_est\n" + "\n".join(rows) + "\n")


def crossing(seed: int, walkers: int, frames: int = 150, fps: float = 10.0) -> np.ndarray:
    """(F, W, 2) walkers at 1.0-1.4 m/s along +x, side by side round y = 0, starting 12-16 m before x = 0."""
    rng = np.random.default_rng(seed)
    start = np.c_[rng.uniform(-16, -12, walkers), np.linspace(-1.5, 1.5, walkers) + rng.normal(0, 0.1, walkers)]
    speed = rng.uniform(1.0, 1.4, walkers)
    t = np.arange(frames)[:, None] / fps
    return start + np.stack([speed * t, np.zeros_like(t * speed)], axis=-1)


def test_reactive_validate_writes_the_figures_of_every_model_on_citr(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture) -> None:
    """Two CITR experiments (one fitted on, one held out): the JSON holds what the issue names, per folder too."""
    data = tmp_path / "data"
    for name in ("vci_front/front_interaction_01", "vci_lat_bi/bidirection_normal_driving_02"):
        for suffix in (PED_SUFFIX, VEH_SUFFIX):
            (data / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(CITR_ROOT / f"{name}{suffix}", data / f"{name}{suffix}")
    out, chart = tmp_path / "out" / "validation.json", tmp_path / "out" / "validation.png"
    assert main(["reactive-validate", "--data", str(data), "--json", str(out), "--chart", str(chart), "--quiet"]) == 0
    result = json.loads(out.read_text())
    assert result["pedestrians"] == 16 and set(result["groups"]) == {"vci_front", "vci_lat_bi"}
    assert isinstance(result["recorded"]["min_clearance_m_median"], float)
    for model in ("blind", "reactive", "attentive"):
        figures = result["models"][model]
        assert {"ade_m", "min_clearance_m_median", "collisions"} <= set(figures), model
        assert figures["ade_m"] > 0 and figures["collisions"] >= 0
    assert result["models"]["blind"]["onset_gap_m_median"] is None, "blind pedestrians strayed from their intents"
    assert len(result["pedestrian_rows"]) == 16 and chart.stat().st_size > 0
    assert "vci_lat_bi (held out)" in capsys.readouterr().out


@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(1, 6), lateral=st.floats(-1.0, 1.0),
       heading=st.floats(-0.3, 0.3))
def test_every_model_starts_from_the_same_intents_and_blind_ones_walk_them(tmp_path_factory, seed: int, walkers: int,
                                                                           lateral: float, heading: float) -> None:
    folder = tmp_path_factory.mktemp("exp")
    people = crossing(seed, walkers)
    vehicle = np.c_[np.linspace(20.0, -20.0, len(people)), np.full(len(people), lateral)]
    write_experiment(folder, "run", people, vehicle, np.pi + heading, 40.0 / 15.0)
    grid = on_grid(find_experiments(folder, fps=10.0)[0], 0.4)
    intent = intents(grid, CART)
    assert len(intent.columns) == walkers, "a walker that came near the cart was not scored"
    for model in (None, fitted_reaction()):
        xy = walk(grid, intent, CART, model)
        for n, (begin, column) in enumerate(zip(intent.start, intent.columns, strict=True)):
            assert begin >= INTENT_STEPS and np.array_equal(xy[begin, n], grid.xy_m[begin, column])
            assert np.isnan(xy[:begin, n]).all()
        if model is None:
            assert np.array_equal(xy, intent.xy_m, equal_nan=True)


@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(1, 6), turn=st.floats(-np.pi, np.pi))
def test_a_standing_vehicle_is_walked_into_by_blind_pedestrians_never_by_reactive_ones(tmp_path_factory, seed: int,
                                                                                       walkers: int,
                                                                                       turn: float) -> None:
    """The safety rule with a vehicle's box: a cart standing across the walkers' way, turned any way."""
    folder = tmp_path_factory.mktemp("exp")
    people = crossing(seed, walkers)
    write_experiment(folder, "run", people, np.zeros((len(people), 2)), turn, 0.0)
    result = validate(find_experiments(folder, fps=10.0), CART, fitted_reaction(), progress=False)
    rows = result["pedestrian_rows"]
    assert all(row["reactive"]["min_clearance_m"] > 0.2 for row in rows), [r["reactive"] for r in rows]
    assert result["models"]["reactive"]["collisions"] == result["models"]["attentive"]["collisions"] == 0
    recorded = sum(row["recorded"]["collision"] for row in rows)  # the walkers walk straight: as blind ones do
    assert result["models"]["blind"]["collisions"] == recorded


@pytest.mark.parametrize("flags, message", [(["--fps", "0"], "--fps"), (["--vehicle-length", "-1"], "--vehicle-length"),
                                            (["--vehicle-width", "nan"], "--vehicle-width")],
                         ids=["fps", "length", "width"])
def test_bad_flags_give_one_error_line(tmp_path: Path, capsys: pytest.CaptureFixture, flags: list[str],
                                       message: str) -> None:
    assert main(["reactive-validate", "--data", str(CITR_ROOT), "--json", str(tmp_path / "v.json"), *flags]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: {message}") and err.count("\n") == 1, err
    assert not (tmp_path / "v.json").exists()


def test_bad_data_gives_one_error_line_naming_the_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["reactive-validate", "--data", str(tmp_path), "--json", str(tmp_path / "v.json")]) == 1
    assert "no vehicle recording" in capsys.readouterr().err
    write_experiment(tmp_path / "a", "run", crossing(0, 2), np.zeros((150, 2)), 0.0, 0.0)
    (tmp_path / "a" / f"run{PED_SUFFIX}").unlink()
    assert main(["reactive-validate", "--data", str(tmp_path), "--json", str(tmp_path / "v.json")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and f"run{VEH_SUFFIX}" in err and "without its pedestrian file" in err, err
    assert not (tmp_path / "v.json").exists()


def test_another_reaction_fit_is_validated_and_a_bad_one_is_one_error_line(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture) -> None:
    """``--reaction FIT`` gives the reactive pedestrians that fit's parameters (recorded in the JSON's settings); a
    file that is no fit is one error line before any data is read."""
    folder = tmp_path / "data"
    write_experiment(folder, "run", crossing(3, 3), np.c_[np.linspace(-8.0, 8.0, 150), np.zeros(150)], 0.0, 4.0)
    fit = json.loads((Path(__file__).parents[1] / "st_sim/reactive/reaction_fit.json").read_text())
    fit["params"]["aside_cost"] = 2.0
    (tmp_path / "fit.json").write_text(json.dumps(fit))
    out = tmp_path / "v.json"
    assert main(["reactive-validate", "--data", str(folder), "--fps", "10", "--reaction", str(tmp_path / "fit.json"),
                 "--json", str(out), "--quiet"]) == 0
    settings_ = json.loads(out.read_text())["settings"]
    assert settings_["reaction"]["aside_cost"] == 2.0 and settings_["reaction_file"] == str(tmp_path / "fit.json")
    (tmp_path / "bad.json").write_text('{"params": {}}')
    assert main(["reactive-validate", "--data", str(folder), "--reaction", str(tmp_path / "bad.json"),
                 "--json", str(tmp_path / "w.json")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: --reaction") and "bad.json" in err and "params.fov_deg" in err, err


def test_the_folders_a_fit_was_not_fitted_on_are_marked_held_out(tmp_path: Path) -> None:
    """docs/environments.md: with ``--reaction FIT``, the folders the file names as ``fitted_on`` are the fitted
    ones and every other folder is marked held out (``settings.held_out``)."""
    data = tmp_path / "data"
    for folder, seed in (("seen", 1), ("unseen", 2), ("also_unseen", 3)):
        write_experiment(data / folder, "run", crossing(seed, 2), np.c_[np.linspace(-8.0, 8.0, 150), np.zeros(150)],
                         0.0, 4.0)
    fit = json.loads((Path(__file__).parents[1] / "st_sim/reactive/reaction_fit.json").read_text())
    fit["fitted_on"] = ["seen"]
    (tmp_path / "fit.json").write_text(json.dumps(fit))
    out = tmp_path / "v.json"
    assert main(["reactive-validate", "--data", str(data), "--fps", "10", "--reaction", str(tmp_path / "fit.json"),
                 "--json", str(out), "--quiet"]) == 0
    assert sorted(json.loads(out.read_text())["settings"]["held_out"]) == ["also_unseen", "unseen"]


@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(1, 5), rollout_seed=st.integers(0, 2**31))
def test_rollouts_walk_the_same_paces_for_every_model_seeded_and_the_deterministic_walk_without_variety(
        tmp_path_factory, seed: int, walkers: int, rollout_seed: int) -> None:
    """A blind rollout walks each intent from its start at a pace within ``PACE_RANGE``; the same seed and index give
    the same rollout; another index other paces; zero sigmas give ``walk`` itself, blind and reactive."""
    folder = tmp_path_factory.mktemp("exp")
    people = crossing(seed, walkers)
    write_experiment(folder, "run", people, np.c_[np.linspace(20.0, -20.0, len(people)), np.zeros(len(people))],
                     np.pi, 40.0 / 15.0)
    grid = on_grid(find_experiments(folder, fps=10.0)[0], 0.4)
    intent = intents(grid, CART)
    case = Case("run", ".", grid, intent, score(grid, intent, grid.xy_m[:, intent.columns], CART))
    variety = Variety(0.2, Spread.even(0.3))
    first, again = (rollout(case, CART, None, 0, rollout_seed, variety) for _ in range(2))
    assert np.array_equal(first, again, equal_nan=True)
    steps = np.arange(len(grid.times_s))
    for n, begin in enumerate(intent.start):
        later = steps > begin
        walked = np.linalg.norm(first[later, n] - first[begin, n], axis=-1)
        meant = np.linalg.norm(intent.xy_m[later, n] - intent.xy_m[begin, n], axis=-1)
        pace = walked[-1] / meant[-1]
        assert PACE_RANGE[0] - 1e-9 <= pace <= PACE_RANGE[1] + 1e-9 and np.allclose(walked, pace * meant)
        assert np.array_equal(first[begin, n], grid.xy_m[begin, intent.columns[n]])
    assert not np.allclose(np.nan_to_num(rollout(case, CART, None, 1, rollout_seed, variety)), np.nan_to_num(first))
    for reaction in (None, fitted_reaction()):
        assert np.array_equal(rollout(case, CART, reaction, 3, rollout_seed, Variety(0.0, Spread())),
                              walk(grid, intent, CART, reaction), equal_nan=True)
