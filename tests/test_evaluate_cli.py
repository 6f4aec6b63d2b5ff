from __future__ import annotations

import json

from st_sim.cli import main


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
