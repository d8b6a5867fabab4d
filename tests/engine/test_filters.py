"""The engine's own numerical filters against the libraries they replace.

Savitzky-Golay, the joints' Kalman filters and the payload's recursive least squares
are written on numpy so that the daemon starts without scipy (``bench/startup.py``);
scipy's and filterpy's implementations stay the reference they must agree with.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from scipy.signal import savgol_coeffs as scipy_coeffs
from scipy.signal import savgol_filter as scipy_filter

from shoveld.kinematics.causal import HANDLE, JointFilter, Kalman3, white_jerk_q
from shoveld.kinematics.savgol import savgol_coeffs, savgol_filter
from shoveld.payload.rls import PayloadRls, RlsConfig


@pytest.mark.parametrize("window", [5, 11, 25, 51])
@pytest.mark.parametrize("deriv", [0, 1, 2])
def test_savgol_matches_scipy(window: int, deriv: int) -> None:
    rng = np.random.default_rng(window + deriv)
    y = np.cumsum(rng.normal(size=400)) + np.sin(np.arange(400) / 7.0)
    for use in ("conv", "dot"):
        ref = scipy_coeffs(window, 3, deriv=deriv, delta=0.02, use=use)
        assert np.allclose(savgol_coeffs(window, 3, deriv, 0.02, use=use), ref,
                           rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    ref = scipy_filter(y, window, 3, deriv=deriv, delta=0.02, mode="interp")
    got = savgol_filter(y, window, 3, deriv, 0.02)
    assert np.max(np.abs(got - ref)) <= 1e-10 * np.max(np.abs(ref))


@pytest.mark.parametrize(("window", "order", "delta"),
                         [(51, 7, 0.02), (101, 7, 0.01), (81, 9, 0.02), (161, 9, 0.01)])
def test_savgol_fits_a_polynomial_of_its_own_order_exactly(window: int, order: int,
                                                           delta: float) -> None:
    """A fit of order n gives any polynomial of degree n back: value, rate and acceleration
    at the centre, with and without missing samples. Long windows of high order are where
    weights built on raw powers of the sample index lose the high terms (scipy's 9th-order
    weights over 81 samples had the value and the acceleration wrong by 100 %)."""
    rng = np.random.default_rng(window + order)
    c = rng.normal(size=order + 1)
    half = window // 2
    span = half * delta
    t = (np.arange(window) - half) * delta
    y = np.polynomial.polynomial.polyval(t / span, c)
    want = [c[0], c[1] / span, 2 * c[2] / span**2]
    keep = np.ones(window, dtype=bool)
    keep[rng.choice(window, size=window // 10, replace=False)] = False
    for d in range(3):
        got = savgol_coeffs(window, order, d, delta, use="dot") @ y
        assert got == pytest.approx(want[d], rel=1e-6, abs=1e-9 * abs(want[d]) + 1e-9)
        got = savgol_coeffs(window, order, d, delta, use="dot", keep=keep) @ y[keep]
        assert got == pytest.approx(want[d], rel=1e-6, abs=1e-9 * abs(want[d]) + 1e-9)


def test_savgol_refuses_a_window_it_cannot_fit() -> None:
    with pytest.raises(ValueError, match="window"):
        savgol_filter(np.zeros(4), 5, 3)
    with pytest.raises(ValueError, match="order"):
        savgol_coeffs(3, 3)


def test_white_jerk_noise_is_filterpys() -> None:
    assert np.allclose(white_jerk_q(0.01, 2.5), Q_discrete_white_noise(dim=3, dt=0.01, var=2.5))


def _filterpy_joint(dt: float, zs: np.ndarray) -> np.ndarray:
    """The joint filter as it was built on filterpy: predict, then update when z is
    not NaN (the test sequence has no gap longer than the coast limit)."""
    cfg = HANDLE
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    kf.H = np.array([[1.0, 0.0, 0.0]])
    kf.R = np.array([[cfg.meas_std**2]])
    kf.Q = Q_discrete_white_noise(dim=3, dt=dt, var=(cfg.jerk_std * dt) ** 2)
    kf.x = np.array([[zs[0]], [0.0], [0.0]])
    kf.P = np.diag([cfg.meas_std**2, 1.0, 10.0])
    out = [(zs[0], 0.0, 0.0)]
    for z in zs[1:]:
        kf.predict()
        if not math.isnan(z):
            kf.update(z)
        out.append((float(kf.x[0, 0]), float(kf.x[1, 0]), float(kf.x[2, 0])))
    return np.array(out)


def test_joint_filter_matches_filterpy_through_gaps() -> None:
    dt = 0.01
    t = np.arange(3000) * dt
    rng = np.random.default_rng(3)
    zs = 0.4 * np.sin(0.7 * t) + rng.normal(0, HANDLE.meas_std, len(t))
    zs[1200:1230] = np.nan  # a 0.3 s dropout: the filter coasts, then leaves its steady state
    jf = JointFilter(HANDLE, dt)
    got = np.array([jf.update(float(ti), float(z)) for ti, z in zip(t, zs, strict=True)])
    ref = _filterpy_joint(dt, zs)
    scale = np.max(np.abs(ref), axis=0)
    # Once settled, the joint filter freezes its gain (steady-state Kalman filter), so it
    # is the full filter only to about 1e-7 of the signal.
    assert np.all(np.max(np.abs(got - ref), axis=0) <= 1e-6 * scale)


def test_a_skipped_tick_is_a_missing_sample_not_a_jump() -> None:
    """A loaded host skips loop ticks: the samples' times jump. The filter must predict
    over the skipped ticks (as over NaN samples), not take the move in one step."""
    dt = 0.01
    t = np.arange(3000) * dt
    rng = np.random.default_rng(3)
    zs = 0.4 * np.sin(0.7 * t) + rng.normal(0, HANDLE.meas_std, len(t))
    skipped = np.zeros(len(t), bool)
    skipped[rng.choice(np.arange(500, 3000), 150, replace=False)] = True
    with_nan = np.where(skipped, np.nan, zs)
    ref_f = JointFilter(HANDLE, dt)
    ref = np.array([ref_f.update(float(ti), float(z)) for ti, z in zip(t, with_nan, strict=True)])
    jf = JointFilter(HANDLE, dt)
    got = np.array([jf.update(float(t[i]), float(zs[i])) for i in range(len(t))
                    if not skipped[i]])
    assert np.allclose(got, ref[~skipped], rtol=0, atol=1e-12)
    # and the rate error stays the filter's own (the move over a skipped tick, taken in
    # one step, made it 6.4 times larger: RMS 0.020 rad/s against 0.0031)
    full_f = JointFilter(HANDLE, dt)
    full = np.array([full_f.update(float(ti), float(z)) for ti, z in zip(t, zs, strict=True)])
    rate = 0.4 * 0.7 * np.cos(0.7 * t)

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x[500:] ** 2)))

    assert rms(got[:, 1] - rate[~skipped]) < 1.2 * rms(full[:, 1] - rate)


def test_kalman3_step_is_filterpys_step() -> None:
    dt = 0.02
    F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = white_jerk_q(dt, 0.3)
    ours = Kalman3(F, Q, 1e-4)
    ref = KalmanFilter(dim_x=3, dim_z=1)
    ref.F, ref.Q, ref.R, ref.H = F, Q, np.array([[1e-4]]), np.array([[1.0, 0.0, 0.0]])
    ours.x, ref.x = np.array([0.1, 0.2, 0.3]), np.array([[0.1], [0.2], [0.3]])
    ours.P, ref.P = np.diag([1.0, 2.0, 3.0]), np.diag([1.0, 2.0, 3.0])
    for z in np.random.default_rng(5).normal(size=200):
        ours.predict()
        ref.predict()
        ours.update(float(z))
        ref.update(float(z))
        assert np.allclose(ours.x, ref.x[:, 0], rtol=1e-12, atol=1e-14)
        assert np.allclose(ours.P, ref.P, rtol=1e-10, atol=1e-16)


def _filterpy_rls(noise: tuple[float, float], dt: float, cfg: RlsConfig,
                  blocks: list[tuple[np.ndarray, np.ndarray]]) -> tuple[float, float, float]:
    kf = KalmanFilter(dim_x=1, dim_z=2)
    kf.F = np.eye(1)
    kf.x = np.array([[cfg.prior_kg]])
    kf.P = np.array([[cfg.prior_std_kg**2]])
    r = np.square(np.asarray(noise))
    nis = 0.0
    for a, b in blocks:
        n = len(a)
        kf.Q = np.array([[(cfg.forgetting_std_kg_per_s**2) * dt * n]])
        kf.predict()
        kf.update(b.reshape(-1, 1), R=np.diag(np.tile(r, n)), H=a.reshape(-1, 1))
        nis += float((kf.y.T @ kf.SI @ kf.y)[0, 0])
    return float(kf.x[0, 0]), float(kf.P[0, 0]), nis


@pytest.mark.parametrize("forgetting", [0.0, 300.0])
def test_payload_rls_matches_filterpy(forgetting: float) -> None:
    rng = np.random.default_rng(11)
    cfg = RlsConfig(forgetting_std_kg_per_s=forgetting)
    noise = (3.0, 2.0)
    blocks = []
    for _ in range(30):
        a = rng.uniform(0.01, 0.05, (10, 2))
        b = a * 21000.0 + rng.normal(0, 1, (10, 2)) * noise
        blocks.append((a, b))
    rls = PayloadRls(noise, 0.01, cfg)
    for a, b in blocks:
        rls.update(a, b)
    x, p, nis = _filterpy_rls(noise, 0.01, cfg, blocks)
    assert rls.payload_kg == pytest.approx(x, rel=1e-10)
    assert rls.p == pytest.approx(p, rel=1e-8)
    assert rls._nis_sum == pytest.approx(nis, rel=1e-8)


def test_payload_rls_misfit_is_one_when_the_noise_model_holds() -> None:
    """``misfit`` (filterpy's innovation statistic per degree of freedom, which the test
    above checks) is about 1 on data with the noise the filter was given, and about
    k**2 when the residuals are k times that size (``bench/pass_misfit.py``)."""
    rng = np.random.default_rng(5)
    noise = (3.0, 2.0)
    fits = {}
    for k in (1.0, 4.0):
        rls = PayloadRls(noise, 0.01)
        assert math.isnan(rls.misfit)
        for _ in range(200):
            a = rng.uniform(0.01, 0.05, (10, 2))
            rls.update(a, a * 21000.0 + k * rng.normal(0, 1, (10, 2)) * noise)
        fits[k] = rls.misfit
    assert fits[1.0] == pytest.approx(1.0, abs=0.1)
    assert fits[4.0] == pytest.approx(16.0, rel=0.1)


def test_the_daemon_and_the_engine_start_without_scipy_or_filterpy() -> None:
    code = ("import sys, numpy as np, shoveld.daemon.service, shoveld.engine.loop, "
            "shoveld.engine.offline;"
            "from shoveld.model.terms import field_basis;"
            "field_basis(np.linspace(30, 70, 9), (30.0, 40.0, 50.0, 60.0, 70.0));"
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'scipy', 'filterpy'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


@pytest.mark.parametrize("ends", ["natural", "not-a-knot"])
@pytest.mark.parametrize("knots", [(30.0, 40.0, 50.0), (30.0, 40.0, 50.0, 60.0),
                                   (30.0, 40.0, 50.0, 60.0, 70.0),
                                   (25.0, 31.0, 47.0, 52.0, 70.0, 71.5)])
def test_field_spline_is_scipys_cubic_spline(knots: tuple[float, ...], ends: str) -> None:
    from scipy.interpolate import CubicSpline

    from shoveld.model.terms import _CubicSpline

    x = np.linspace(knots[0], knots[-1], 301)
    ref = CubicSpline(np.asarray(knots), np.eye(len(knots)), bc_type=ends)(x)
    assert np.allclose(_CubicSpline(knots, ends)(x), ref, rtol=1e-10, atol=1e-12)


def test_the_newey_west_sums_carry_lags_across_blocks() -> None:
    """Blocks of any size (shorter and longer than the bandwidth) give the direct
    Newey-West variance of the whole pass."""
    rng = np.random.default_rng(5)
    lag = 10
    rls = PayloadRls((3.0, 2.0), 0.02, hac_lag=lag)
    rows_a, rows_b, rows_v = [], [], []
    for n in (3, 50, 1, 7, 20, 11):
        a = rng.uniform(0.01, 0.05, (n, 2))
        b = a * 18000.0 + rng.normal(0, 1, (n, 2)) * 3.0
        sig = rng.uniform(2.0, 4.0, (n, 2))
        rls.update(a, b, sigma=sig)
        rows_a.append(a)
        rows_b.append(b)
        rows_v.append(sig**2)
    a, b, v = np.vstack(rows_a), np.vstack(rows_b), np.vstack(rows_v)
    s = np.sum(a * (b - a * rls.payload_kg) / v, axis=1)
    var = s @ s + sum(2 * (1 - j / (lag + 1)) * (s[j:] @ s[:-j]) for j in range(1, lag + 1))
    assert rls.hac_std_kg() == pytest.approx(np.sqrt(var) / np.sum(a * a / v), rel=1e-9)


def test_the_std_covers_errors_of_correlated_noise() -> None:
    """Noise correlated over several samples (as the angles' smoothing makes it): the
    filter's white-noise std covers about a third of the errors within 1 sigma; the
    pass's own Newey-West std about the honest 68 % (a little short at 2 sigma, its
    variance being estimated from some 70 effectively independent samples)."""
    rng = np.random.default_rng(9)
    rho, n, trials = 0.7, 400, 500
    e = np.empty((trials, n, 2))
    e[:, 0] = rng.normal(0, 1, (trials, 2))
    for k in range(1, n):
        e[:, k] = rho * e[:, k - 1] + np.sqrt(1 - rho**2) * rng.normal(0, 1, (trials, 2))
    a = 0.005 + 0.002 * np.sin(np.linspace(0, 3, n))[:, None] * np.ones(2)
    z, white = [], []
    for t in range(trials):
        rls = PayloadRls((3.0, 3.0), 0.02, hac_lag=41)
        for i in range(0, n, 10):
            rls.update(a[i:i + 10], a[i:i + 10] * 20000.0 + 3.0 * e[t, i:i + 10])
        z.append((rls.payload_kg - 20000.0) / rls.std_kg)
        white.append((rls.payload_kg - 20000.0) / np.sqrt(rls.p))
    assert np.mean(np.abs(white) < 1) < 0.45
    assert 0.6 < np.mean(np.abs(z) < 1) < 0.76
    assert 0.88 < np.mean(np.abs(z) < 2) <= 0.99


def test_the_smoothed_rates_noise_is_what_white_noise_leaves_after_the_fit() -> None:
    """``smoothed_noise_sd`` (the identification's errors-in-variables correction rests
    on it) against Monte Carlo: white noise through ``savgol_derivatives``, the value's,
    rate's and acceleration's spread within 3 %, and the rate's error uncorrelated with
    the acceleration's."""
    from shoveld.kinematics.offline import savgol_derivatives, smoothed_noise_sd

    rng = np.random.default_rng(11)
    dt, window, sigma = 0.02, 41, 0.002
    y = rng.normal(0.0, sigma, 60_000)
    v, r, a, ok = savgol_derivatives(y, dt, window, np.ones(len(y), dtype=bool))
    want = smoothed_noise_sd(sigma, dt, window)
    for got, sd in zip((v[ok], r[ok], a[ok]), want, strict=True):
        assert np.std(got) == pytest.approx(sd, rel=0.03)
    assert abs(np.corrcoef(r[ok], a[ok])[0, 1]) < 0.03
    assert np.corrcoef(v[ok], a[ok])[0, 1] < -0.3  # the value's and acceleration's are not


def test_a_position_readings_noise_is_read_from_its_third_differences() -> None:
    """A handle angle moving like a dig cycle (strokes of up to 0.9 rad/s², at 50 Hz) plus
    white noise of 0.03° gives back the noise within 5 %; the motion alone reads as
    under a tenth of it."""
    from shoveld.kinematics.offline import difference_noise

    rng = np.random.default_rng(4)
    t = np.arange(0.0, 120.0, 0.02)
    th = 0.4 * np.sin(2 * np.pi * t / 30) + 0.2 * np.sin(2 * np.pi * t / 3 + 1.0)
    sigma = math.radians(0.03)
    assert difference_noise(th, 3) < 0.1 * sigma
    assert difference_noise(th + rng.normal(0.0, sigma, len(t)), 3) == pytest.approx(
        sigma, rel=0.05)
