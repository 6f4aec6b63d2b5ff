"""Data-root resolution (argument > $STCROWD_DATA > default cache) and its checks."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from replays.data_root import ENV_VAR, data_root, expected_sums, verify_data_root
from replays.errors import DataRootError

SHARED = data_root()  # $STCROWD_DATA in CI
SUMS = expected_sums()
VICTIM = "homography/crowds_zara01_H.txt"


def linked_layout(dst: Path) -> Path:
    """A data root of symlinks into the shared folder (cheap); replace one link to alter a file."""
    for name in SUMS:
        (dst / name).parent.mkdir(parents=True, exist_ok=True)
        (dst / name).symlink_to(SHARED / name)
    return dst


@pytest.fixture
def home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private $HOME, so the default cache resolves under tmp_path."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def test_data_root_argument_beats_env_beats_default_cache(tmp_path: Path, home: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "env"))
    assert data_root(tmp_path / "arg", check=False) == (tmp_path / "arg").resolve()
    assert data_root(check=False) == (tmp_path / "env").resolve()
    monkeypatch.setenv(ENV_VAR, "")
    assert data_root(check=False) == (home / ".cache/stcrowd/eth_ucy").resolve()
    monkeypatch.delenv(ENV_VAR)
    assert data_root(check=False) == (home / ".cache/stcrowd/eth_ucy").resolve()


def test_data_root_argument_is_used_even_when_env_points_nowhere(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "nowhere"))
    assert data_root(SHARED) == SHARED


@pytest.mark.parametrize("source", ["argument", "env", "default"], ids=["argument", "env", "default"])
def test_data_root_missing_folder_names_it_and_the_fetch_command(source: str, tmp_path: Path, home: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    missing = {"argument": tmp_path / "arg", "env": tmp_path / "env", "default": home / ".cache/stcrowd/eth_ucy"}
    monkeypatch.setenv(ENV_VAR, str(missing["env"]))
    if source == "default":
        monkeypatch.delenv(ENV_VAR)
    with pytest.raises(DataRootError) as info:
        data_root(missing["argument"] if source == "argument" else None)
    message = str(info.value)
    assert str(missing[source].resolve()) in message and "python -m replays fetch" in message, message


def test_data_root_incomplete_folder_names_a_missing_file(tmp_path: Path) -> None:
    root = linked_layout(tmp_path / "root")
    (root / VICTIM).unlink()
    with pytest.raises(DataRootError, match=re.escape(VICTIM)):
        data_root(root)


def test_verify_data_root_accepts_the_reference_copy() -> None:
    verify_data_root(SHARED)


def test_verify_data_root_names_a_corrupted_file(tmp_path: Path) -> None:
    root = linked_layout(tmp_path / "root")
    data = (SHARED / VICTIM).read_bytes()
    (root / VICTIM).unlink()
    (root / VICTIM).write_bytes(data.replace(b"0", b"1", 1))
    with pytest.raises(DataRootError, match=re.escape(VICTIM) + ".*SHA-256"):
        data_root(root)  # the first use of a root checks the sums
    with pytest.raises(DataRootError, match=re.escape(VICTIM) + ".*SHA-256"):
        verify_data_root(root)


def test_verify_data_root_names_a_missing_file(tmp_path: Path) -> None:
    root = linked_layout(tmp_path / "root")
    (root / VICTIM).unlink()
    with pytest.raises(DataRootError, match=re.escape(VICTIM) + ": missing"):
        verify_data_root(root)
