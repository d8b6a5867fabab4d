"""Fast replay: the drivers' own code on in-memory transports, stepped by the loop itself.

The threaded replay (:mod:`shoveld.replay.service`) runs every driver in its thread
against ptys, a virtual CAN bus and a Modbus server, exactly like live; but each
10 ms tick then needs several thread and socket hand-offs, which limits it to a few
times real time, and the order in which threads see data can vary between runs.

Here the same driver classes (their ``open`` handshakes, parsers, validity rules
and health counters) read from in-memory transports - a pyserial-like port, a
python-can-like bus, a Modbus client - that hold the recording, answered by the
drivers' replay helpers (:class:`~drivers.capture.replay.RecordedAnswers`,
:class:`~drivers.capture.replay.RecordedRegisters`). Before each tick the loop
releases the recorded data up to the tick time and lets each driver read it, in
the loop's thread. No threads, no sockets, nothing timed by the host: the same
capture gives the same readings, samples and passes on every run.

This is the per-tick feeder, in the live daemon's order of work. ``shoveld replay
--fast`` steps the same :class:`SyncDevice` objects one device at a time ahead of the
loop and builds the samples in bulk (:mod:`shoveld.replay.bulk`); both give the
same samples.
"""

from __future__ import annotations

import bisect
import functools
import logging
import math
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

from drivers.base import Driver, Reading
from drivers.capture.format import Capture
from shoveld.daemon.config import DeviceConfig, build_driver

log = logging.getLogger(__name__)


class StepClock:
    """The drivers' clock in fast replay: capture time, set by the loop before each tick."""

    stepped = True
    speed = None

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def now(self) -> float:
        return self.t

    __call__ = now

    def wait_until(self, t: float, timeout: float) -> bool:
        """Never waits: time only moves when the loop moves it."""
        return self.t >= t


class MemorySerial:
    """A pyserial-like port holding a recorded byte stream and its recorded answers."""

    def __init__(self, stream: list[tuple[float, bytes]], responder: Callable[[bytes], Any],
                 port: str, *, columns: tuple[list[float], list[bytes]] | None = None
                 ) -> None:
        """``stream``: the recorded ``(time, bytes)`` chunks; or ``columns``, the same as
        a list of times and one of bytes (as the capture's columns reader gives them),
        with ``stream`` empty."""
        if columns is not None:
            self._times, self._chunks = columns
        else:
            self._times = [c[0] for c in stream]
            self._chunks = [c[1] for c in stream]
        self.responder = responder
        self.port = port
        self.timeout = 0.0
        self.is_open = True
        self._i = 0
        self._buf = bytearray()
        self.lookahead = False
        """While a driver opens: an empty port releases its next recorded chunk at once
        (devices that answer by streaming need data before time may move)."""

    def release(self, t: float) -> None:
        i = self._i
        times = self._times
        if i < len(times) and times[i] <= t:
            j = bisect.bisect_right(times, t, i)
            self._buf += self._chunks[i] if j == i + 1 else b"".join(self._chunks[i:j])
            self._i = j

    def recording(self) -> tuple[list[float], list[bytes]]:
        """The recorded chunks' times and bytes (the lists ``release`` reads)."""
        return self._times, self._chunks

    @property
    def position(self) -> int:
        """Recorded chunks released so far."""
        return self._i

    def advance(self, j: int) -> None:
        """Count the chunks before ``j`` as released and read (a span reader took them)."""
        self._i = j

    @functools.cached_property
    def stream(self) -> list[tuple[float, bytes]]:
        """The recorded chunks as ``(time, bytes)``, made when first asked for (tests
        edit it, then set ``_times`` and ``_chunks``, which the port reads, from it)."""
        return list(zip(self._times, self._chunks, strict=True))

    @property
    def exhausted(self) -> bool:
        return self._i >= len(self._times)

    @property
    def first_t(self) -> float:
        return self._times[0] if self._times else 0.0

    @property
    def end_t(self) -> float:
        return self._times[-1] if self._times else 0.0

    @property
    def in_waiting(self) -> int:
        return len(self._buf)

    def read(self, n: int = 1) -> bytes:
        buf = self._buf
        if not buf and self.lookahead and self._i < len(self._chunks):
            buf += self._chunks[self._i]
            self._i += 1
        if n >= len(buf):  # the usual case (drivers ask for in_waiting): one copy
            out = bytes(buf)
            buf.clear()
            return out
        out = bytes(buf[:n])
        del buf[:n]
        return out

    def write(self, data: bytes) -> int:
        ans = self.responder(bytes(data))
        if ans:
            self._buf += ans
        return len(data)

    def flush(self) -> None:
        pass

    def reset_input_buffer(self) -> None:
        self._buf.clear()

    def reset_output_buffer(self) -> None:
        pass

    def close(self) -> None:
        self.is_open = False

    def open(self) -> None:
        self.is_open = True


