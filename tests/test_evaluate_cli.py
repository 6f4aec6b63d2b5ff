from __future__ import annotations

import json

import numpy as np
import pytest

from predictor.registry import MissingCheckpointError, make_predictor
from st_sim.apps.cli import main
from st_sim.apps.evaluate import SAMPLE_KEYS, aggregate, markdown_table
from st_sim.command_line import CliError
from st_sim.metrics import paired_bootstrap


def test_evaluate_cli_prints_table_and_writes_json(tmp_path, capsys):
    out = tmp_path / "res.json"
    assert main(["evaluate", "--task", "deterministic", "--predictor", "cvm", "--scenes", "eth", "hotel",
                 "--json", str(out), "--quiet", "--runs", str(tmp_path / "runs")]) == 0
    printed = capsys.readouterr().out
    assert "| eth | 181 |" in printed and "0.720 / 1.230" in printed  # paper numbers beside ours
    result = json.loads(out.read_text())
    assert set(result["scenes"]) == {"eth", "hotel"}
    assert result["scenes"]["hotel"]["samples"] == 1053
    assert 0.2 < result["avg"]["ade"] < 2.0 and result["avg"]["fde"] > result["avg"]["ade"]
    assert "paper_ade" not in result["avg"]  # a partial table is not compared with the paper's AVG


def test_missing_checkpoint_says_how_to_train_it(tmp_path, capsys):
    with pytest.raises(MissingCheckpointError, match="python -m predictor train --task domain --scene A2B --seed 1"):
        make_predictor("singular", "domain", "A2B", runs_dir=str(tmp_path), seed=1)  # none ships for a domain pair
    assert main(["evaluate", "--task", "domain", "--predictor", "singular", "--scenes", "A2B", "--no-train",
                 "--runs", str(tmp_path)]) == 1
    assert "error: 1 checkpoints are missing (domain/A2B/seed0); drop --no-train" in capsys.readouterr().err


