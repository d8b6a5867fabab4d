"""The signals table reader: seconds and peak memory per hour of 50 Hz signals.

Writes two simulated tables (about 1 and 3 hours), reads each in a fresh process and
reports the median time and the peak resident memory; the slope between the two is
the memory per hour of signals (what grows with the data), the rest is the program.
The whole process (interpreter, imports, read) is the figure and gives the speed-up;
the read alone (``read_table`` timed inside the process) is printed beside it, to show
what the process's start (the same for both readers) takes out of the ratio.

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

READ = ("import sys, time, shoveld.signals.table as T\n"
        "if sys.argv[2] == 'cells':\n"
        "    T._read_fast = lambda data, offset: None\n"
        "t0 = time.perf_counter()\n"
        "T.read_table(sys.argv[1])\n"
        "print(time.perf_counter() - t0)\n")


def run(path: Path, mode: str) -> tuple[float, float, float]:
    """Whole-process seconds, peak resident MiB, and the seconds of the read alone."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", READ, str(path), mode],
                            stdout=subprocess.PIPE, text=True)
    out = proc.stdout.read() if proc.stdout else ""
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if proc.stdout:
        proc.stdout.close()
    if os.waitstatus_to_exitcode(status):
        raise SystemExit(f"reading {path} failed")
    return wall, usage.ru_maxrss / 1024.0, float(out)


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
        res: dict[tuple[Path, str], tuple[float, float, float]] = {}
        for p in sizes:
            for mode in ("arrow", "cells"):
                runs = [run(p, mode) for _ in range(args.runs)]
                res[p, mode] = (statistics.median(r[0] for r in runs),
                                max(r[1] for r in runs),
                                statistics.median(r[2] for r in runs))
    (a, ha), (b, hb) = sizes.items()
    print(f"{'reader':<8s} {'s per hour':>11s} {'MiB per hour':>13s} {'peak MiB (3 h)':>15s}"
          f" {'read alone, s per hour':>23s}")
    for mode in ("arrow", "cells"):
        s_h = res[b, mode][0] / hb
        mib_h = (res[b, mode][1] - res[a, mode][1]) / (hb - ha)
        print(f"{mode:<8s} {s_h:11.2f} {mib_h:13.0f} {res[b, mode][1]:15.0f}"
              f" {res[b, mode][2] / hb:23.2f}")
    print(f"speed-up of the Arrow path: {res[b, 'cells'][0] / res[b, 'arrow'][0]:.1f}x "
          f"(whole process, median of {args.runs}; the read alone: "
          f"{res[b, 'cells'][2] / res[b, 'arrow'][2]:.1f}x)")


if __name__ == "__main__":
    main()
