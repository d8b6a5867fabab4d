"""How long ``shoveld diagnose`` takes on one hour of 50 Hz operating data.

Simulates an hour of dig cycles (3-35 t, half the passes scale-verified) with a
hidden effect, plus the two calibration trials, writes them as signals tables, and
times the diagnosis through the command line's own steps: reading the tables, the
diagnosis with the live engine re-run on the verified passes, and the report.
Median of --repeat runs (the machine is shared).

    .venv/bin/python bench/diagnose_speed.py [--hours 1] [--effect payload_cog_offset=1]
                                             [--repeat 1]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--effect", default="payload_cog_offset=1.0")
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()

    from shoveld.diagnose import diagnose
    from shoveld.diagnose.report import write_report
    from shoveld.signals.table import read_table, write_table
    from shoveld.sim.effects import make_effects
    from shoveld.sim.scenario import simulate_calibration, simulate_cycles

    name, _, mag = args.effect.partition("=")
    spec = {name: float(mag)} if name else {}
    passes = max(4, int(round(args.hours * 3600 / 28.5)))
    t0 = time.perf_counter()
    c0 = simulate_calibration(0.0, 11, effects=make_effects(dict(spec)))
    c1 = simulate_calibration(8420.0, 12, effects=make_effects(dict(spec)))
    ops = simulate_cycles(passes, 13, payload_range=(3000.0, 35000.0), truck_target_kg=None,
                          verified_fraction=0.5, effects=make_effects(dict(spec)))
    hours = ops.table.time[-1] / 3600
    print(f"simulated {hours:.2f} h of 50 Hz data ({len(ops.table)} samples, {passes} passes)"
          f" in {time.perf_counter() - t0:.0f} s; hidden effect {spec or 'none'}")
    with tempfile.TemporaryDirectory() as tmp:
        paths = [Path(tmp) / f for f in ("c0.csv", "c1.csv", "ops.csv")]
        for p, tab in zip(paths, (c0.table, c1.table, ops.table), strict=True):
            write_table(p, tab)
        runs: list[dict[str, float]] = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            tabs = [read_table(p) for p in paths]
            t1 = time.perf_counter()
            d = diagnose(tabs[:2], tabs[2:], engine=True)
            t2 = time.perf_counter()
            write_report(d, Path(tmp) / "report")
            t3 = time.perf_counter()
            runs.append({"read": t1 - t0, "diagnose": t2 - t1, "report": t3 - t2,
                         "total": t3 - t0, **{f"  {k}": v for k, v in d.timing.items()}})
        print(f"found {d.found}; payload RMS base {d.payload('base').get('rms_kg')} kg -> "
              f"extended {d.payload('extended').get('rms_kg')} kg")
        for k in runs[0]:
            med = statistics.median(r[k] for r in runs)
            print(f"{k:14s} {med:7.1f} s  ({med / hours:6.1f} s per hour of data)")


if __name__ == "__main__":
    main()
