"""An option the command would ignore is refused, in one line saying where it belongs:
``shoveld sim``'s options of the other scenario, an effect given twice, a machine both
drawn and ideal; ``shoveld cab``'s options of the other view. Each was taken without a
word (2026-11-30: ``sim --load 8420`` on the dig cycles wrote passes of random payloads;
``cab --listen`` without ``--web`` drew in the terminal and served no page)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from shoveld.cli import main


@pytest.mark.parametrize("argv,expected", [
    (["--load", "8420"], "--load is the known load of --scenario calibration"),
    (["--scenario", "calibration", "--passes", "3"],
     "--passes: for --scenario cycles; a calibration trial is one run at --load KG"),
    (["--scenario", "calibration", "--load", "0", "--truck-target", "9000",
      "--verified-fraction", "1"], "--truck-target, --verified-fraction: for --scenario cycles"),
    (["--payload-range", "1000", "2000", "--truck-target", "9000"],
     "--truck-target fills trucks with passes drawn to suit it, and --payload-range"),
    (["--effect", "ground_slope=1", "--effect", "ground_slope=2"],
     "--effect 'ground_slope=2': ground_slope is already switched on (by --effect "
     "ground_slope=1): give each effect once"),
    (["--effect", "ground_slope", "--effect", " ground_slope"],
     "ground_slope is already switched on (by --effect ground_slope)"),
    (["--machine", "3", "--ideal"], "argument --ideal: not allowed with argument --machine"),
])
def test_an_option_sim_would_ignore_is_refused(
        tmp_path: Path, argv: list[str], expected: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.csv"
    code: str | int | None  # main's exit code, or what argparse exits with
    try:
        code = main(["sim", *argv, "--out", str(out)])
    except SystemExit as e:  # argparse's own refusals
        code = e.code
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert expected in err[-1], err
    assert not out.exists()


def test_the_defaults_still_apply(tmp_path: Path) -> None:
    """The options' defaults (now put in by the command, not argparse) are those its help
    names: a calibration trial at 0 kg, the cycles' trucks filled to 136 t."""
    c, s = tmp_path / "c.csv", tmp_path / "s.csv"
    assert main(["sim", "--scenario", "calibration", "--seed", "1", "--out", str(c)]) == 0
    truth = json.loads(Path(str(c) + ".truth.json").read_text())
    assert truth["load_kg"] == 0.0, truth.keys()
    assert main(["sim", "--passes", "2", "--seed", "1", "--out", str(s)]) == 0
    truth = json.loads(Path(str(s) + ".truth.json").read_text())
    assert len(truth["passes"]) == 2
    assert truth["truck_target_kg"] == 136000.0, truth.keys()


@pytest.mark.parametrize("argv,expected", [
    (["--listen", "127.0.0.1:8089"], "--listen is the address of the cab page: add --web"),
    (["--web", "--lines"], "--lines: for the cab in the terminal, not the page (--web)"),
    (["--web", "--until-closed-trucks", "2", "--lines"],
     "--lines, --until-closed-trucks: for the cab in the terminal"),
])
def test_an_option_of_the_other_cab_view_is_refused(
        argv: list[str], expected: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Refused before anything is connected or served (the --duration would end it)."""
    assert main(["cab", *argv, "--connect", "tcp/127.0.0.1:9", "--duration", "30"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err
