"""A params file that is not what ``calibrate`` writes is refused with one line naming
the file and the key; nothing non-finite gets into the engine."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from shoveld.cli import main
from shoveld.model.params import ParamsFileError, load_params
from shoveld.model.terms import HoistDrive

GOOD = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e" / \
    "params.toml"


def variant(tmp_path: Path, old: str, new: str, count: int = 1) -> Path:
    text = GOOD.read_text()
    assert old in text, old
    p = tmp_path / "params.toml"
    p.write_text(text.replace(old, new, count))
    return p


def first_value(text: str) -> str:
    return re.search(r"^value = .*$", text, re.M).group(0)  # type: ignore[union-attr]


@pytest.mark.parametrize("value,key", [("nan", "value"), ("inf", "value"), ("-inf", "value")])
def test_non_finite_values_are_refused(tmp_path: Path, value: str, key: str) -> None:
    p = variant(tmp_path, first_value(GOOD.read_text()), f"value = {value}")
    with pytest.raises(ParamsFileError, match=r"params\.\w+\.value.*finite"):
        load_params(p)


def test_a_file_that_is_not_text(tmp_path: Path) -> None:
    p = tmp_path / "params.toml"
    p.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(ParamsFileError, match="not a text file"):
        load_params(p)


def test_a_covariance_that_does_not_fit_is_refused(tmp_path: Path) -> None:
    text = GOOD.read_text()
    assert "[covariance]" in text
    p = variant(tmp_path, "[covariance]\nnames = [", "[covariance]\nnames = [\"x\", ")
    with pytest.raises(ParamsFileError, match="covariance.names"):
        load_params(p)


def test_a_missing_covariance_falls_back_to_the_standard_errors(tmp_path: Path) -> None:
    text = GOOD.read_text()
    cut = re.sub(r"\[covariance\]\n.*?(?=^\[|\Z)", "", text, flags=re.S | re.M)
    assert "[covariance]" not in cut and "[noise]" in cut
    p = tmp_path / "params.toml"
    p.write_text(cut)
    got = load_params(p)
    assert got.cov.shape == (len(got.values),) * 2
    assert got.cov[0, 0] == pytest.approx(got.stderr[0] ** 2)


def test_estimate_with_a_bad_params_file_is_one_line(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    p = variant(tmp_path, first_value(GOOD.read_text()), "value = nan")
    table = tmp_path / "t.csv"
    table.write_text("# format: shovel-signals/1\n")
    assert main(["estimate", "--params", str(p), str(table)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "params.toml" in err and "Traceback" not in err


@pytest.mark.parametrize("argv", [["sim", "--passes", "1", "--out", "{d}/no/such/s.csv"],
                                  ["calibrate", "--out", "{d}/no/such/p.toml", "{d}/t.csv",
                                   "{d}/t1.csv"]])
def test_an_output_in_a_missing_folder_is_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    from shoveld.signals.table import write_table
    from shoveld.sim.scenario import simulate_calibration

    for name, load in (("t.csv", 0.0), ("t1.csv", 8420.0)):
        write_table(tmp_path / name, simulate_calibration(load, 1, n_poses=6, free_motion_s=30,
                                                          fast_moves=0).table)
    assert main([a.format(d=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "no/such" in err and "does not exist" in err


@pytest.mark.parametrize(("key", "old", "new"), [("below_bottom_knot", "proportional", "slope"),
                                                 ("spline_ends", "natural", "not-a-knot")])
def test_the_field_curve_below_its_lowest_knot_and_its_ends_are_read_or_refused(
        tmp_path: Path, key: str, old: str, new: str) -> None:
    """Files written before each key keep the curve they were identified with."""
    attr = {"below_bottom_knot": "below", "spline_ends": "ends"}[key]
    assert getattr(load_params(GOOD).model().terms[1], attr) == old
    head = "[hyper.hoist_drive]\n"
    p = variant(tmp_path, head, head + f'{key} = "{new}"\n')
    assert getattr(load_params(p).model().terms[1], attr) == new
    p = variant(tmp_path, head, head + f'{key} = "up"\n')
    with pytest.raises(ParamsFileError, match=rf"params\.toml: hyper\.hoist_drive\.{key}: "
                                              rf"expected '{new}' or '{old}', got 'up'"):
        load_params(p)


def hoist_drive(path: Path) -> HoistDrive:
    """The hoist drive's term (the model's second) of a params file's model."""
    term = load_params(path).model().terms[1]
    assert isinstance(term, HoistDrive)
    return term


def test_the_field_curve_above_its_top_knot_is_read_or_refused(tmp_path: Path) -> None:
    """Files written before the key keep the flat curve they were identified with."""
    assert hoist_drive(GOOD).above == "flat"
    head = "[hyper.hoist_drive]\n"
    p = variant(tmp_path, head, head + 'above_top_knot = "slope"\n')
    assert hoist_drive(p).above == "slope"
    p = variant(tmp_path, head, head + 'above_top_knot = "up"\n')
    with pytest.raises(ParamsFileError, match=r"params\.toml: hyper\.hoist_drive\.above_top_knot: "
                                              r"expected 'slope' or 'flat', got 'up'"):
        load_params(p)


@pytest.mark.parametrize("value", ['"high"', "-2.4", "nan", "true", "[2.4]"])
def test_a_passes_to_trials_ratio_that_is_not_a_positive_number_is_refused(
        tmp_path: Path, value: str) -> None:
    """The one record of the fit that the daemon and check-config read (the calibration's
    verified passes against its trials) is checked like a parameter."""
    p = variant(tmp_path, "[fit.residual_rms]",
                f"[fit.passes_to_trials_rms]\nhoist = {value}\n\n[fit.residual_rms]")
    with pytest.raises(ParamsFileError, match=r"params\.toml: key 'fit\.passes_to_trials_rms' "
                                              r"must be a table of positive numbers"):
        load_params(p)
    p = variant(tmp_path, "[fit.residual_rms]",
                "[fit.passes_to_trials_rms]\nhoist = 2.4\ncrowd = 1\n\n[fit.residual_rms]")
    assert load_params(p).fit["passes_to_trials_rms"] == {"hoist": 2.4, "crowd": 1}
