from __future__ import annotations

import json

import pytest

from predictor.registry import MissingCheckpointError, make_predictor
from st_sim.apps.cli import main
from st_sim.apps.evaluate import aggregate, markdown_table
from st_sim.command_line import CliError


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