def test_cli_errors_are_one_line_without_traceback(tmp_path, capsys):
    assert main(["evaluate", "--task", "stochastic", "--predictor", "cvm", "--scenes", "narnia", "--runs",
                 str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "narnia" in err and "Traceback" not in err
    with pytest.raises(CliError, match="--step 99999"):
        main(["--debug", "plot", "--scene", "hotel", "--step", "99999", "--predictor", "cvm"])


def test_seed_rows_are_the_mean_and_sample_sd_of_the_seeds():
    def cell(ade, fde):
        return {"samples": 10, "ade": ade, "fde": fde, "map_violation": 0.1, "path_map_violation": 0.2,
                "gt_map_violation": 0.0, "collision_rate": 0.0, "paper_ade": 0.3, "paper_fde": 0.5,
                "checkpoint": "x.pt", "stream_samples": 10}
    cells = {("eth", 0): cell(0.3, 0.5), ("eth", 1): cell(0.5, 0.7), ("hotel", 0): cell(0.1, 0.2),
             ("hotel", 1): cell(0.1, 0.4)}
    result = aggregate("stochastic", "singular", cells)
    assert result["scenes"]["eth"]["ade"] == pytest.approx(0.4)
    assert result["scenes"]["eth"]["ade_sd"] == pytest.approx(0.1414, abs=1e-4)  # n - 1 in the denominator
    assert result["avg"]["per_seed"]["1"]["fde"] == pytest.approx(0.55)
    assert result["avg"]["fde"] == pytest.approx((0.35 + 0.55) / 2)
    assert "paper_ade" not in result["avg"]  # two of five scenes: not compared with the paper's AVG
    assert "0.400 ± 0.141 / 0.600 ± 0.141" in markdown_table(result)


def test_evaluate_cli_out_folder_gets_json_and_markdown(tmp_path, capsys):
    assert main(["evaluate", "--task", "momentary", "--predictor", "linear", "--scenes", "zara1",
                 "--out", str(tmp_path), "--quiet", "--momentary-from-8", "--runs", str(tmp_path / "runs")]) == 0
    result = json.loads((tmp_path / "momentary.json").read_text())
    assert result["scenes"]["zara1"]["samples"] == 2253  # the 8-frame protocol's samples, scored on 2 frames
    assert result["momentary_protocol"] == "from-8"
    assert "| zara1 | 2253 |" in (tmp_path / "momentary.md").read_text()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != "runs") == ["momentary.json", "momentary.md"]


def test_plot_cli_writes_a_png(tmp_path):
    import cv2

    out = tmp_path / "fig.png"
    assert main(["plot", "--scene", "hotel", "--step", "3", "--predictor", "cvm-s", "--out", str(out)]) == 0
    image = cv2.imread(str(out))
    assert image is not None and image.shape[0] >= 576


def test_figures_command_writes_the_readme_figures_outside_docs(tmp_path):
    import cv2

    assert main(["figures", "--out", str(tmp_path)]) == 0
    for name in ("zara1_window120.png", "eth_window30.png"):
        assert cv2.imread(str(tmp_path / name)) is not None


@pytest.mark.parametrize("flag", ["--json", "--out"])
def test_unwritable_output_paths_fail_before_any_work(tmp_path, capsys, flag):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    target = blocker / "result.json" if flag == "--json" else blocker / "tables"
    assert main(["evaluate", "--task", "stochastic", "--predictor", "cvm", flag, str(target),
                 "--runs", str(tmp_path / "runs")]) == 1
    assert f"error: {blocker}" in capsys.readouterr().err
    assert not (tmp_path / "runs").exists()  # nothing was evaluated


def test_several_predictors_get_a_table_each_and_a_paired_comparison(tmp_path, capsys):
    runs = tmp_path / "runs"
    assert main(["evaluate", "--task", "deterministic", "--predictor", "cvm", "--scenes", "eth", "hotel",
                 "--no-stream", "--quiet", "--runs", str(runs)]) == 0
    cell = runs / "evaluations" / "deterministic" / "hotel" / "cvm-offline.json"
    old = {k: v for k, v in json.loads(cell.read_text()).items() if k not in SAMPLE_KEYS}
    assert len(json.loads(cell.read_text())["sample_fde"]) == 1053
    cell.write_text(json.dumps(old))  # a cell written before cells kept per-sample errors
    out = tmp_path / "res.json"
    assert main(["evaluate", "--task", "deterministic", "--predictor", "cvm", "linear", "--scenes", "eth", "hotel",
                 "--no-stream", "--quiet", "--runs", str(runs), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "predictor `cvm`" in printed and "predictor `linear`" in printed and "ΔFDE `linear`" in printed
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == [
        "res_comparison.json", "res_cvm.json", "res_linear.json"]
    tables = {name: json.loads((tmp_path / f"res_{name}.json").read_text()) for name in ("cvm", "linear")}
    assert not set(SAMPLE_KEYS) & set(tables["cvm"]["scenes"]["eth"]["seeds"]["0"]), "tables stay small"
    comparison = json.loads((tmp_path / "res_comparison.json").read_text())
    assert comparison["predictors"] == ["cvm", "linear"] and comparison["reference"] == "cvm"
    for scene in ("eth", "hotel"):
        row = comparison["scenes"][scene]
        delta = row["fde_difference"]["linear"]
        expected = tables["linear"]["scenes"][scene]["fde"] - tables["cvm"]["scenes"][scene]["fde"]
        assert abs(delta["mean"] - expected) < 1e-4, scene  # per-sample errors are rounded to 1e-5 m
        assert delta["low"] < delta["mean"] < delta["high"], scene
        assert row["fde"]["cvm"] == pytest.approx(tables["cvm"]["scenes"][scene]["fde"])
    avg = comparison["avg"]["fde_difference"]["linear"]
    assert avg["mean"] == pytest.approx(np.mean([comparison["scenes"][s]["fde_difference"]["linear"]["mean"]
                                                 for s in ("eth", "hotel")]))


def test_several_predictors_write_one_file_each_into_out_and_must_differ(tmp_path, capsys):
    assert main(["evaluate", "--task", "deterministic", "--predictor", "cvm", "linear", "--scenes", "eth",
                 "--no-stream", "--quiet", "--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "t")]) == 0
    assert sorted(p.name for p in (tmp_path / "t").iterdir()) == [
        f"deterministic_{name}.{ext}" for name in ("comparison", "cvm", "linear") for ext in ("json", "md")]
    assert "| **AVG** |" in (tmp_path / "t" / "deterministic_comparison.md").read_text()
    assert main(["evaluate", "--predictor", "cvm", "linear", "cvm", "--runs", str(tmp_path / "runs")]) == 1
    assert "error: --predictor cvm linear cvm: each must be given once" in capsys.readouterr().err


def test_paired_bootstrap_resamples_windows_and_is_seeded():
    rng = np.random.default_rng(1)
    constant = paired_bootstrap([np.full(50, 0.25)], [np.arange(50) // 5])
    assert constant == ([(0.25, 0.25, 0.25)], (0.25, 0.25, 0.25))
    iid = rng.normal(0.1, 1.0, 4000)
    [(_, low, high)], _ = paired_bootstrap([iid], [np.arange(4000)], seed=3)
    assert high - low == pytest.approx(2 * 1.96 * iid.std() / np.sqrt(4000), rel=0.1)
    assert paired_bootstrap([iid], [np.arange(4000)], seed=3) == paired_bootstrap([iid], [np.arange(4000)], seed=3)
    clustered = np.repeat(rng.normal(0.0, 1.0, 40), 100)  # 40 windows of 100 identical samples
    [(_, low_c, high_c)], _ = paired_bootstrap([clustered], [np.repeat(np.arange(40), 100)])
    assert high_c - low_c > 5 * (high - low), "samples of one window are not independent evidence"
    _, (mean, low_a, high_a) = paired_bootstrap([np.full(10, 1.0), np.full(30, 3.0)],
                                                [np.arange(10), np.arange(30)])
    assert mean == low_a == high_a == 2.0, "AVG is the mean over strata, not over samples"
