"""Identification recovers the simulator's parameters; the params file round-trips."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from shoveld.identify.calibrate import Calibrator
from shoveld.model.params import ModelParams, ParamsFileError, load_params, save_params
from shoveld.sim.plant import PlantParams
from shoveld.sim.scenario import SimResult


def truth() -> dict[str, float]:
    pp = PlantParams()
    return {"Md": pp.Md, "MdLc": pp.Md * pp.Lc, "K_H": pp.K_H, "K_C": pp.K_C,
            "J": pp.Izz + pp.Md * pp.Lc**2, "fv3": pp.fv3, "fc3": pp.fc3, "fv4": pp.fv4,
            "fc4": pp.fc4}


def test_recovers_table5_values(params: ModelParams) -> None:
    """Thesis Table 5 (Md, Lc, K_H, K_C) come back from data simulated with them."""
    md, mdlc, kh, kc = (params.get(n) for n in ("Md", "MdLc", "K_H", "K_C"))
    assert md == pytest.approx(56960, rel=0.01)
    assert mdlc / md == pytest.approx(3.27, rel=0.01)
    assert kh == pytest.approx(1715, rel=0.01)
    assert kc == pytest.approx(4418, rel=0.015)


def test_all_parameters_within_their_uncertainty(params: ModelParams) -> None:
    tr = truth()
    for n, v, se in zip(params.names, params.values, params.stderr, strict=True):
        assert se > 0
        # The sim's friction law is smoother than the model's: allow 4 standard errors
        # and a 6 % floor on the friction terms, 2 % on the rest.
        floor = 0.06 if n.startswith("f") else 0.02
        assert abs(v - tr[n]) < max(4 * se, floor * abs(tr[n])), (n, v, tr[n], se)


def test_report_contents(params: ModelParams) -> None:
    fit = params.fit
    assert fit["condition_number"] > 1
    assert set(fit["residual_rms"]) == {"handle", "crowd"}
    reasons = {k for ex in fit["excluded"].values() for k in ex}
    assert any("weak hoist field" in r for r in reasons)


def test_needs_a_known_load(calib_trials: tuple[SimResult, SimResult]) -> None:
    with pytest.raises(ValueError, match="known non-zero payload"):
        Calibrator().fit([calib_trials[0].table])


def test_noise_does_not_shrink_the_scale(calib_trials: tuple[SimResult, SimResult]) -> None:
    """Guards the K_H normalisation: a plain fit shrinks all parameters by ~5 %."""
    cal = Calibrator(method="joint").fit([t.table for t in calib_trials])
    assert cal.params_ is not None
    assert cal.params_.get("K_H") == pytest.approx(1715, rel=0.01)


def test_params_file_round_trip(params: ModelParams, tmp_path: Path) -> None:
    p = tmp_path / "params.toml"
    save_params(p, params)
    back = load_params(p)
    assert back.terms == params.terms
    np.testing.assert_allclose(back.values, params.values, rtol=1e-12)
    np.testing.assert_allclose(back.cov, params.cov, rtol=1e-12)
    assert back.noise == params.noise


@pytest.mark.parametrize(("edit", "words"), [
    (lambda s: s.replace('format = "shoveld-params/1"', 'format = "x"'), "key 'format'"),
    (lambda s: s.replace("[params.K_H]", "[params.K_X]"), "params.K_H"),
    (lambda s: s.replace('terms = ["rigid_arm"', 'terms = ["bogus", "rigid_arm"'), "key 'terms'"),
    (lambda s: s.replace("[noise]", "[noize]"), "'noise'"),
    (lambda s: s + "\n[[[", "not valid TOML"),
])
def test_params_file_errors_name_the_key(params: ModelParams, tmp_path: Path, edit, words) -> None:
    p = tmp_path / "params.toml"
    save_params(p, params)
    p.write_text(edit(p.read_text()))
    with pytest.raises(ParamsFileError, match=words) as ei:
        load_params(p)
    assert str(p) in str(ei.value)
