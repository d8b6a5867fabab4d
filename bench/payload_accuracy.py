"""Accuracy of identification and per-pass payload on simulated data.

Prints: the error of every identified parameter against the simulator's truth
(thesis Table 5 values for Md, Lc, K_H, K_C), the per-pass payload error over many
passes of 3 to 35 t (mean, RMS, 95th percentile, in kg and % of the 35 t rated
load), the empty-dipper and 8,420 kg known-load results (the thesis's trials),
and how often the reported std covers the error.

    .venv/bin/python bench/payload_accuracy.py [--passes 60] [--seeds 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from shoveld.engine.offline import estimate_table
from shoveld.identify.calibrate import Calibrator
from shoveld.sim.plant import PlantParams
from shoveld.sim.scenario import RATED_PAYLOAD_KG, simulate_calibration, simulate_cycles


def per_pass_errors(params, res) -> tuple[np.ndarray, np.ndarray, int]:
    est = estimate_table(res.table, params)
    errs, stds, missed = [], [], 0
    for tp in res.passes:
        near = [p for p in est.passes if abs(p.start_s - tp.phases["dig"][0]) < 2.0]
        if not near or not near[0].valid:
            missed += 1
            continue
        errs.append(near[0].payload_kg - tp.payload_kg)
        stds.append(near[0].std_kg)
    return np.array(errs), np.array(stds), missed


def stats(label: str, e: np.ndarray) -> None:
    r = RATED_PAYLOAD_KG / 100
    print(f"  {label:28s} n={len(e):3d}  mean {e.mean():+7.0f} kg ({e.mean() / r:+.2f} %)  "
          f"RMS {np.sqrt(np.mean(e**2)):6.0f} kg ({np.sqrt(np.mean(e**2)) / r:.2f} %)  "
          f"p95 |err| {np.percentile(np.abs(e), 95):6.0f} kg "
          f"({np.percentile(np.abs(e), 95) / r:.2f} %)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--passes", type=int, default=60, help="passes per seed")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--method", default="staged")
    args = ap.parse_args()
    pp = PlantParams()
    truth = {"Md": pp.Md, "MdLc": pp.Md * pp.Lc, "K_H": pp.K_H, "K_C": pp.K_C,
             "J": pp.Izz + pp.Md * pp.Lc**2, "fv3": pp.fv3, "fc3": pp.fc3, "fv4": pp.fv4,
             "fc4": pp.fc4}
    all_err, all_std, empty, known = [], [], [], []
    missed = 0
    for seed in range(args.seeds):
        t0 = time.perf_counter()
        cal = Calibrator(method=args.method).fit(
            [simulate_calibration(0, seed=1000 + seed).table,
             simulate_calibration(8420, seed=2000 + seed).table])
        p = cal.params_
        assert p is not None
        print(f"seed {seed}: identification ({args.method}), "
              f"condition number {p.fit['condition_number']:.1f}")
        for n, v, se in zip(p.names, p.values, p.stderr, strict=True):
            tv = truth[n]
            print(f"  {n:5s} {v:12.6g} +- {se:9.3g}   truth {tv:12.6g}   error "
                  f"{100 * (v - tv) / tv:+6.2f} %  ({(v - tv) / se:+5.1f} sigma)")
        print(f"  Lc = MdLc/Md = {p.get('MdLc') / p.get('Md'):.3f} m (truth {pp.Lc})")
        res = simulate_cycles(args.passes, seed=3000 + seed, payload_range=(3000, 35000))
        e, s, m = per_pass_errors(p, res)
        missed += m
        all_err.append(e)
        all_std.append(s)
        e0, _, m0 = per_pass_errors(p, simulate_cycles(8, seed=4000 + seed, payloads=[0.0] * 8))
        empty.append(e0)
        ek, _, mk = per_pass_errors(p, simulate_cycles(8, seed=5000 + seed,
                                                       payloads=[8420.0] * 8))
        known.append(ek)
        missed += m0 + mk
        print(f"  ({time.perf_counter() - t0:.1f} s)")
    e = np.concatenate(all_err)
    s = np.concatenate(all_std)
    print(f"\nper-pass payload error, {args.seeds} seeds, passes uniform in 3..35 t "
          f"(rated {RATED_PAYLOAD_KG:.0f} kg); passes missed or invalid: {missed}")
    stats("3..35 t", e)
    stats("empty dipper (truth 0 kg)", np.concatenate(empty))
    ek = np.concatenate(known)
    stats("known load 8,420 kg", ek)
    print(f"  known load: mean estimate {8420 + ek.mean():.0f} kg ({100 * ek.mean() / 8420:+.2f} %"
          " of the load; thesis: 8,310 kg lift -1.3 %, 8,340 kg swing -1.0 %)")
    print(f"  reported std covers the error: |err| < 1 std in {np.mean(np.abs(e) < s):.0%}, "
          f"< 2 std in {np.mean(np.abs(e) < 2 * s):.0%} of passes (normal: 68 %, 95 %)")


if __name__ == "__main__":
    main()
