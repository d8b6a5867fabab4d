"""An output a command could not write is refused before its work, in the line a late
failure gave: the calibration or diagnosis of hours of data is not lost at its end."""

from __future__ import annotations

from pathlib import Path

import pytest

from shoveld.cli import main

GARBLED = "# format: shovel-signals/1\nt,x\n1,2\n"


@pytest.fixture
def garbled(tmp_path: Path) -> Path:
    p = tmp_path / "garbled.csv"
    p.write_text(GARBLED)
    return p


def _err(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_calibrate_out_in_a_missing_folder(tmp_path: Path, garbled: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "no" / "p.toml"
    # the garbled input is not read: the output comes first
    assert _err(["calibrate", "--out", str(out), str(garbled)], capsys) == (
        f"shoveld calibrate: error: {out}: No such file or directory "
        f"(the folder {out.parent} does not exist)")


def test_calibrate_out_a_folder_and_plot_a_file(tmp_path: Path, garbled: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert _err(["calibrate", "--out", str(tmp_path), str(garbled)], capsys).endswith(
        f"{tmp_path}: Is a directory")
    assert _err(["calibrate", "--out", str(tmp_path / "p.toml"), "--plot", str(garbled),
                 str(garbled)], capsys).endswith(
        f"{garbled}: Not a directory (a file is there; expected a folder)")
    assert not (tmp_path / "p.toml").exists()


def test_estimate_plot_a_folder(tmp_path: Path, garbled: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    """A folder as the PNG was written to as FOLDER/.png, a hidden file, and said
    "plot: FOLDER"."""
    params = Path(__file__).resolve().parents[2] / "hil_fixtures/captures/daemon-e2e/params.toml"
    assert _err(["estimate", "--params", str(params), "--plot", str(tmp_path), str(garbled)],
                capsys).endswith(f"{tmp_path}: Is a directory")
    assert not (tmp_path / ".png").exists()


def test_report_folders_under_a_file(tmp_path: Path, garbled: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    below = garbled / "a" / "b"
    assert _err(["diagnose", "--calib", str(garbled), "--measured", str(garbled),
                 "--report", str(below)], capsys).endswith(
        f"{below}: Not a directory ({garbled} is a file)")
    assert _err(["report", "--db", str(tmp_path / "none.sqlite"), "--out", str(below)],
                capsys).endswith(f"{below}: Not a directory ({garbled} is a file)")


def test_a_writable_output_goes_on_to_the_input(tmp_path: Path, garbled: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """A folder to be made (with its parents) and a file in a folder that is there pass:
    the garbled input is then what is refused, and nothing is made."""
    line = _err(["calibrate", "--out", str(tmp_path / "p.toml"), "--plot",
                 str(tmp_path / "plots" / "cal"), str(garbled)], capsys)
    assert str(garbled) in line and "plots" not in line, line
    assert not (tmp_path / "plots").exists() and not (tmp_path / "p.toml").exists()


def test_an_output_in_a_folder_one_may_not_write(
        tmp_path: Path, garbled: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The permission branch: a folder its user may not write (mode 0555; as root, who
    may write anywhere, an immutable folder, which root may not write either). Refused
    before the work, naming the folder."""
    import os
    import subprocess

    ro = tmp_path / "ro"
    ro.mkdir()
    if os.geteuid() == 0:
        r = subprocess.run(["chattr", "+i", str(ro)], capture_output=True, text=True)
        if r.returncode:
            pytest.skip(f"root, and no immutable folder here: {r.stderr.strip()}")
    else:
        ro.chmod(0o555)
    try:
        out = ro / "p.toml"
        assert _err(["calibrate", "--out", str(out), str(garbled)], capsys) == (
            f"shoveld calibrate: error: {out}: Permission denied (the folder {ro} is not "
            "writable)")
        assert _err(["diagnose", "--calib", str(garbled), "--measured", str(garbled),
                     "--report", str(ro / "report")], capsys).endswith(
            f"{ro / 'report'}: Permission denied (the folder {ro} is not writable)")
    finally:
        if os.geteuid() == 0:
            subprocess.run(["chattr", "-i", str(ro)], check=False)
        else:
            ro.chmod(0o755)


def test_the_demo_names_its_inputs_before_its_work(tmp_path: Path, garbled: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``demo --params`` that is not there was named in the demo's own temporary config
    (``/tmp/shoveld-demo-.../shoveld.toml: key 'shovel.params': ...``), after the
    simulation; a ``--state-dir`` that is a file ended in a traceback at the daemon's
    start. Both are said first, naming what was given."""
    import socket

    with socket.socket() as sk:
        sk.bind(("127.0.0.1", 0))
        port = str(sk.getsockname()[1])
    missing = tmp_path / "nope.toml"
    assert _err(["demo", "--port", port, "--params", str(missing)], capsys) == (
        f"shoveld demo: error: {missing}: cannot read: No such file or directory")
    assert _err(["demo", "--port", port, "--state-dir", str(garbled)], capsys).endswith(
        f"{garbled}: Not a directory (a file is there; expected a folder)")
