"""The engine's own filters against the library versions they replaced: the cost of one
joint-filter step, one payload update (a block of 10 samples, the live loop's batch),
and the import each needs.

    .venv/bin/python bench/filters.py [--repeat 7]

filterpy is a development dependency now (the oracle of ``tests/engine/test_filters.py``).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np


def per_call(fn: Callable[[], object], n: int, repeat: int) -> float:
    """Median over ``repeat`` runs of the time per call, in microseconds."""
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        out.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(out)


def import_time(module: str, repeat: int) -> float:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", f"import {module}"], check=True)
        out.append(time.perf_counter() - t0)
    base = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        base.append(time.perf_counter() - t0)
    return statistics.median(out) - statistics.median(base)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    from filterpy.common import Q_discrete_white_noise
    from filterpy.kalman import KalmanFilter

    from shoveld.kinematics.causal import Kalman3, white_jerk_q
    from shoveld.payload.rls import PayloadRls

    dt = 0.01
    F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.F, kf.H, kf.R = F, np.array([[1.0, 0.0, 0.0]]), np.array([[1e-6]])
    kf.Q = Q_discrete_white_noise(dim=3, dt=dt, var=1e-4)
    own = Kalman3(F, white_jerk_q(dt, 1e-4), 1e-6)

    def fp_step() -> None:
        kf.predict()
        kf.update(0.1)

    def own_step() -> None:
        own.predict()
        own.update(0.1)

    rng = np.random.default_rng(0)
    a = rng.uniform(0.01, 0.05, (10, 2))
    b = a * 20000.0
    r = np.array([9.0, 4.0])
    fk = KalmanFilter(dim_x=1, dim_z=2)
    fk.x, fk.P = np.array([[15000.0]]), np.array([[1.6e9]])

    def fp_rls() -> None:
        fk.Q = np.array([[0.0]])
        fk.predict()
        fk.update(b.reshape(-1, 1), R=np.diag(np.tile(r, 10)), H=a.reshape(-1, 1))

    rls = PayloadRls((3.0, 2.0), dt)

    def own_rls() -> None:
        rls.update(a, b)

    rows = [("joint filter step (3 states)", per_call(fp_step, 20000, args.repeat),
             per_call(own_step, 20000, args.repeat)),
            ("payload update, block of 10 samples", per_call(fp_rls, 5000, args.repeat),
             per_call(own_rls, 5000, args.repeat))]
    print(f"{'what':<40s} {'filterpy us':>12s} {'own us':>8s} {'ratio':>6s}")
    for name, f, o in rows:
        print(f"{name:<40s} {f:12.1f} {o:8.1f} {f / o:6.1f}")
    fp_imp = import_time("filterpy.kalman", args.repeat)
    own_imp = import_time("shoveld.payload.rls, shoveld.kinematics.causal", args.repeat)
    print(f"{'import (s over python -c pass)':<40s} {fp_imp:12.3f} {own_imp:8.3f}")


if __name__ == "__main__":
    main()
