"""Modbus ADC emulator: a real pymodbus server whose registers follow a signals source.

The emulated module is a typical 8-channel +-10 V analog-input module. On every
request the registers are computed from ``source(t)`` (a mapping of column name
to engineering value) through the :class:`~drivers.modbus_adc.ChannelMap`
*inverse*, so the driver's decode is checked against the same numbers. The
module can stop answering (``silent = True``) or answer with a Modbus exception
(``exception_code = 4``). TCP runs on 127.0.0.1 with a free port; RTU runs over a
pseudo-terminal (``emulator.serial_port``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping

import numpy as np

from drivers.modbus_adc.channels import ChannelMap
from drivers.modbus_adc.server import RegisterServer
from shoveld.signals import SignalsTable

ValuesSource = Callable[[float], Mapping[str, float]]


def source_from_table(table: SignalsTable, channels: ChannelMap,
                      t_offset: float | None = None) -> ValuesSource:
    """Channel values along a signals table, linearly interpolated in time.

    ``t`` maps to table time ``t_offset + t`` (default: the first row's time);
    past the end the last row holds. Blank cells stay NaN (register left at 0).
    """
    tt = np.asarray(table.time, dtype=float)
    cols = {c.name: np.asarray(table[c.name], dtype=float) for c in channels}
    off = float(tt[0]) if t_offset is None else t_offset

    def source(t: float) -> dict[str, float]:
        x = t + off
        return {n: float(np.interp(x, tt, a)) for n, a in cols.items()}

    return source


class ModbusAdcEmulator:
    """An analog-input module on Modbus TCP or RTU; start with :meth:`start` or ``with``."""

    def __init__(self, source: ValuesSource, channels: ChannelMap, *, transport: str = "tcp",
                 unit: int = 1, clock: Callable[[], float] | None = None,
                 baudrate: int = 19200) -> None:
        self.source = source
        self.channels = channels
        self.unit = unit
        self._origin = time.monotonic()
        self.clock: Callable[[], float] = clock or (lambda: time.monotonic() - self._origin)
        self.exception_code: int | None = None
        """Answer every request with this Modbus exception code (None: answer normally)."""
        self.server = RegisterServer(self._provide, transport=transport, unit=unit,
                                     baudrate=baudrate)

    @property
    def silent(self) -> bool:
        return self.server.silent

    @silent.setter
    def silent(self, v: bool) -> None:
        self.server.silent = v

    @property
    def host(self) -> str:
        return self.server.host

    @property
    def port(self) -> int:
        return self.server.port

    @property
    def serial_port(self) -> str | None:
        return self.server.serial_port

    @property
    def requests(self) -> int:
        return self.server.requests

    def _provide(self, fc: int, address: int, count: int) -> list[int] | int | None:
        if self.exception_code is not None:
            return self.exception_code
        values = {k: v for k, v in self.source(self.clock()).items() if not math.isnan(v)}
        return self.channels.encode(values, address, count)

    def driver_config(self, **extra: object) -> dict[str, object]:
        """A config table for :class:`~drivers.modbus_adc.ModbusAdcDriver` pointing here."""
        if self.server.transport == "tcp":
            d: dict[str, object] = {"kind": "modbus_tcp", "host": self.host, "port": self.port}
        else:
            d = {"kind": "modbus_rtu", "port": self.serial_port,
                 "baudrate": self.server.baudrate}
        d.update(unit=self.unit, channels=self.channels.to_config())
        d.update(extra)
        return d

    def start(self) -> ModbusAdcEmulator:
        self.server.start()
        return self

    def stop(self) -> None:
        self.server.stop()

    def __enter__(self) -> ModbusAdcEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
