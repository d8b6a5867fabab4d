"""A Modbus module that answers after the driver's timeout (issue 12's "a Modbus module
that answers late"): how many of its late answers the driver sees, and how many it
takes as values, over TCP and over RTU.

The emulator (a real pymodbus server; over RTU on a pair of pseudo-terminals) answers
every request ``delay`` seconds late, against the driver's 0.05 s timeout at 100 Hz, for
``--seconds`` each. Over TCP a value taken is its request's own answer, matched by its
transaction id (timed around the driver's requests on 2026-12-02, the answers taken at
0.06 and 0.2 s came 10-12 ms after their request in the median, at most 50 ms: in steady
state this emulator's answers mostly come in time); over RTU, where an answer carries no
id, a value taken is an earlier request's answer published as new (every one was, until
2026-12-02). Printed per transport and delay: the requests that timed out, the late
answers counted, the readings with values taken after the first half second of the fault
(``taken``) and all readings in that time, and whether health names the fault.

    .venv/bin/python bench/modbus_late.py [--seconds 4] [--delays 0.06,0.08,0.12,0.2,0.3,0.5]
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from typing import Any

from drivers.modbus_adc import ChannelMap, ModbusAdcDriver
from hil_fixtures.modbus_adc import ModbusAdcEmulator
from hil_fixtures.virtual_shovel import DriverRunner

CHANNELS = ChannelMap.from_config([
    {"name": "hoist1_a", "register": 0, "scale": 400.0},
    {"name": "crowd_a", "register": 1, "scale": 400.0},
])
VALUES = {"hoist1_a": 2345.6, "crowd_a": -1234.5}
TIMEOUT_S = 0.05
SETTLE_S = 0.5
"""Readings in the first half second of the fault may answer requests sent before it."""


def one(transport: str, delay: float, seconds: float) -> dict[str, Any]:
    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS, transport=transport) as emu:
        cfg = emu.driver_config(poll_hz=100, timeout_s=TIMEOUT_S, stale_after_s=0.2,
                                reconnect_after=100000)
        with DriverRunner(ModbusAdcDriver.from_config("adc", cfg, backoff_s=(0.05, 0.2))
                          ) as run:
            h = run.driver.health
            if not run.wait_for(lambda: len(run.readings) >= 5, 10):
                raise SystemExit(f"{transport}: the driver read nothing from the emulator")
            t0, late0 = h.timeouts, h.extra["late_answers"]
            emu.server.delay_s = delay
            time.sleep(SETTLE_S)
            n = len(run.readings)
            time.sleep(seconds - SETTLE_S)
            rs = run.readings[n:]
            return {"transport": transport, "delay_s": delay, "timeouts": h.timeouts - t0,
                    "late_answers": h.extra["late_answers"] - late0,
                    "taken": sum(1 for r in rs if r.values), "readings": len(rs),
                    "named": bool(h.extra["answering_late"])}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--delays", default="0.06,0.08,0.12,0.2,0.3,0.5")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    logging.basicConfig(level=logging.CRITICAL)
    rows = [one(tr, float(d), args.seconds) for tr in ("tcp", "rtu")
            for d in args.delays.split(",")]
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"module answering late, driver timeout {TIMEOUT_S} s, 100 Hz, {args.seconds:g} s "
          "each (after the first half second: readings with values taken, of all)")
    print(f"{'transport':>9} {'delay s':>8} {'timeouts':>9} {'late':>6} {'taken':>6} "
          f"{'of':>5}  named")
    for r in rows:
        print(f"{r['transport']:>9} {r['delay_s']:>8g} {r['timeouts']:>9} "
              f"{r['late_answers']:>6} {r['taken']:>6} {r['readings']:>5}  "
              f"{'yes' if r['named'] else 'no'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
