"""``shoveld diagnose`` end to end on files, and the extended model in operation."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from shoveld.cli import main
from shoveld.model.params import load_params
from shoveld.signals.table import write_table
from tests.diagnose.conftest import session


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("diag")
    calib, measured, _ = session({"sensor_time_skew": 140.0}, 4242, passes=16)
    out = {"c0": d / "c0.csv", "c1": d / "c1.csv", "ops": d / "ops.csv", "dir": d}
    write_table(out["c0"], calib[0])
    write_table(out["c1"], calib[1])
    write_table(out["ops"], measured[0])
    return out


def test_diagnose_json_and_report(files: dict[str, Path], capsys: pytest.CaptureFixture[str]
                                  ) -> None:
    rep = files["dir"] / "report"
    rc = main(["diagnose", "--calib", str(files["c0"]), str(files["c1"]), "--measured",
               str(files["ops"]), "--json", "--report", str(rep)])
    assert rc == 0
    js = json.loads(capsys.readouterr().out)
    assert js["found"] == ["sensor_time_skew"]
    assert abs(js["extended"]["hyper"]["sensor_time_skew"]["delay_s"] - 0.14) <= 0.021
    # the whole arm stream is late (MTi and laser together): no lag between the two
    assert abs(js["extended"]["hyper"]["sensor_time_skew"]["crowd_lag_s"]) <= 0.021
    # each device's lateness with its uncertainty: the search's standard error (more
    # than the grid's rounding alone) and the model's error beside it, covering the truth
    hyper = js["extended"]["hyper"]["sensor_time_skew"]
    for dev in ("mti", "laser"):
        assert 0.02 / math.sqrt(12) < hyper[f"{dev}_late_std_s"] < 0.05
    late = {f["what"].split()[0]: f for f in js["physical"]["sensor_time_skew"]}
    for dev in ("MTi", "laser"):
        assert late[dev]["std"] > 0.0115
        assert abs(late[dev]["value"] - 0.14) <= 2 * late[dev]["std"]
    for key in ("found", "ranked", "base", "extended", "passes", "residuals_against"):
        assert key in js
    for tag in ("base", "extended"):
        assert set(js[tag]["residual_rms"]) >= {"hoist_A", "crowd_A"}
        pay = js[tag]["payload"]
        assert set(pay) >= {"mean_kg", "rms_kg", "mean_pct_rated", "rms_pct_rated"}
        assert js[tag]["payload_engine"]["passes"] > 0
    assert js["extended"]["payload"]["rms_kg"] < js["base"]["payload"]["rms_kg"]
    assert js["extended"]["payload_engine"]["rms_kg"] < js["base"]["payload_engine"]["rms_kg"]
    assert {c["name"] for c in js["ranked"]} >= {"sensor_time_skew", "ground_slope"}
    for name in ("report.md", "residual_vs_cause.png", "payload_per_pass.png",
                 "residuals_overview.png", "extended.params.toml"):
        assert (rep / name).stat().st_size > 0
    text = (rep / "report.md").read_text()
    assert "out of step" in text and "payload_per_pass.png" in text
    p = load_params(rep / "extended.params.toml")
    assert "sensor_time_skew" in p.terms


def test_calibrate_and_estimate_take_the_extended_model(
        files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    out = files["dir"] / "skew.toml"
    assert main(["calibrate", str(files["c0"]), str(files["c1"]), "--effects",
                 "sensor_time_skew", "--out", str(out)]) == 0
    p = load_params(out)
    assert p.terms[-1] == "sensor_time_skew"
    assert abs(p.hyper["sensor_time_skew"]["delay_s"] - 0.14) <= 0.021
    assert abs(p.hyper["sensor_time_skew"]["crowd_lag_s"]) <= 0.021
    capsys.readouterr()
    assert main(["estimate", str(files["ops"]), "--params", str(out), "--json"]) == 0
    passes = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert sum(1 for x in passes if x["valid"]) >= 12


def test_calibrate_refuses_a_term_the_trials_cannot_identify_without_verified_passes(
        files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """Fitted on trials that never swing, the swing's term took whatever values the fit
    left it and weighed the passes of a swinging machine 8 t heavy; the diagnosis adds
    the verified passes. The command says so in one line and writes nothing."""
    effect = "swing_centrifugal"
    why = ("swing_centrifugal: only swinging excites it, and the trials swing faster than "
           "0.1 rad/s for 0.0 s (at least 5 s needed)")
    out = files["dir"] / f"{effect}.toml"
    capsys.readouterr()
    assert main(["calibrate", str(files["c0"]), str(files["c1"]), "--effects",
                 f"sensor_time_skew,{effect}", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("shoveld calibrate: error: --effects sensor_time_skew,"), err
    assert why in err and "add scale-verified passes with --verified TABLE" in err
    assert "sensor_time_skew" not in err.split("identify", 1)[1]  # the trials do see a skew
    assert not out.exists()


def test_the_diagnosis_report_says_which_terms_need_the_verified_passes() -> None:
    """The report's re-identification command carries ``--verified`` where the command
    would otherwise refuse (or, before, weigh tonnes off)."""
    from shoveld.diagnose.report import _verified_hint

    assert _verified_hint(["sensor_time_skew", "ground_slope"]) == ""
    assert "--verified" in _verified_hint(["sensor_time_skew", "swing_centrifugal"])
    assert "--verified" in _verified_hint(["current_saturation"])  # as the diagnosis had it
