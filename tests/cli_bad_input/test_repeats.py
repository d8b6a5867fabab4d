"""A signals table given twice is refused before any work: its data would count twice (a
calibration's standard errors shrank as if there were one more trial; an estimate listed
every pass twice, in two trucks)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from shoveld.cli import main

TABLE = "# format: shovel-signals/1\nt,x\n1,2\n"  # never read: the refusal comes first


@pytest.fixture
def tables(tmp_path: Path) -> tuple[Path, Path]:
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text(TABLE)
    b.write_text(TABLE.replace("2", "3"))
    return a, b


def _err(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_one_file_twice(tables: tuple[Path, Path], tmp_path: Path,
                        capsys: pytest.CaptureFixture[str]) -> None:
    a, b = tables
    out = str(tmp_path / "p.toml")
    assert _err(["calibrate", "--out", out, str(a), str(b), str(a)], capsys) == (
        f"shoveld calibrate: error: {a}: given twice: its data would count twice")
    os.symlink(a, tmp_path / "link.csv")
    link = str(tmp_path / "link.csv")
    assert _err(["calibrate", "--out", out, str(a), str(b), "--verified", link],
                capsys).endswith(f"{link}: given twice (as {a} too): its data would count "
                                 "twice")
    params = Path(__file__).resolve().parents[2] / "hil_fixtures/captures/daemon-e2e/params.toml"
    assert "given twice" in _err(["estimate", "--params", str(params), str(b),
                                  str(tmp_path / "." / "b.csv")], capsys)
    assert "given twice" in _err(["diagnose", "--calib", str(a), "--measured", str(b),
                                  str(b)], capsys)


def test_a_copy(tables: tuple[Path, Path], tmp_path: Path,
                capsys: pytest.CaptureFixture[str]) -> None:
    a, b = tables
    shutil.copy(a, tmp_path / "copy.csv")
    assert _err(["calibrate", "--out", str(tmp_path / "p.toml"), str(a), str(b),
                 str(tmp_path / "copy.csv")], capsys).endswith(
        f"{tmp_path / 'copy.csv'}: the same data as {a} (a copy): its data would count twice")


def test_distinct_tables_of_one_size_go_on(tables: tuple[Path, Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Two tables of the same size and other bytes are not copies: the reader then names
    what is wrong with them (here, their columns)."""
    a, b = tables
    assert a.stat().st_size == b.stat().st_size
    line = _err(["calibrate", "--out", str(tmp_path / "p.toml"), str(a), str(b)], capsys)
    assert "twice" not in line and str(a) in line, line
