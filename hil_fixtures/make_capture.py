"""Turn a signals table into a capture by recording the virtual shovel with real drivers.

The emulators play the table as device byte streams and the real drivers record
them through their taps, so the capture is what ``shoveld record`` would have
written on a shovel that moved like the table. The clock is a paced
:class:`~drivers.capture.clock.ReplayClock` running ``--speed`` times faster than
real time (emulators and drivers share it, and capture time 0 is table time
``table.time[0]``), so a ten-minute table records in about a minute at speed 10.

Usage::

    python -m hil_fixtures.make_capture TABLE.csv OUT_DIR [--speed 5] [--mti serial|can|none]

The manifest gets ``signals_table`` (file, first time, rows, known payload) so the
expected payloads can be attached once the engine exists (TODO: ``expected``).
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

from drivers.capture.clock import ReplayClock
from drivers.capture.recorder import Recorder
from hil_fixtures.virtual_shovel import VirtualShovel
from shoveld.installation import Installation
from shoveld.signals import SignalsTable, read_table


def make_capture(table: SignalsTable, out_dir: str | Path, *, speed: float = 5.0,
                 mti: str | None = "serial", installation: Installation | None = None,
                 duration_s: float | None = None, adc_transport: str = "tcp",
                 overwrite: bool = False) -> dict[str, Any]:
    """Record ``table`` through the emulators into ``out_dir``; return the summary."""
    clock = ReplayClock(0.0, speed=speed)
    span = float(table.time[-1] - table.time[0])
    duration = span if duration_s is None else min(duration_s, span)
    with VirtualShovel(table, installation, clock=clock, mti=mti,
                       adc_transport=adc_transport) as shovel:
        # time_origin=0: capture time = clock time, which lines up with the table
        rec = Recorder(shovel.config(), out_dir, clock=clock, overwrite=overwrite,
                       source="hil_fixtures.make_capture", time_origin=0.0)
        rec.writer.set_meta("signals_table", {
            "file": table.source, "t0_s": float(table.time[0]), "rows": len(table),
            "known_payload_kg": table.known_payload_kg,
            "note": "capture time t corresponds to table time t0_s + t"})
        rec.writer.set_meta("expected", None)  # TODO: expected payloads once the engine exists
        summary = rec.run(duration)
    return {"capture": str(Path(out_dir)), "duration_s": duration, "speed": speed,
            "devices": summary}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m hil_fixtures.make_capture",
                                description=__doc__.splitlines()[0])
    p.add_argument("table", help="signals table (shovel-signals/1 CSV)")
    p.add_argument("out", help="capture folder to create")
    p.add_argument("--speed", type=float, default=5.0, help="times faster than real time")
    p.add_argument("--mti", choices=("serial", "can", "none"), default="serial")
    p.add_argument("--adc", choices=("tcp", "rtu"), default="tcp")
    p.add_argument("--duration", type=float, default=None, help="capture seconds (default: "
                   "the whole table)")
    p.add_argument("--overwrite", action="store_true")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    table = read_table(args.table)
    summary = make_capture(table, args.out, speed=args.speed,
                           mti=None if args.mti == "none" else args.mti,
                           duration_s=args.duration, adc_transport=args.adc,
                           overwrite=args.overwrite)
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
