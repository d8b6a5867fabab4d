"""Throughput of the AR4000 line parser: lines per second through the driver's parse path.

Measures the same code the driver runs on every chunk (line splitting, parsing,
zero/plausibility checks, Reading construction), fed in 64-byte chunks like a
serial read would deliver them, with 5 % garbage lines mixed in.

    .venv/bin/python bench/parsers_ar4000.py [--lines 200000]
"""

from __future__ import annotations

import argparse
import random
import time

from drivers.acuity.ar4000 import Ar4000Config, Ar4000Driver, parse_line


def make_stream(n: int, seed: int = 1) -> bytes:
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        r = rng.random()
        if r < 0.05:
            out.append(b"#\x8f@junk\r\n")
        elif r < 0.08:
            out.append(b"0\r\n")
        else:
            out.append(f"{rng.randint(1000, 16000)}\r\n".encode())
    return b"".join(out)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--lines", type=int, default=200_000)
    args = p.parse_args(argv)
    stream = make_stream(args.lines)
    chunks = [stream[i:i + 64] for i in range(0, len(stream), 64)]

    lines = stream.split(b"\r\n")[:-1]
    t0 = time.perf_counter()
    for line in lines:
        parse_line(line, 0.001)
    dt = time.perf_counter() - t0
    print(f"parse_line:            {len(lines) / dt:12,.0f} lines/s")

    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/null"))
    out: list[object] = []
    t0 = time.perf_counter()
    for c in chunks:
        drv._parse(c, out.append, 0.0)
    dt = time.perf_counter() - t0
    print(f"driver parse (chunks): {args.lines / dt:12,.0f} lines/s  "
          f"({len(out)} readings, {drv.health.bad_frames} bad lines, "
          f"{len(stream) / dt / 1e6:.1f} MB/s)")
    for baud in (9600, 115200):
        print(f"for scale: {baud} baud 8N1 carries {baud / 10 / 7:,.0f} seven-byte lines/s")


if __name__ == "__main__":
    main()
