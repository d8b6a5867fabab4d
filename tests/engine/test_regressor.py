"""The model's regressor against the equations of motion derived independently.

The reference is the Lagrangian, evaluated by finite differences of the kinetic
and potential energy along a smooth trajectory, with rope and crowd forces from
vector geometry. A sign or factor error in any term of the regressor fails it.
"""

from __future__ import annotations

import dataclasses
from typing import TypeVar

import numpy as np
import pytest

from shoveld.model import G, Kinematics, Model
from shoveld.model.terms import payload_phi
from shoveld.sim.plant import PlantParams, rope_force_geometry

Currents = TypeVar("Currents", np.ndarray, float)

MD, LC, IZZ, KH, KC, FV3, FV4 = 56960.0, 3.27, 6.0e5, 1715.0, 4418.0, 1.5e5, 2.0e4


def traj(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    th = 0.3 * np.sin(0.7 * t) - 0.1 + 0.05 * np.sin(2.3 * t)
    d = 8.0 + 1.5 * np.sin(0.5 * t + 1.0)
    return th, d


def energies(th: float, d: float, thd: float, dd: float, m: float) -> tuple[float, float]:
    r = d - LC
    t_kin = 0.5 * MD * (dd**2 + (r * thd) ** 2) + 0.5 * IZZ * thd**2 + 0.5 * m * (
        dd**2 + (d * thd) ** 2)
    v = (MD * r + m * d) * G * np.sin(th)
    return t_kin, v


def lagrange_q(t: float, m: float, h: float = 1e-4) -> np.ndarray:
    """Q_j = d/dt dT/dqd_j - dT/dq_j + dV/dq_j, all by central differences."""

    def state(tt: float) -> tuple[float, float, float, float]:
        th0, d0 = traj(np.array([tt - h, tt, tt + h]))
        return th0[1], d0[1], (th0[2] - th0[0]) / (2 * h), (d0[2] - d0[0]) / (2 * h)

    def dT_dqd(tt: float) -> np.ndarray:
        th, d, thd, dd = state(tt)
        e = 1e-5
        return np.array([
            (energies(th, d, thd + e, dd, m)[0] - energies(th, d, thd - e, dd, m)[0]) / (2 * e),
            (energies(th, d, thd, dd + e, m)[0] - energies(th, d, thd, dd - e, m)[0]) / (2 * e)])

    th, d, thd, dd = state(t)
    e = 1e-6
    dT_dq = np.array([
        (energies(th + e, d, thd, dd, m)[0] - energies(th - e, d, thd, dd, m)[0]) / (2 * e),
        (energies(th, d + e, thd, dd, m)[0] - energies(th, d - e, thd, dd, m)[0]) / (2 * e)])
    dV_dq = np.array([
        (energies(th + e, d, thd, dd, m)[1] - energies(th - e, d, thd, dd, m)[1]) / (2 * e),
        (energies(th, d + e, thd, dd, m)[1] - energies(th, d - e, thd, dd, m)[1]) / (2 * e)])
    ddt = (dT_dqd(t + h) - dT_dqd(t - h)) / (2 * h)
    return ddt - dT_dq + dV_dq


def kin_at(t: np.ndarray, i_h: np.ndarray, i_c: np.ndarray, boom: float) -> Kinematics:
    h = 1e-4
    th, d = traj(t)
    thp, dp = traj(t + h)
    thm, dm = traj(t - h)
    z = np.zeros_like(t)
    return Kinematics(t=t, th=th, thd=(thp - thm) / (2 * h), thdd=(thp - 2 * th + thm) / h**2,
                      d=d, dd=(dp - dm) / (2 * h), ddd=(dp - 2 * d + dm) / h**2,
                      boom=np.full_like(t, boom), i_h=i_h, i_c=i_c, i_hf=np.full_like(t, 70.0),
                      swing=z, swing_rate=z, swing_acc=z, roll=z, pitch=z)


@pytest.mark.parametrize("m", [0.0, 8420.0, 35000.0])
def test_regressor_matches_lagrangian(m: float) -> None:
    rng = np.random.default_rng(7)
    t = np.linspace(0.5, 12.0, 25)
    i_h = rng.uniform(100, 800, len(t))
    i_c = rng.uniform(-100, 150, len(t))
    boom = np.radians(45.0)
    k = kin_at(t, i_h, i_c, boom)
    model = Model.from_names()
    p = np.array([MD, MD * LC, KH, KC, IZZ + MD * LC**2, FV3, 0.0, FV4, 0.0, 0.0, 0.0])
    res = model.residual(k, p, m)
    # Independent: actuators from the rope's force vector, friction viscous only.
    tau_u, along_u = rope_force_geometry(k.th, k.d, k.boom, PlantParams().l_bs)
    rope = KH * i_h
    q_act = np.stack([rope * tau_u - FV3 * k.thd, KC * i_c + rope * along_u - FV4 * k.dd], 1)
    q_lag = np.array([lagrange_q(tt, m) for tt in t])
    expected = q_lag - q_act
    scale = np.abs(q_lag).max(axis=0)
    np.testing.assert_allclose(res / scale, expected / scale, atol=2e-6)


def test_payload_equations_are_the_residual_in_m() -> None:
    rng = np.random.default_rng(3)
    t = np.linspace(1, 5, 9)
    k = kin_at(t, rng.uniform(200, 600, 9), rng.uniform(0, 100, 9), np.radians(45))
    model = Model.from_names()
    p = np.array([MD, MD * LC, KH, KC, IZZ + MD * LC**2, FV3, 3e4, FV4, 1e4, 0.0, 0.0])
    a, b = model.payload_equations(k, p)
    for m in (0.0, 12000.0):
        np.testing.assert_allclose(model.residual(k, p, m), a * m - b, rtol=1e-12, atol=1e-6)
    np.testing.assert_allclose(a, payload_phi(k))


def test_unknown_term_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown model term"):
        Model.from_names(["no_such_effect"])


def test_the_field_curve_goes_on_along_its_slope_just_above_the_nominal() -> None:
    """Readings of the nominal field scatter around its knot (noise, rounding): above
    it the curve must follow the magnetisation curve's slope, not stop flat, or K_H is
    biased (docs/engine.md); far above, it is flat (saturated iron)."""
    from shoveld.model.terms import field_basis

    knots = (30.0, 40.0, 50.0, 60.0, 70.0)
    def curve(x: np.ndarray) -> np.ndarray:  # a Froehlich magnetisation curve
        return x / (40.0 + x)

    y = curve(np.array(knots))
    x = np.array([69.0, 70.0, 70.5, 71.0, 74.0, 75.0, 90.0])
    got = field_basis(x, knots) @ y
    err = (got - curve(x)) / curve(x)
    # within a reading's scatter of the knot: 0.03 % off (a flat curve: 0.5 % at 71 A)
    assert np.all(np.abs(err[:4]) < 4e-4)
    assert got[4] > got[3] > got[1]  # still rising ...
    assert got[5] == pytest.approx(got[6])  # ... for half a step, then flat
    assert np.all(np.diff(got) >= 0)
    # params identified with the flat curve keep it
    flat = field_basis(x, knots, slope_above=False) @ y
    assert flat[3] == pytest.approx(flat[1]) and flat[0] < flat[1]


def test_the_field_curve_goes_on_along_its_slope_just_below_the_lowest_knot() -> None:
    """The lowest knot is the drive's minimum field, and noise puts half its readings
    below it: there the curve must follow the magnetisation curve's slope (proportional
    from the knot down was 0.7 % low at 29.5 A and biased that knot by +1.5 standard
    errors, docs/engine.md); far below, proportional to the field (unsaturated iron)."""
    from shoveld.model.terms import field_basis

    knots = (30.0, 40.0, 50.0, 60.0, 70.0)
    def curve(x: Currents) -> Currents:  # a Froehlich magnetisation curve
        return x / (40.0 + x)

    y = curve(np.array(knots))
    x = np.array([0.0, 10.0, 20.0, 25.0, 29.0, 29.5, 30.0, 31.0, 35.0])
    got = field_basis(x, knots) @ y
    err = (got[4:] - curve(x[4:])) / curve(x[4:])
    assert np.all(np.abs(err) < 5e-4)  # within a reading's scatter and above
    old = field_basis(x, knots, slope_below=False) @ y
    assert (old[5] - curve(29.5)) / curve(29.5) < -6e-3  # what it was
    assert got[0] == 0.0 and got[1] / 10.0 == pytest.approx(got[2] / 20.0)  # proportional
    assert got[2] / 20.0 == pytest.approx(got[3] / 25.0)  # ... up to half a step below
    assert np.all(np.diff(got) > 0)


def test_the_field_spline_is_within_0_02_percent_of_a_magnetisation_curve() -> None:
    """Not-a-knot ends: a natural spline (no curvature at the end knots) is 0.24 % under
    a Froehlich curve between the two lowest knots, and the fit moved the knots to make
    up for it."""
    from shoveld.model.terms import field_basis

    knots = (30.0, 40.0, 50.0, 60.0, 70.0)
    x = np.linspace(30.0, 70.0, 81)
    for knee in (30.0, 40.0, 55.0):
        y = np.array(knots) / (knee + np.array(knots))
        truth = x / (knee + x)
        got = field_basis(x, knots) @ y
        natural = field_basis(x, knots, ends="natural") @ y
        assert np.max(np.abs(got / truth - 1)) < 2.5e-4
        assert np.max(np.abs(natural / truth - 1)) > 2e-3


def test_the_friction_sign_is_uncertain_at_standstill_only() -> None:
    """Each channel's model variance is (fc over the current's gain)^2 where a joint
    stands still, sech^2 of the rate over the sign's width near it, and vanishes a few
    widths away."""
    from shoveld.model.output import CurrentEquations
    from shoveld.model.terms import SIGN_EPS_D

    t = np.linspace(1, 2, 3)
    k = kin_at(t, np.full(3, 500.0), np.full(3, 50.0), np.radians(45))
    k = dataclasses.replace(k, thd=np.full(3, 0.2),
                            dd=np.array([0.0, SIGN_EPS_D, 8 * SIGN_EPS_D]))
    model = Model.from_names()
    fc4 = 1.5e4
    p = np.array([MD, MD * LC, KH, KC, IZZ + MD * LC**2, FV3, 3e4, FV4, fc4, 0.0, 0.0])
    ce = CurrentEquations(model, k)
    var = ce.model_variance(p)
    g_c = ce.gains(p)[2]
    assert var[0, 1] == pytest.approx((fc4 / g_c[0]) ** 2, rel=1e-6)
    assert var[1, 1] == pytest.approx((fc4 / g_c[1]) ** 2 / np.cosh(1.0) ** 2, rel=1e-6)
    assert var[2, 1] < 1e-5 * var[0, 1]
    assert np.all(var[:, 0] < 1e-9 * var[0, 1])  # the handle moves: its sign is known


def _kin_with_est(k: Kinematics) -> Kinematics:
    """``k`` with its neighbour estimates of the currents fixed (copies): a shifted
    measured current then moves only the columns that use the sample's own reading."""
    return dataclasses.replace(k, i_h_est=k.i_h.copy(), i_c_est=k.i_c.copy())


def test_the_columns_move_with_the_measured_currents_only_where_the_model_says() -> None:
    """``Model.current_derivatives`` names the few columns a measured current moves
    (the drives'); every other column of the base model stays put when a current is
    shifted, and the named ones move by what it says."""
    from pathlib import Path

    from shoveld.model.params import load_params

    params = load_params(Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures"
                         / "daemon-e2e" / "params.toml")
    model = params.model()
    t = np.linspace(1, 3, 7)
    k = _kin_with_est(dataclasses.replace(
        kin_at(t, np.linspace(200, 900, 7), np.linspace(-80, 80, 7), np.radians(45)),
        i_hf=np.linspace(35, 72, 7)))
    d = model.current_derivatives(k)
    w = model.regressor(k)[0]
    for field, cols, got in (("i_h", d.hoist, d.d_hoist), ("i_c", d.crowd, d.d_crowd)):
        step = 0.5
        moved = [model.regressor(dataclasses.replace(k, **{field: getattr(k, field) + s}))[0]
                 for s in (step, -step)]
        dense = (moved[0] - moved[1]) / (2 * step)
        want = np.zeros_like(w)
        want[:, :, cols] = got
        assert np.allclose(dense, want, rtol=1e-9, atol=1e-9 * np.abs(w).max()), field
        assert np.any(got), field


@pytest.mark.parametrize("effects", [[], ["payload_cog_offset", "current_saturation",
                                          "hoist_field_weakening", "swing_centrifugal"]])
def test_the_current_residuals_jacobian_is_their_derivative(effects: list[str]) -> None:
    """``CurrentEquations.jacobian`` against central differences of the residual, for
    every parameter, with a payload per sample and with the engine's one payload."""
    from shoveld.model.output import CurrentEquations

    model = Model.from_names(effects)
    n = 9
    t = np.linspace(1, 3, n)
    k = _kin_with_est(dataclasses.replace(
        kin_at(t, np.linspace(200, 900, n), np.linspace(-80, 80, n), np.radians(45)),
        i_hf=np.linspace(60, 75, n), swing=np.full(n, 0.4), swing_rate=np.full(n, 0.2)))
    rng = np.random.default_rng(3)
    base = np.array([MD, MD * LC, KH, KC, IZZ + MD * LC**2, FV3, 3e4, FV4, 1.5e4, 4.0, -3.0])
    p = np.concatenate([base, rng.normal(0.0, 50.0, len(model.param_names) - len(base))])
    ce = CurrentEquations(model, k)
    for m in (rng.uniform(0, 30000, n), 31000.0):
        jac = ce.jacobian(p, m)
        assert jac.shape == (n, 2, len(p))
        for j in range(len(p)):
            # a step that moves the residual by a milliampere or more (rounding), and
            # is small beside the parameter (the gains' 1 / p curvature)
            h = 1e-3 * max(abs(p[j]), 1.0 / (np.abs(jac[:, :, j]).max() + 1e-300))
            dp = np.zeros(len(p))
            dp[j] = h
            num = (ce.residual(p + dp, m) - ce.residual(p - dp, m)) / (2 * h)
            scale = np.abs(num).max() + np.abs(jac[:, :, j]).max() + 1e-12
            assert np.allclose(jac[:, :, j], num, rtol=1e-5, atol=1e-5 * scale), (
                model.param_names[j], jac[:, :, j], num)
