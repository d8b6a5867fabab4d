"""Throughput of the Xsens Xbus parser and MTData2 decoder on a realistic 100 Hz stream.

A shift is 8 h of 100 Hz MTi data = 2,880,000 MTData2 frames; replaying or decoding a
recorded shift must take seconds to tens of seconds. Prints frames/s per CPU
second (the machine may be shared; wall-clock rate beside it) and the extrapolated CPU
time per shift for three stages:

* framing: XbusParser.feed on 64 KiB chunks (resync machinery included);
* framing + decode_mtdata2 (every item to Python values);
* framing + MtiSerialDriver.decode (what the daemon does per packet: a Reading).

Streams: the driver's default packet (PacketCounter, SampleTimeFine, EulerAngles,
Quaternion; 51-byte frames) built by the emulator, and the real MTi-G-710 capture
(GNSS-rich 100-200 byte frames) repeated. ``--noise`` inserts
that fraction of random garbage bytes.

    .venv/bin/python bench/parsers_xsens.py [--frames 288000] [--shift] [--noise 0.01]
        [--repeat 3]
"""

from __future__ import annotations

import argparse
import logging
import math
import random
import time
from collections.abc import Callable
from pathlib import Path

from drivers.xsens.mtdata2 import decode_mtdata2
from drivers.xsens.serial_driver import MtiSerialDriver
from drivers.xsens.xbus import MID, XbusParser, encode_frame
from hil_fixtures.mti import MtiEmulator

SHIFT_FRAMES = 8 * 3600 * 100
CAPTURE = Path(__file__).resolve().parents[1] / "tests/fixtures/xsens-mti-g710/1/output.bin"


def daemon_stream(n_unique: int) -> list[bytes]:
    emu = MtiEmulator(lambda t: (0.3 * math.sin(t), 25.0 * math.sin(0.4 * t),
                                 (100.0 * t) % 360.0 - 180.0),
                      outputs=tuple(MtiSerialDriver(port="/dev/null").requested_outputs()))
    try:
        return [encode_frame(MID.MTDATA2, emu.packet(k)) for k in range(n_unique)]
    finally:
        emu.stop()


def capture_stream() -> list[bytes]:
    p = XbusParser()
    return [encode_frame(m.mid, m.data) for m in p.feed(CAPTURE.read_bytes())]


def build(frames: list[bytes], n: int, noise: float, seed: int = 1) -> bytes:
    rng = random.Random(seed)
    out = bytearray()
    for k in range(n):
        f = frames[k % len(frames)]
        out += f
        if noise and rng.random() < noise * len(f) / 20.0:  # ~noise of the bytes, 20 B bursts
            out += rng.randbytes(rng.randint(1, 39))
    return bytes(out)


def run(stream: bytes, per_frame: Callable[[bytes], object] | None
        ) -> tuple[int, float, float, int]:
    """(frames, CPU seconds, wall seconds, rejected bytes) of one pass over the stream."""
    p = XbusParser()
    t0 = time.perf_counter()
    c0 = time.process_time()
    n = 0
    for k in range(0, len(stream), 1 << 16):
        msgs = p.feed(stream[k:k + (1 << 16)])
        n += len(msgs)
        if per_frame is not None:
            for m in msgs:
                per_frame(m.data)
    p.finish()
    return n, time.process_time() - c0, time.perf_counter() - t0, p.rejected_bytes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=288_000, help="frames per stream")
    ap.add_argument("--shift", action="store_true", help="a full shift: 2,880,000 frames")
    ap.add_argument("--noise", type=float, default=0.0, help="fraction of garbage bytes")
    ap.add_argument("--repeat", type=int, default=3, help="runs per stage; the best is shown "
                    "(the machine may be shared)")
    args = ap.parse_args()
    logging.disable(logging.WARNING)  # the tiled stream repeats packet counters on purpose
    n = SHIFT_FRAMES if args.shift else args.frames
    drv = MtiSerialDriver(port="/dev/null")
    stages: list[tuple[str, Callable[[bytes], object] | None]] = [
        ("framing", None), ("framing + decode_mtdata2", decode_mtdata2),
        ("framing + driver Reading", drv.decode)]
    for label, frames in (("driver default (4 items)", daemon_stream(20_000)),
                          ("MTi-G-710 capture (13 items)", capture_stream())):
        stream = build(frames, n, args.noise)
        print(f"{label}: {n} frames, {len(stream) / 1e6:.1f} MB, "
              f"{len(stream) / n:.0f} B/frame, noise {args.noise:g}")
        for name, fn in stages:
            got, cpu, wall, rej = min((run(stream, fn) for _ in range(args.repeat)),
                                      key=lambda r: r[1])
            rate = got / cpu
            print(f"  {name:26s} {rate:9,.0f} frames/s CPU ({got / wall:9,.0f} wall)  one 8 h "
                  f"shift {SHIFT_FRAMES / rate:5.1f} s CPU  frames {got} rejected B {rej}")


if __name__ == "__main__":
    main()
