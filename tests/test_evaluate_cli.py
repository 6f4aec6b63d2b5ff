from __future__ import annotations

import json

from st_sim.apps.cli import main


def test_evaluate_cli_prints_table_and_writes_json(tmp_path, capsys):
    out = tmp_path / "res.json"
    assert main(["evaluate", "--task", "deterministic", "--predictor", "cvm", "--scenes", "eth", "hotel",
                 "--json", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "| eth | 181 |" in printed and "0.720 / 1.230" in printed  # paper numbers beside ours
    result = json.loads(out.read_text())
    assert set(result["scenes"]) == {"eth", "hotel"}
    assert result["scenes"]["hotel"]["samples"] == 1053
    assert 0.2 < result["avg"]["ade"] < 2.0 and result["avg"]["fde"] > result["avg"]["ade"]
    assert "paper_ade" not in result["avg"]  # a partial table is not compared with the paper's AVG


def test_missing_checkpoint_says_how_to_train_it(tmp_path):
    import pytest

    from predictor.registry import make_predictor

    with pytest.raises(FileNotFoundError, match="--train-missing"):
        make_predictor("singular", "deterministic", "eth", runs_dir=str(tmp_path))  # none ships for S = 1


def test_evaluate_cli_out_folder_gets_json_and_markdown(tmp_path, capsys):
    assert main(["evaluate", "--task", "momentary", "--predictor", "linear", "--scenes", "zara1",
                 "--out", str(tmp_path), "--quiet", "--momentary-from-8"]) == 0
    result = json.loads((tmp_path / "momentary.json").read_text())
    assert result["scenes"]["zara1"]["samples"] == 2253  # the 8-frame protocol's samples, scored on 2 frames
    assert result["momentary_protocol"] == "from-8"
    assert "| zara1 | 2253 |" in (tmp_path / "momentary.md").read_text()


def test_plot_cli_writes_a_png(tmp_path):
    import cv2

    out = tmp_path / "fig.png"
    assert main(["plot", "--scene", "hotel", "--step", "3", "--predictor", "cvm-s", "--out", str(out)]) == 0
    image = cv2.imread(str(out))
    assert image is not None and image.shape[0] >= 576
