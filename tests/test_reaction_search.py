"""Fitting the reaction and cross-validating the fitting (``st_sim.apps.reaction_search``): a fold's fit never sees
the folder it leaves out, fold fits are kept and reused only for the same procedure and data, the CV criterion, the
coarse grids and the variants; and ``reactive-validate --cross-validate`` writes the folds the issue names."""

from __future__ import annotations

import dataclasses
import json
import runpy
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from replays.citr import PED_SUFFIX, VEH_SUFFIX, find_experiments
from replays.data_root import CITR, data_root
from st_sim.apps.cli import main
from st_sim.apps.reaction_search import (
    CV_PROCEDURE,
    CV_TARGETS,
    FIRST_GUESS,
    GRIDS,
    ROOM_FIELDS,
    SUB_GOAL_GRIDS,
    VARIANTS,
    Fit,
    Procedure,
    Scorer,
    cross_validate,
    cv_criterion,
    cv_score,
    fold_fit,
    loss,
    model_of,
    search,
)
from st_sim.apps.sim_agents import WEIGHTS
from st_sim.apps.subgoal_force import SubGoalForce
from st_sim.apps.vehicle_cases import cases
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import fitted_reaction

CITR_ROOT = data_root(dataset=CITR)  # $STCROWD_CITR in CI; missing: a failure
CART = Body(2.4, 1.2)
EXPERIMENTS = ("vci_front/front_interaction_01", "vci_back/back_interaction_01")  # 8 pedestrians each
TINY = Procedure("reactive", FIRST_GUESS, ("clearance_m",), sweeps=2, coarse=True)


