"""How long calibrate and estimate take per hour of 50 Hz data.

Simulates one hour of dig cycles and one hour of calibration trials (half empty,
half known load), writes them as signals tables, then times reading, calibrating
and estimating (median of --repeat runs; the machine is shared, so medians and
multiples of real time are reported, not single timings).

    .venv/bin/python bench/engine_speed.py [--hours 1] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from shoveld.engine.offline import estimate_table
from shoveld.identify.calibrate import Calibrator
from shoveld.signals.table import read_table, write_table
from shoveld.sim.scenario import simulate_calibration, simulate_cycles


def timed(fn: Callable[[], object], repeat: int) -> float:
    runs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        runs.append(time.perf_counter() - t0)
    return statistics.median(runs)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    secs = 3600.0 * args.hours
    t0 = time.perf_counter()
    cyc = simulate_cycles(int(secs / 24.0), seed=1, payload_range=(3000, 35000))
    half = secs / 2
    e = simulate_calibration(0, seed=2, free_motion_s=half - 140)
    l_ = simulate_calibration(8420, seed=3, free_motion_s=half - 140)
    sim_s = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as d:
        paths = [Path(d) / n for n in ("cycles.csv", "empty.csv", "loaded.csv")]
        for p, r in zip(paths, (cyc, e, l_), strict=True):
            write_table(p, r.table)
        t_read = timed(lambda: read_table(paths[0]), args.repeat)
        n_rows = len(cyc.table)
        tables = [read_table(p) for p in paths[1:]]
        calib_rows = sum(len(t) for t in tables)
        t_cal = timed(lambda: Calibrator().fit(tables), args.repeat)
        params = Calibrator().fit(tables).params_
        assert params is not None  # fit sets it
        t_est = timed(lambda: estimate_table(cyc.table, params), args.repeat)
    data_h_cyc = cyc.table.time[-1] / 3600
    data_h_cal = sum(t.time[-1] for t in tables) / 3600
    print(f"simulated {data_h_cyc:.2f} h of cycles ({n_rows} rows, {len(cyc.passes)} passes) and "
          f"{data_h_cal:.2f} h of calibration ({calib_rows} rows) in {sim_s:.1f} s")
    print(f"read_table : {t_read / data_h_cyc:7.2f} s per hour of data "
          f"({3600 / (t_read / data_h_cyc):6.0f} x real time)")
    print(f"calibrate  : {t_cal / data_h_cal:7.2f} s per hour of data "
          f"({3600 / (t_cal / data_h_cal):6.0f} x real time)")
    print(f"estimate   : {t_est / data_h_cyc:7.2f} s per hour of data "
          f"({3600 / (t_est / data_h_cyc):6.0f} x real time)")
    print(f"(medians of {args.repeat} runs; 50 Hz)")


if __name__ == "__main__":
    main()
