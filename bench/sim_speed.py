"""Time and peak memory of ``shoveld sim`` against the number of passes: the simulator
streams whole trucks to disk, so both should grow linearly (time) or not at all (memory).

    .venv/bin/python bench/sim_speed.py [--passes 100 300 1000] [--runs 1]

Goal (issue 14): 1,000 passes in < 60 s and < 500 MiB.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time


def run_once(passes: int, out: str) -> tuple[float, float]:
    """Wall seconds and peak resident MiB of one ``shoveld sim`` process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "shoveld", "sim", "--passes", str(passes),
                             "--seed", "1", "--out", out], stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"shoveld sim --passes {passes} failed")
    return wall, usage.ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--passes", type=int, nargs="+", default=[100, 300, 1000])
    ap.add_argument("--runs", type=int, default=1)
    args = ap.parse_args()
    print(f"{'passes':>7s} {'wall s (median)':>16s} {'s per pass':>11s} {'peak MiB':>9s}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.passes:
            res = [run_once(n, os.path.join(tmp, f"s{n}.csv")) for _ in range(args.runs)]
            wall = statistics.median(r[0] for r in res)
            mem = max(r[1] for r in res)
            print(f"{n:7d} {wall:16.1f} {wall / n:11.3f} {mem:9.0f}", flush=True)


if __name__ == "__main__":
    main()