@pytest.fixture(scope="module")
def two_folders(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One CITR experiment from each of two vehicle folders."""
    data = tmp_path_factory.mktemp("citr")
    for name in EXPERIMENTS:
        for suffix in (PED_SUFFIX, VEH_SUFFIX):
            (data / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(CITR_ROOT / f"{name}{suffix}", data / f"{name}{suffix}")
    return data


@pytest.fixture(scope="module")
def scorer(two_folders: Path) -> Scorer:
    return Scorer(cases(find_experiments(two_folders), CART), CART)


def test_a_fold_fit_never_sees_the_folder_it_leaves_out(scorer: Scorer, tmp_path: Path) -> None:
    """Each fold's fit is the search on the other folders, exactly as a scorer that never read the folder left out
    finds it; the search never ends above where it started."""
    fits = cross_validate(scorer, TINY, tmp_path, progress=False)
    assert set(fits) == set(scorer.groups) == {"vci_back", "vci_front"}
    for held_out, fit in fits.items():
        training = [group for group in scorer.groups if group != held_out]
        assert list(fit.fitted_on) == training and held_out not in fit.figures
        blind_to_it = Scorer(scorer.of(training), CART)
        alone = search(blind_to_it, training, TINY, progress=False, log=False)
        assert alone.reaction == fit.reaction and alone.loss == pytest.approx(fit.loss)
        assert fit.loss <= loss(blind_to_it.figures(training, TINY.first)) + 1e-12
        assert (tmp_path / f"reactive-clearance-tolerance-0-on-{'+'.join(training)}.json").is_file()


def test_fold_fits_are_reused_for_the_same_procedure_and_data_only(scorer: Scorer, tmp_path: Path) -> None:
    training = ["vci_back"]
    fit = fold_fit(scorer, training, TINY, tmp_path, progress=False)
    path = tmp_path / "reactive-clearance-tolerance-0-on-vci_back.json"

    def mark() -> None:  # a mark in the kept fit: read back if reused, gone if searched again
        kept = json.loads(path.read_text())
        kept["params"]["clearance_m"] = 9.0
        path.write_text(json.dumps(kept))

    mark()
    assert fold_fit(scorer, training, TINY, tmp_path, progress=False).reaction.clearance_m == 9.0
    other = dataclasses.replace(TINY, sweeps=1)  # another procedure: searched again, written over
    assert fold_fit(scorer, training, other, tmp_path, progress=False).reaction.clearance_m != 9.0
    assert json.loads(path.read_text())["key"]["procedure"]["sweeps"] == 1
    mark()
    wider = Body(3.0, 1.5)  # other data under the same folder names (here a wider vehicle): searched again
    assert fold_fit(Scorer(scorer.cases, wider), training, other, tmp_path,
                    progress=False).reaction.clearance_m != 9.0
    path.write_text("{ not json")  # a damaged file: searched again
    assert fold_fit(scorer, training, TINY, tmp_path, progress=False).reaction == fit.reaction


@settings(max_examples=100, deadline=None)
@given(ratios=st.lists(st.floats(0.1, 3.0), min_size=1, max_size=4), errors=st.data(),
       tolerance=st.floats(0.0, 1.0), collisions=st.integers(0, 3))
def test_the_loss_charges_clearance_errors_beyond_the_tolerance_only(ratios: list[float], errors: st.DataObject,
                                                                    tolerance: float, collisions: int) -> None:
    """Per folder, the ADE ratio plus the relative clearance error beyond the tolerance; a larger tolerance never
    costs more; errors within it cost nothing; collisions cost alike whatever the tolerance."""
    relative = errors.draw(st.lists(st.floats(-0.9, 2.0), min_size=len(ratios), max_size=len(ratios)))
    per_group = {f"f{i}": {"ade_ratio": r, "clearance_m": 2.0 * (1.0 + e), "recorded_clearance_m": 2.0,
                           "collisions": collisions if i == 0 else 0, "pedestrians": 10}
                 for i, (r, e) in enumerate(zip(ratios, relative, strict=True))}
    crashes = 10.0 * collisions / (10 * len(ratios))
    expected = np.mean([r + max(abs(e) - tolerance, 0.0) for r, e in zip(ratios, relative, strict=True)]) + crashes
    assert loss(per_group, tolerance) == pytest.approx(expected)
    assert loss(per_group, tolerance) <= loss(per_group) + 1e-12
    assert loss(per_group, tolerance + 0.1) <= loss(per_group, tolerance) + 1e-12
    within = max(abs(e) for e in relative)
    assert loss(per_group, within) == pytest.approx(np.mean(ratios) + crashes)


def test_the_clearance_tolerance_is_part_of_the_procedure_its_fold_fits_and_their_files(scorer: Scorer,
                                                                                         tmp_path: Path) -> None:
    """Fits of two tolerances are kept apart (file and key); a fit's loss is its procedure's; a tolerance that is
    negative or not finite is refused."""
    tolerant = dataclasses.replace(TINY, clearance_tolerance=0.25)
    assert tolerant.name == "reactive-clearance-tolerance-0.25" and tolerant.record()["clearance_tolerance"] == 0.25
    fits = {procedure: fold_fit(scorer, ["vci_back"], procedure, tmp_path, progress=False)
            for procedure in (TINY, tolerant)}
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "reactive-clearance-tolerance-0-on-vci_back.json", "reactive-clearance-tolerance-0.25-on-vci_back.json"]
    for procedure, fit in fits.items():
        assert fit.loss == pytest.approx(loss(scorer.figures(["vci_back"], fit.reaction),
                                              procedure.clearance_tolerance))
    for bad in (-0.1, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="clearance tolerance"):
            dataclasses.replace(TINY, clearance_tolerance=bad)


def test_fit_reaction_chooses_the_candidate_of_the_lowest_cv_criterion_and_fits_it_on_every_folder(
        two_folders: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``benchmarks/fit_reaction.py --cross-validate`` over two clearance tolerances: both candidates' CV scores are
    written, the one chosen has the lowest criterion (ties: mean), and the fit written is its procedure's on every
    folder."""
    out = tmp_path / "fit.json"
    monkeypatch.setattr(sys, "argv", ["fit_reaction.py", "--data", str(two_folders), "--cross-validate",
                                      "--clearance-tolerances", "0", "0.25", "--search", "clearance_m",
                                      "--fold-fits", str(tmp_path / "folds"), "--out", str(out)])
    runpy.run_path(str(Path(__file__).resolve().parents[1] / "benchmarks" / "fit_reaction.py"), run_name="__main__")
    table = json.loads(out.read_text())
    scores = table["cross_validation"]
    assert set(scores) == {"reactive-clearance-tolerance-0", "reactive-clearance-tolerance-0.25"}
    assert table["chosen"] == min(scores, key=lambda name: (scores[name]["criterion"], scores[name]["mean_ade_ratio"]))
    assert table["procedure"]["clearance_tolerance"] == scores[table["chosen"]]["clearance_tolerance"]
    assert table["fitted_on"] == ["vci_back", "vci_front"] and table["held_out"] == []
    for score in scores.values():
        assert set(score["folds"]) == {"vci_back", "vci_front"}
        assert score["criterion"] == pytest.approx(cv_criterion(score["mean_ade_ratio"], score["worst_ade_ratio"]))


def test_a_fit_reads_back_as_written() -> None:
    fit = Fit(FIRST_GUESS, {"a": {"ade_ratio": 0.9}}, 1.25, 7, ("a", "b"))
    assert Fit.from_record(json.loads(json.dumps(fit.record()))) == fit


@settings(max_examples=100, deadline=None)
@given(ratios=st.lists(st.floats(0.0, 3.0), min_size=1, max_size=6))
def test_the_cv_criterion_is_at_most_one_exactly_where_both_targets_hold(ratios: list[float]) -> None:
    score = cv_score({f"fold{i}": r for i, r in enumerate(ratios)})
    assert score["mean_ade_ratio"] == pytest.approx(np.mean(ratios)) and score["worst_ade_ratio"] == max(ratios)
    assert score["held_out_ade_ratios"][score["worst_fold"]] == max(ratios)
    met = score["mean_ade_ratio"] <= CV_TARGETS[0] and score["worst_ade_ratio"] <= CV_TARGETS[1]
    assert (score["criterion"] <= 1.0) == met
    assert cv_criterion(0.8, 0.9) == 1.0 and cv_criterion(0.4, 0.9) == 1.0
    assert cv_criterion(0.88, 0.9) == pytest.approx(1.1) and cv_criterion(0.4, 1.8) == pytest.approx(2.0)


def test_coarse_grids_keep_every_other_value_and_the_last_and_variants_skip_the_fields_they_hold() -> None:
    for name, axes in GRIDS.items():
        for full, coarse in zip(axes, CV_PROCEDURE.axes(name), strict=True):
            assert set(coarse) <= set(full) and coarse[0] == full[0] and coarse[-1] == full[-1]
            assert len(coarse) == len(full) if len(full) <= 3 else len(coarse) <= len(full) // 2 + 2
    attentive = dataclasses.replace(CV_PROCEDURE, variant="attentive")
    assert "fov_deg+hearing_m" not in attentive.grids and "reaction_s" not in attentive.grids
    assert all(getattr(attentive.first, key) == value for key, value in VARIANTS["attentive"].holds.items())
    with pytest.raises(ValueError, match="variant 'careless'"):
        Procedure("careless", FIRST_GUESS, (), 1)
    with pytest.raises(ValueError, match="grid 'speed'"):
        Procedure("reactive", FIRST_GUESS, ("speed",), 1)


@settings(max_examples=30, deadline=None)
@given(order=st.permutations(list(GRIDS)), start=st.tuples(*[st.sampled_from(GRIDS["head_on_s"][0])] * 3))
def test_one_room_searches_the_room_once_and_keeps_it_equal_whichever_way_the_vehicle_comes(
        order: list[str], start: tuple[float, float, float]) -> None:
    procedure = Procedure("one-room", dataclasses.replace(FIRST_GUESS, **dict(zip(ROOM_FIELDS, start, strict=True))),
                          tuple(order), 1, coarse=True)
    room_grids = [name for name in procedure.grids if set(name.split("+")) & set(ROOM_FIELDS)]
    assert room_grids == [ROOM_FIELDS[0]]
    assert [name for name in procedure.grids if name not in room_grids] == \
        [name for name in order if not set(name.split("+")) & set(ROOM_FIELDS)]
    assert len({getattr(procedure.first, field) for field in ROOM_FIELDS}) == 1
    assert getattr(procedure.first, ROOM_FIELDS[0]) == pytest.approx(np.mean(start))
    for values in procedure.axes(ROOM_FIELDS[0])[0]:
        assert procedure.changes(ROOM_FIELDS[0], (values,)) == dict.fromkeys(ROOM_FIELDS, values)


def test_a_one_room_fit_ends_with_one_room(scorer: Scorer) -> None:
    procedure = Procedure("one-room", FIRST_GUESS, ("clearance_m", *ROOM_FIELDS), sweeps=1, coarse=True)
    fit = search(scorer, scorer.groups, procedure, progress=False, log=False)
    assert len({getattr(fit.reaction, field) for field in ROOM_FIELDS}) == 1
    assert fit.loss <= loss(scorer.figures(scorer.groups, procedure.first)) + 1e-12


def test_the_sub_goal_family_is_searched_on_its_own_grids_and_its_fits_read_back(scorer: Scorer) -> None:
    procedure = dataclasses.replace(CV_PROCEDURE, variant="sub-goal")
    assert procedure.grids == list(SUB_GOAL_GRIDS) and procedure.first == SubGoalForce()
    tiny = dataclasses.replace(procedure, coarse=True, sweeps=1)
    fit = search(scorer, scorer.groups, tiny, progress=False, log=False)
    assert isinstance(fit.reaction, SubGoalForce)
    assert fit.loss <= loss(scorer.figures(scorer.groups, SubGoalForce()), tiny.clearance_tolerance) + 1e-12
    assert Fit.from_record(json.loads(json.dumps(fit.record()))) == fit
    assert model_of(dataclasses.asdict(FIRST_GUESS)) == FIRST_GUESS


def test_reactive_validate_cross_validates_and_scores_realism(two_folders: Path, scorer: Scorer, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture) -> None:
    """``--cross-validate`` (fold fits read from --fold-fits, as a run of the same procedure left them) and
    ``--no-refit``, both with ``--realism``: the JSON holds ``folds`` with the keys the issue names, the mean and
    worst held-out ratio, and realism per model, per fold too."""
    fits = tmp_path / "fits"
    planted = {}
    for index, held_out in enumerate(scorer.groups):  # what a finished run of CV_PROCEDURE leaves there
        training = [group for group in scorer.groups if group != held_out]
        reaction = dataclasses.replace(FIRST_GUESS, clearance_m=0.1 * (index + 1))
        key = {"procedure": CV_PROCEDURE.record(), "fitted_on": training, "data": scorer.digest(training),
               "start_walks": scorer.walks_digest(training, CV_PROCEDURE.first)}
        record = Fit(reaction, {}, 1.0, 1, tuple(training)).record()
        fits.mkdir(exist_ok=True)
        (fits / f"{CV_PROCEDURE.name}-on-{'+'.join(training)}.json").write_text(json.dumps({"key": key, **record}))
        planted[held_out] = reaction
    for refit in (True, False):  # the realism score with one rollout, refitted only: the plumbing, not the figures
        out = tmp_path / f"cv-{refit}.json"
        flags = ["--fold-fits", str(fits), "--realism", "--rollouts", "1", "--chart", str(tmp_path / "c.png")]
        assert main(["reactive-validate", "--data", str(two_folders), "--json", str(out), "--cross-validate",
                     *(flags if refit else ["--no-refit"]), "--quiet"]) == 0
        result = json.loads(out.read_text())
        assert [fold["held_out"] for fold in result["folds"]] == scorer.groups
        for fold in result["folds"]:
            for model in ("blind", "reactive"):
                assert {"ade_m", "min_clearance_m_median", "collisions"} <= set(fold["models"][model])
                if refit:
                    assert set(fold["realism"][model]) == {"meta", "features", "min_ade_m"}
                    assert set(fold["realism"][model]["features"]) == set(WEIGHTS)
                    assert 0.0 <= fold["realism"][model]["meta"] <= 1.0
            assert isinstance(fold["recorded"]["min_clearance_m_median"], float)
            reaction = planted[fold["held_out"]] if refit else fitted_reaction()
            assert fold["reaction"] == dataclasses.asdict(reaction)
            assert fold["unseen"] == (refit or fold["held_out"] == "vci_lat_bi"), "the shipped fit saw vci_back"
        ratios = [fold["models"]["reactive"]["ade_m"] / fold["models"]["blind"]["ade_m"] for fold in result["folds"]]
        cv = result["cross_validation"]
        assert cv["mean_ade_ratio"] == pytest.approx(np.mean(ratios)) and cv["worst_ade_ratio"] == max(ratios)
        assert cv["refit"] == refit and ("realism" in result) == refit
        assert result["models"]["attentive"]["ade_m"] > 0, "the command's own keys stay"
    assert set(json.loads((tmp_path / "cv-True.json").read_text())["realism"]) == {"blind", "reactive"}
    assert (tmp_path / "c-scores.png").stat().st_size > 0
    printed = capsys.readouterr().out
    assert "held-out ADE ratio: mean" in printed and "| reactive |" in printed
    assert "vci_back (seen by the fit)" in printed


@pytest.mark.parametrize("flags, message", [
    (["--no-refit"], "--no-refit goes with --cross-validate"),
    (["--realism", "--pace-sigma", "-0.1"], "--pace-sigma"),
    (["--realism", "--trait-sigma", "nan"], "--trait-sigma"),
    (["--realism", "--trait-sigma", "2.5"], "--trait-sigma")], ids=["no-refit", "pace", "traits", "traits-wide"])
def test_bad_cross_validation_and_realism_flags_give_one_error_line(two_folders: Path, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture, flags: list[str],
                                                                   message: str) -> None:
    assert main(["reactive-validate", "--data", str(two_folders), "--json", str(tmp_path / "v.json"), *flags]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: {message}") and err.count("\n") == 1, err


@pytest.mark.parametrize("tolerance", ["-0.25", "inf", "a quarter"])
def test_a_bad_clearance_tolerance_is_refused_by_the_parser_naming_the_flag(two_folders: Path, tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture,
                                                                           tolerance: str) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["reactive-validate", "--data", str(two_folders), "--json", str(tmp_path / "v.json"), "--cross-validate",
              "--clearance-tolerance", tolerance])
    assert exit_.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "argument --clearance-tolerance" in last and tolerance in last, last
    assert not (tmp_path / "v.json").exists()


def test_cross_validating_one_folder_is_one_error_line(two_folders: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture) -> None:
    assert main(["reactive-validate", "--data", str(two_folders / "vci_front"), "--json", str(tmp_path / "v.json"),
                 "--cross-validate", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "--cross-validate needs at least two folders" in err and err.count("\n") == 1, err
    assert not (tmp_path / "v.json").exists()
