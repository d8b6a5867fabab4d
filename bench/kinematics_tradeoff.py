"""Lag/noise trade-off of the live loop's Kalman joint filters, and what it does to payload.

For a range of jerk intensities (the filter's one tuning knob) it runs the causal
filter over simulated dig cycles and compares with the simulator's true rates:
RMS error and lag of the handle rate and acceleration in lift and swing, and the
per-pass payload error of the whole engine. The zero-phase offline smoother used
for identification is shown for reference.

    .venv/bin/python bench/kinematics_tradeoff.py [--passes 20]
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np

import shoveld.engine.loop as loop
from shoveld.cycle.phases import ESTIMATING
from shoveld.engine.loop import EngineConfig
from shoveld.engine.offline import estimate_table
from shoveld.identify.calibrate import Calibrator
from shoveld.kinematics import DEFAULT_POLYORDER, DEFAULT_WINDOW_S, causal
from shoveld.kinematics.fixed_lag import FixedLagSavgol
from shoveld.kinematics.offline import offline_kinematics
from shoveld.sim.plant import derivative
from shoveld.sim.scenario import CHUNK_PASSES, simulate_calibration, simulate_cycles


def lag_s(est: np.ndarray, true: np.ndarray, dt: float, max_lag: int = 25) -> float:
    """Delay that best aligns est with true (positive: est lags)."""
    best, arg = -np.inf, 0
    for k in range(0, max_lag):
        c = np.corrcoef(est[k:], true[: len(true) - k])[0, 1]
        if c > best:
            best, arg = c, k
    return arg * dt


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--passes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args()
    params = Calibrator().fit([simulate_calibration(0, seed=1).table,
                               simulate_calibration(8420, seed=2).table]).params_
    assert params is not None  # fit sets it
    # One segment however many passes: the true motion compared with is kept only for a
    # run simulated in one (over CHUNK_PASSES passes the default is several, no motion).
    res = simulate_cycles(args.passes, seed=args.seed, payload_range=(3000, 35000),
                          chunk_passes=max(args.passes, CHUNK_PASSES))
    m = res.motion
    assert m is not None and res.ctx is not None  # one segment: kept
    assert m.phase is not None  # Motion.__post_init__ sets it
    dtf = m.t[1] - m.t[0]
    idx = res.ctx["sample_index"]
    true_thd = derivative(m.th, dtf)[idx]
    true_thdd = derivative(derivative(m.th, dtf), dtf)[idx]
    sel = np.isin(m.phase[idx], list(ESTIMATING))
    table = res.table
    dt = 1.0 / table.sample_rate_hz
    truth = np.array([p.payload_kg for p in res.passes])
    print(f"{args.passes} passes, 50 Hz; errors over lift and swing samples")
    print(f"{'filter':>22s} {'thd rms':>9s} {'thd lag':>8s} {'thdd rms':>9s} {'thdd lag':>9s}"
          f" {'payload rms':>12s} {'p95':>7s}")
    kin, _ = offline_kinematics(table)
    e1 = kin.thd - true_thd
    e2 = kin.thdd - true_thdd
    ok = sel & np.isfinite(e1)
    print(f"{'zero-phase (offline)':>22s} {math.degrees(np.sqrt(np.mean(e1[ok]**2))):8.3f}d"
          f" {lag_s(kin.thd[ok], true_thd[ok], dt) * 1000:6.0f}ms"
          f" {math.degrees(np.sqrt(np.mean(e2[ok]**2))):8.3f}d"
          f" {lag_s(kin.thdd[ok], true_thdd[ok], dt) * 1000:7.0f}ms {'-':>12s} {'-':>7s}")
    original = causal.HANDLE
    for jerk in (0.5, 1.0, 2.0, 4.0, 8.0):
        causal.HANDLE = dataclasses.replace(original, jerk_std=jerk)
        f = causal.JointFilter(causal.HANDLE, dt)
        est = np.array([f.update(t, math.radians(h))
                        for t, h in zip(table.time, table["handle_deg"], strict=True)])
        e1 = est[:, 1] - true_thd
        e2 = est[:, 2] - true_thdd
        loop.HANDLE = causal.HANDLE
        ests = estimate_table(table, params, EngineConfig(payload_rates="kalman")).passes
        got = np.array([p.payload_kg for p in ests])
        err = got - truth if len(got) == len(truth) else np.full(1, np.nan)
        print(f"{'kalman jerk=' + format(jerk, 'g'):>22s}"
              f" {math.degrees(np.sqrt(np.mean(e1[sel]**2))):8.3f}d"
              f" {lag_s(est[sel, 1], true_thd[sel], dt) * 1000:6.0f}ms"
              f" {math.degrees(np.sqrt(np.mean(e2[sel]**2))):8.3f}d"
              f" {lag_s(est[sel, 2], true_thdd[sel], dt) * 1000:7.0f}ms"
              f" {np.sqrt(np.mean(err**2)):10.0f}kg {np.percentile(np.abs(err), 95):6.0f}kg")
    causal.HANDLE = original
    loop.HANDLE = original
    ests = estimate_table(table, params, EngineConfig(payload_rates="fixed_lag")).passes
    err = np.array([p.payload_kg for p in ests]) - truth
    fixed: FixedLagSavgol[float] = FixedLagSavgol(DEFAULT_WINDOW_S, dt, 1, DEFAULT_POLYORDER)
    fl = [fixed.push(t, (math.radians(h),), t) for t, h in zip(table.time, table["handle_deg"],
                                                                   strict=True)]
    t_c = np.array([o[0] for o in fl if o is not None])
    k = np.array([o[1][:, 0] for o in fl if o is not None])
    j = np.searchsorted(table.time, t_c)
    ok = sel[j]
    e1, e2 = k[ok, 1] - true_thd[j][ok], k[ok, 2] - true_thdd[j][ok]
    print(f"{'fixed-lag (0.25 s late)':>22s} {math.degrees(np.sqrt(np.mean(e1**2))):8.3f}d"
          f" {0:6.0f}ms {math.degrees(np.sqrt(np.mean(e2**2))):8.3f}d {0:7.0f}ms"
          f" {np.sqrt(np.mean(err**2)):10.0f}kg {np.percentile(np.abs(err), 95):6.0f}kg"
          "   <- used for the payload")
    print(f"payload mean error: fixed-lag {err.mean():+.0f} kg")
    print("(rates in deg/s, accelerations in deg/s^2; the Kalman filter (default jerk ="
          f" {original.jerk_std}) drives the phases and the published joints)")


if __name__ == "__main__":
    main()
