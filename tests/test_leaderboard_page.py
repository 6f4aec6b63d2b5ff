"""The leaderboard page's figures from the committed results: each policy's worst scenarios with the commands that
record and replay them, and the per-scenario small multiples."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from st_sim.apps.navigation.leaderboard import BASELINES_DIR, load_result
from st_sim.apps.navigation.leaderboard_page import main, worst_scenarios, worst_table
from st_sim.charts import ScatterPoint, small_multiples

FOLDERS = sorted(path for path in BASELINES_DIR.iterdir() if path.is_dir())


def test_the_worst_scenarios_are_the_least_successful_with_commands_that_find_them() -> None:
    results = [load_result(folder) for folder in FOLDERS]
    table = worst_table(FOLDERS, results).splitlines()
    assert len(table) == 2 + len(FOLDERS)
    for folder, result, row in zip(FOLDERS, results, table[2:], strict=True):
        worst = worst_scenarios(result)
        success = {s["name"]: s["summary"]["success"]["value"] for s in result["scenarios"]}
        assert len(worst) == 3 and max(success[s["name"]] for s in worst) <= min(
            value for name, value in success.items() if name not in {s["name"] for s in worst})
        assert f"--policy {result['policy']} --predictor {result['predictor']} --scenarios " in row
        assert "--record failures" in row
        failed = [line for line in worst[0]["episodes"] if not line["success"]]
        if failed:
            assert f"episode results/benchmark/{folder.name} {worst[0]['name']} {failed[0]['episode']}" in row


def test_the_page_figures_are_written(tmp_path: Path) -> None:
    assert main([str(FOLDERS[0]), str(FOLDERS[-1]), "--chart", str(tmp_path / "s.png"),
                 "--out", str(tmp_path / "w.md")]) == 0
    assert (tmp_path / "s.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len((tmp_path / "w.md").read_text().splitlines()) == 4


def test_small_multiples_refuses_an_empty_panel_and_a_point_outside_its_interval() -> None:
    with pytest.raises(ValueError, match="panel 'b' has no point"):
        small_multiples("x", "y", {"a": [ScatterPoint("p", 0.5, 0.5)], "b": []})
    with pytest.raises(ValueError, match="outside its interval"):
        small_multiples("x", "y", {"a": [ScatterPoint("p", 0.5, 0.5, (0.6, 0.7))]})
    figure = small_multiples("x", "y", {f"s{k}": [ScatterPoint(name, v, v) for name, v in (("p", 0.2), ("q", 0.8))]
                                        for k in range(7)}, columns=3)
    visible = [ax for ax in figure.axes if ax.get_visible() and ax.get_title()]
    assert [ax.get_title() for ax in visible] == [f"s{k}" for k in range(7)]
    assert np.allclose(visible[0].get_xlim(), (-0.05, 1.05))