class MemoryBus:
    """A python-can-like bus holding recorded frames."""

    def __init__(self, messages: list[tuple[float, Any]]) -> None:
        self.messages = messages
        self._i = 0
        self._q: deque[Any] = deque()
        self.lookahead = False

    def release(self, t: float) -> None:
        m = self.messages
        while self._i < len(m) and m[self._i][0] <= t:
            self._q.append(m[self._i][1])
            self._i += 1

    @property
    def exhausted(self) -> bool:
        return self._i >= len(self.messages)

    @property
    def first_t(self) -> float:
        return self.messages[0][0] if self.messages else 0.0

    @property
    def end_t(self) -> float:
        return self.messages[-1][0] if self.messages else 0.0

    @property
    def in_waiting(self) -> int:
        return len(self._q)

    def recv(self, timeout: float | None = None) -> Any:
        if not self._q and self.lookahead and self._i < len(self.messages):
            self._q.append(self.messages[self._i][1])
            self._i += 1
        return self._q.popleft() if self._q else None

    def send(self, msg: Any, timeout: float | None = None) -> None:
        pass

    def shutdown(self) -> None:
        pass


class _Response:
    def __init__(self, registers: list[int] | None = None, code: int | None = None) -> None:
        self.registers = registers or []
        self.exception_code = code

    def isError(self) -> bool:  # noqa: N802 - pymodbus' name
        return self.exception_code is not None


def _modbus_io_exception() -> type[Exception]:
    from pymodbus.exceptions import ModbusIOException

    return ModbusIOException


class MemoryModbus:
    """A pymodbus-like client answering from recorded register reads at capture time."""

    def __init__(self, registers: Any, end_t: float) -> None:
        self.registers = registers
        self.connected = True
        self.end_t = end_t
        self.lookahead = False
        self.in_waiting = 0

    def release(self, t: float) -> None:
        pass

    exhausted = True

    def connect(self) -> bool:
        return True

    def close(self) -> None:
        pass

    def _read(self, fc: int, address: int, count: int) -> _Response:
        r = self.registers(fc, address, count)
        if r is None:
            raise _modbus_io_exception()("no answer (recorded timeout)")
        if isinstance(r, int):
            return _Response(code=r)
        return _Response(r)  # a fresh list from the recording

    def read_input_registers(self, address: int, count: int = 1, **kw: Any) -> _Response:
        return self._read(4, address, count)

    def read_holding_registers(self, address: int, count: int = 1, **kw: Any) -> _Response:
        return self._read(3, address, count)


class SyncDevice:
    """One driver stepped by the loop: open with back-off in capture time, read per tick."""

    def __init__(self, name: str, driver: Driver, transport: Any,
                 sink: Callable[[Reading], None], clock: StepClock) -> None:
        self.name = name
        self.driver = driver
        self.transport = transport
        self.sink = sink
        self.clock = clock
        self.next_open_t = getattr(transport, "first_t", -math.inf)
        """Not before the device's first recorded data: a device that is silent until
        then would be judged dead by its driver's silence timeout."""
        self.delay = driver.backoff_s[0]
        self.opened_once = False
        self.idle: Callable[[float], bool] | None = getattr(driver, "idle", None)
        """The driver's "a read now, with nothing received, would change nothing" (a
        50 Hz laser has nothing on every other 100 Hz tick); None: read at every tick."""
        self.skipped = 0

    def step(self, t: float) -> None:
        tr, drv = self.transport, self.driver
        tr.release(t)
        h = drv.health
        if h.connected:
            idle = self.idle
            if idle is not None and not tr.in_waiting and idle(t):
                self.skipped += 1
                return
        else:
            if t < self.next_open_t:
                return
            tr.lookahead = True
            try:
                drv.open()
            except Exception as e:  # noqa: BLE001 - same policy as Driver.run
                self._fail(t, e)
                return
            finally:
                tr.lookahead = False
            h.connected = True
            if self.opened_once:
                h.reconnects += 1
            self.opened_once = True
            self.delay = drv.backoff_s[0]
        try:
            drv.read(self.sink)
            while tr.in_waiting:
                drv.read(self.sink)
        except Exception as e:  # noqa: BLE001
            self._fail(t, e)

    def _fail(self, t: float, e: Exception) -> None:
        h = self.driver.health
        h.connected = False
        h.last_error = f"{type(e).__name__}: {e}"
        log.warning("%s: %s; retrying in %.1f s (capture time)", self.name, h.last_error,
                    self.delay)
        try:
            self.driver.close()
        except Exception:  # noqa: BLE001
            pass
        self.next_open_t = t + self.delay
        self.delay = min(2 * self.delay, self.driver.backoff_s[1])


