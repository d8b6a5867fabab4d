"""`shoveld estimate` as a whole: seconds and peak memory per hour of 50 Hz signals.

Simulates a calibration (two trials) and two runs of dig cycles (about 1 and 3.5
hours) with `shoveld sim`, calibrates, then runs `shoveld estimate` on each run in a
fresh process. Reports the median time and peak resident memory of ``--runs`` runs;
the slope between the two lengths is what grows with the data (the rest is the
program and its imports).

    .venv/bin/python bench/estimate_memory.py [--runs 3] [--keep DIR]

Goal (issue 14): <= 50 MiB per hour of signals.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SHOVELD = [sys.executable, "-m", "shoveld"]


def sh(*args: str) -> None:
    subprocess.run([*SHOVELD, *args], check=True, stdout=subprocess.DEVNULL)


def estimate(params: Path, table: Path) -> tuple[float, float]:
    """Wall seconds and peak resident MiB of one `shoveld estimate` process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([*SHOVELD, "estimate", "--params", str(params), str(table)],
                            stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"shoveld estimate {table} failed")
    return time.perf_counter() - t0, usage.ru_maxrss / 1024.0


def hours(table: Path) -> float:
    truth = json.loads(Path(str(table) + ".truth.json").read_text())
    return float(truth["passes"][-1]["phases"]["return"][1]) / 3600.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--keep", help="write the tables here (default: a temporary folder)")
    args = ap.parse_args()
    tmp = tempfile.TemporaryDirectory()
    d = Path(args.keep or tmp.name)
    d.mkdir(parents=True, exist_ok=True)
    sh("sim", "--scenario", "calibration", "--load", "0", "--seed", "1", "--out",
       str(d / "c0.csv"))
    sh("sim", "--scenario", "calibration", "--load", "8420", "--seed", "2", "--out",
       str(d / "c1.csv"))
    sh("calibrate", str(d / "c0.csv"), str(d / "c1.csv"), "--out", str(d / "p.toml"))
    rows = []
    for passes, seed in ((130, 3), (390, 4)):
        table = d / f"cycles-{passes}.csv"
        sh("sim", "--passes", str(passes), "--seed", str(seed), "--out", str(table))
        runs = [estimate(d / "p.toml", table) for _ in range(args.runs)]
        rows.append((hours(table), statistics.median(r[0] for r in runs),
                     statistics.median(r[1] for r in runs), [round(r[1]) for r in runs]))
    print(f"{'hours':>6s} {'s (median)':>11s} {'peak MiB (median)':>18s}  runs")
    for h, s, m, all_m in rows:
        print(f"{h:6.2f} {s:11.2f} {m:18.1f}  {all_m}")
    (h1, s1, m1, _), (h2, s2, m2, _) = rows
    print(f"per hour of signals: {(m2 - m1) / (h2 - h1):.0f} MiB, "
          f"{(s2 - s1) / (h2 - h1):.2f} s ({3600 * (h2 - h1) / (s2 - s1):.0f}x real time)")


if __name__ == "__main__":
    main()
