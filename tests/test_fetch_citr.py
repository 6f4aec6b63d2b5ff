"""CITR as a second data set: its root is resolved like ETH/UCY's ($STCROWD_CITR), fetched from its authors' GitHub
repository at a fixed commit (a local server laid out like raw.githubusercontent.com here) or from a local copy, and
every file checked against the project's SHA-256 sums (``replays/citr.sha256``)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from test_fetch import http_server

import replays.fetch as fetch_module
from replays.cli import main
from replays.data_root import CITR, ETH_UCY, data_root, expected_sums, modified_files, verify_data_root
from replays.errors import DataRootError
from replays.fetch import CITR_URL, FetchError, fetch, mirror_url

SHARED_CITR = data_root(dataset=CITR)  # $STCROWD_CITR in CI: the read-only reference copy
SUMS = expected_sums(CITR)
VICTIM = "vci_front/front_interaction_01_traj_ped_filtered.csv"
REPOSITORY_PATH = "dongfang-steven-yang/vci-dataset-citr/b6a980628f48e7c80c748c3e333979ca3a6b0301/" \
                  "data/trajectories_filtered/"


def test_the_citr_list_is_its_filtered_folder_and_differs_from_eth_ucy() -> None:
    assert len(SUMS) == 102 and VICTIM in SUMS
    assert sum(name.endswith("_traj_veh_filtered.csv") for name in SUMS) == 26
    assert not set(SUMS) & set(expected_sums(ETH_UCY))


def test_citr_files_come_from_the_authors_repository_at_commit_b6a9806() -> None:
    assert CITR_URL == "https://raw.githubusercontent.com/" + REPOSITORY_PATH
    assert mirror_url(VICTIM, CITR) == CITR_URL + VICTIM


def test_fetch_citr_from_a_server_laid_out_like_github(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    served = tmp_path / "github"
    for name in SUMS:
        (served / REPOSITORY_PATH / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(SHARED_CITR / name, served / REPOSITORY_PATH / name)
    with http_server(served) as url:
        monkeypatch.setattr(fetch_module, "CITR_URL", url + REPOSITORY_PATH)
        report = fetch(None, tmp_path / "dest", quiet=True, dataset=CITR)
        assert (report.fetched, report.skipped) == (len(SUMS), 0)
        verify_data_root(tmp_path / "dest", CITR)
        (served / REPOSITORY_PATH / VICTIM).write_bytes(b"id,frame\n")  # the repository changed under us
        (tmp_path / "dest" / VICTIM).unlink()
        with pytest.raises(FetchError, match=re.escape(VICTIM) + ".*SHA-256 mismatch"):
            fetch(None, tmp_path / "dest", quiet=True, dataset=CITR)
    assert not (tmp_path / "dest" / VICTIM).exists(), "a file that failed its check got its final name"


def test_fetch_and_verify_citr_on_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    dest = tmp_path / "citr"
    assert main(["fetch", "--dataset", "citr", "--from", str(SHARED_CITR), "--dest", str(dest), "--quiet"]) == 0
    assert main(["verify", "--dataset", "citr", "--root", str(dest)]) == 0
    assert "CITR" in capsys.readouterr().out
    (dest / VICTIM).write_text("id,frame,label,x_est,y_est,vx_est,vy_est\n1,1,ped,0,0,0,0\n")
    assert main(["verify", "--dataset", "citr", "--root", str(dest)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and VICTIM in err and "python -m replays fetch --dataset citr" in err, err


def test_the_citr_root_comes_from_the_argument_then_stcrowd_citr_then_the_cache(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("STCROWD_CITR", str(tmp_path / "env"))
    assert data_root(tmp_path / "arg", check=False, dataset=CITR) == (tmp_path / "arg").resolve()
    assert data_root(check=False, dataset=CITR) == (tmp_path / "env").resolve()
    monkeypatch.delenv("STCROWD_CITR")
    assert data_root(check=False, dataset=CITR) == (tmp_path / "home/.cache/stcrowd/citr").resolve()
    with pytest.raises(DataRootError, match=r"CITR data root .* is missing 102 of 102 files.*"
                                            r"python -m replays fetch --dataset citr.*STCROWD_CITR"):
        data_root(dataset=CITR)


def test_an_extra_recording_in_a_citr_folder_counts_as_a_change(tmp_path: Path) -> None:
    root = tmp_path / "citr"
    fetch(SHARED_CITR, root, quiet=True, dataset=CITR)
    assert modified_files(root, dataset=CITR) == {}
    shutil.copyfile(root / VICTIM, root / "vci_front" / "extra_traj_ped_filtered.csv")
    assert list(modified_files(root, dataset=CITR)) == ["vci_front/extra_traj_ped_filtered.csv"]


def test_citr_keeps_the_resume_modified_and_archive_rules_of_eth_ucy(tmp_path: Path) -> None:
    """docs/data.md, "CITR": the same resume, ``.modified`` and archive rules as ETH/UCY's."""
    import tarfile

    archive = tmp_path / "citr.tar.gz"
    with tarfile.open(archive, "w:gz", compresslevel=1) as tar:
        tar.add(SHARED_CITR, arcname="citr")  # a top folder, as a downloaded archive has
    dest = tmp_path / "dest"
    report = fetch(archive, dest, quiet=True, dataset=CITR)
    assert (report.fetched, report.skipped) == (len(SUMS), 0)
    (dest / VICTIM).write_text("edited\n")
    (dest / VICTIM).with_name(Path(VICTIM).name + ".modified").write_text("edited before\n")
    report = fetch(SHARED_CITR, dest, quiet=True, dataset=CITR)
    assert (report.fetched, report.skipped) == (1, len(SUMS) - 1), "checked files are skipped, the edited one again"
    assert (dest / (VICTIM + ".modified")).read_text() == "edited before\n"
    assert (dest / (VICTIM + ".modified.1")).read_text() == "edited\n", "the edit is kept beside the original"
    verify_data_root(dest, CITR)