class SyncReplay:
    """All recorded devices of a capture as drivers on in-memory transports."""

    def __init__(self, capture_dir: str | Path | Capture, devices: dict[str, DeviceConfig],
                 clock: StepClock | None = None, answer_window_s: float = 0.05) -> None:
        from drivers.capture.format import CAN_KINDS, MODBUS_KINDS, SERIAL_KINDS, read_capture
        from drivers.capture.replay import (
            RecordedAnswers,
            RecordedRegisters,
            split_answer_columns,
        )

        self.capture = (capture_dir if isinstance(capture_dir, Capture)  # already read
                        else read_capture(Path(capture_dir)))
        self.clock = clock or StepClock(0.0)
        self.devices = devices
        self.drivers: dict[str, Driver] = {}
        self.transports: dict[str, Any] = {}
        for name, dev in devices.items():
            entry = self.capture.devices[name]
            tr: Any
            if entry.kind in SERIAL_KINDS:
                times, data, pairs = split_answer_columns(
                    *self.capture.serial_columns(name), answer_window_s)
                tr = MemorySerial([], RecordedAnswers(pairs), f"capture:{name}",
                                  columns=(times, data))
                transport = tr
                drv = build_driver(dev, self.clock,
                                   serial_factory=lambda *a, _t=transport, **k: _t,
                                   **self._timeouts(entry.kind))
            elif entry.kind in CAN_KINDS:
                tr = MemoryBus(list(self.capture.can_messages(name)))
                transport = tr
                drv = build_driver(dev, self.clock, bus_factory=lambda _t=transport, **k: _t,
                                   **self._timeouts(entry.kind))
            elif entry.kind in MODBUS_KINDS:
                regs = RecordedRegisters(self.capture.modbus_recording(name), self.clock)
                tr = MemoryModbus(regs, regs.end_t)
                drv = build_driver(dev, self.clock, client_factory=lambda cfg, _t=tr: _t)
            else:  # pragma: no cover - read_capture rejects unknown kinds
                raise ValueError(f"{name}: kind {entry.kind!r} cannot be replayed")
            self.drivers[name] = drv
            self.transports[name] = tr
        self.end_t = max((tr.end_t for tr in self.transports.values()), default=0.0)
        self._devs: list[SyncDevice] = []

    def _timeouts(self, kind: str) -> dict[str, Any]:
        """Driver arguments that put its data timeout on capture time (the MTi's runs on
        host time live; here host time says only how fast the machine replays)."""
        from shoveld.daemon.config import MTI_KINDS

        return {"timeout_clock": self.clock} if kind in MTI_KINDS else {}

    def attach(self, sinks: dict[str, Callable[[Reading], None]]) -> None:
        self._devs = [SyncDevice(n, self.drivers[n], self.transports[n], sinks[n], self.clock)
                      for n in self.drivers]

    def step(self, t: float) -> None:
        """Move capture time to ``t`` and let every driver read what was recorded by then."""
        self.clock.t = t
        for d in self._devs:
            d.step(t)

    @property
    def finished(self) -> bool:
        return self.clock.t >= self.end_t and all(
            getattr(tr, "exhausted", True) and not tr.in_waiting
            for tr in self.transports.values())

    def close(self) -> None:
        for d in self.drivers.values():
            try:
                d.close()
            except Exception:  # noqa: BLE001
                pass
