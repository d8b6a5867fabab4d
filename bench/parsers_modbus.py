"""Throughput of Modbus ADC decoding: register blocks decoded to engineering values per second.

Two figures: the channel-map decode alone (words -> {name: value}), and a full
driver poll against an in-process fake client (decode, health bookkeeping,
Reading), which is the per-poll CPU cost the daemon pays besides the network.

    .venv/bin/python bench/parsers_modbus.py [--blocks 200000]
"""

from __future__ import annotations

import argparse
import random
import time
from typing import Any

from drivers.modbus_adc import ModbusAdcConfig, ModbusAdcDriver
from hil_fixtures.virtual_shovel import MOTOR_CHANNELS


class _Resp:
    def __init__(self, regs: list[int]) -> None:
        self.registers = regs

    def isError(self) -> bool:  # noqa: N802 - pymodbus API name
        return False


class _FakeClient:
    connected = True

    def __init__(self, blocks: list[list[int]]) -> None:
        self._blocks = blocks
        self._i = 0

    def read_input_registers(self, address: int, *, count: int, device_id: int) -> Any:
        self._i += 1
        return _Resp(self._blocks[self._i % len(self._blocks)])


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--blocks", type=int, default=200_000)
    args = p.parse_args(argv)
    rng = random.Random(1)
    (addr, count, _), = MOTOR_CHANNELS.blocks()
    blocks = [[rng.randrange(65536) for _ in range(count)] for _ in range(1024)]

    t0 = time.perf_counter()
    for i in range(args.blocks):
        MOTOR_CHANNELS.decode(addr, blocks[i & 1023])
    dt = time.perf_counter() - t0
    print(f"ChannelMap.decode ({count} ch):   {args.blocks / dt:12,.0f} blocks/s "
          f"({args.blocks * len(MOTOR_CHANNELS) / dt:,.0f} values/s)")

    cfg = ModbusAdcConfig.from_config({"kind": "modbus_tcp", "host": "bench",
                                       "channels": MOTOR_CHANNELS.to_config()})
    drv = ModbusAdcDriver("adc", cfg)
    drv._client = _FakeClient(blocks)
    n = args.blocks // 4
    t0 = time.perf_counter()
    for _ in range(n):
        drv.poll(lambda r: None)
    dt = time.perf_counter() - t0
    print(f"driver poll (decode+health):  {n / dt:12,.0f} polls/s  ({1e6 * dt / n:.1f} us/poll; "
          "a 50 Hz poll uses "
          f"{50 * dt / n * 100:.3f} % of a core)")


if __name__ == "__main__":
    main()
