"""The signals table reader: seconds and peak memory per hour of 50 Hz signals.

Writes two simulated tables (about 1 and 3 hours), reads each in a fresh process and
reports the median time and the peak resident memory; the slope between the two is
the memory per hour of signals (what grows with the data), the rest is the program.

    .venv/bin/python bench/table_read.py [--runs 3]

Goal (issue 14): <= 50 MiB per hour of signals, and reading at least 3x faster than the
cell-by-cell reader (the reader's own fallback, timed here for the ratio).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

READ = ("import sys, shoveld.signals.table as T\n"
        "if sys.argv[2] == 'cells':\n"
        "    T._fast_chunk = lambda chunk, prev: (None, prev)\n"
        "T.read_table(sys.argv[1])\n")


def run(path: Path, mode: str) -> tuple[float, float]:
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", READ, str(path), mode])
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"reading {path} failed")
    return time.perf_counter() - t0, usage.ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        sizes = {}
        for passes in (110, 330):
            p = Path(tmp) / f"t{passes}.csv"
            subprocess.run([sys.executable, "-m", "shoveld", "sim", "--passes", str(passes),
                            "--out", str(p)], check=True, stdout=subprocess.DEVNULL)
            with open(p) as f:
                hours = (sum(1 for _ in f) - 10) / 50.0 / 3600.0
            sizes[p] = hours
        res: dict[tuple[Path, str], tuple[float, float]] = {}
        for p in sizes:
            for mode in ("numpy", "cells"):
                runs = [run(p, mode) for _ in range(args.runs)]
                res[p, mode] = (statistics.median(r[0] for r in runs),
                                max(r[1] for r in runs))
    (a, ha), (b, hb) = sizes.items()
    print(f"{'reader':<8s} {'s per hour':>11s} {'MiB per hour':>13s} {'peak MiB (3 h)':>15s}")
    for mode in ("numpy", "cells"):
        s_h = res[b, mode][0] / hb
        mib_h = (res[b, mode][1] - res[a, mode][1]) / (hb - ha)
        print(f"{mode:<8s} {s_h:11.2f} {mib_h:13.0f} {res[b, mode][1]:15.0f}")
    print(f"speed-up of the numpy path: {res[b, 'cells'][0] / res[b, 'numpy'][0]:.1f}x "
          f"(whole process, median of {args.runs})")


if __name__ == "__main__":
    main()
