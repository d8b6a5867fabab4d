"""Start-up time of the command line: ``shoveld --help``, ``shoveld replay --help`` and
the daemon's imports, against ``python -c pass`` in the same run (the machines are
shared: the ratio to a bare interpreter holds better than seconds).

    .venv/bin/python bench/startup.py [--runs 15]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

CASES: dict[str, list[str]] = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "shoveld --help": [sys.executable, "-m", "shoveld", "--help"],
    "shoveld replay --help": [sys.executable, "-m", "shoveld", "replay", "--help"],
    "daemon imports (shoveld.daemon.service)": [
        sys.executable, "-c", "import shoveld.daemon.service"],
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=15)
    args = ap.parse_args()
    times: dict[str, list[float]] = {k: [] for k in CASES}
    for _ in range(args.runs):  # interleaved, so a burst of load hits every case alike
        for name, cmd in CASES.items():
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
            times[name].append(time.perf_counter() - t0)
    base = statistics.median(times["python -c pass"])
    print(f"{'command':<42s} {'median':>8s} {'min':>8s} {'max':>8s}  over python -c pass")
    for name, ts in times.items():
        med = statistics.median(ts)
        print(f"{name:<42s} {med:8.3f} {min(ts):8.3f} {max(ts):8.3f}  +{med - base:.3f} s")


if __name__ == "__main__":
    main()
