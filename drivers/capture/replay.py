"""Replay a capture through the same driver code that recorded it.

:func:`open_replay` turns every recorded device back into an endpoint a driver
connects to exactly as it would to hardware:

* serial devices (``ar4000``, ``mti_serial``): a pseudo-terminal; the driver opens
  ``endpoint.port``. Recorded received bytes are written at their capture times.
  What the driver writes is answered from the recording: each recorded write
  (``tx`` chunk) maps to the bytes the device sent within ``answer_window_s``
  after it, and those answers are sent when the replayed driver writes the same
  bytes, so configuration handshakes (MTi GoToConfig/ReqDID/SetOutputConfiguration/
  GoToMeasurement, AR4000 commands) succeed without a protocol model here. A
  per-device ``responders`` hook replaces this for protocols where byte-exact
  matching is not enough.
* CAN devices (``mti_can``): python-can's ``virtual`` interface on a channel name
  unique to the session; frames are sent at their capture times.
* Modbus devices (``modbus_tcp``/``modbus_rtu``): a pymodbus server (TCP on
  127.0.0.1 with a free port, or RTU over a pty) that answers each request with the
  latest recorded read of that register block at the current capture time: the
  recorded words, the recorded exception, or silence for a recorded timeout.

Time comes from the session's :class:`~drivers.capture.clock.ReplayClock`:
paced (``speed`` = 1.0 recorded pace, 5.0 five times faster) or stepped
(``speed=None``, as fast as possible; the consumer calls ``clock.advance``).
Drivers should be built with ``clock=session.clock`` so their readings carry
capture times.
"""

from __future__ import annotations

import bisect
import logging
import operator
import os
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers.capture.clock import ReplayClock
from drivers.capture.format import (
    CAN_KINDS,
    MODBUS_KINDS,
    SERIAL_KINDS,
    Capture,
    DeviceEntry,
    RegisterColumns,
    RegisterRead,
    SerialChunk,
    read_capture,
)
from drivers.capture.ptylink import PtyLink, open_pty_link

log = logging.getLogger(__name__)

Responder = Callable[[bytes], "bytes | None"]
"""Given bytes the replayed driver wrote, return bytes to answer with (or None)."""


@dataclass
class SerialEndpoint:
    """Where a serial driver connects during replay."""

    name: str
    kind: str
    port: str
    baudrate: int | None


@dataclass
class CanEndpoint:
    """Where a CAN driver connects during replay (python-can ``virtual`` interface)."""

    name: str
    kind: str
    channel: str
    interface: str = "virtual"


@dataclass
class ModbusEndpoint:
    """Where a Modbus driver connects during replay."""

    name: str
    kind: str
    host: str | None = None
    port: int | None = None
    serial_port: str | None = None


Endpoint = SerialEndpoint | CanEndpoint | ModbusEndpoint


class _Waker:
    """A pipe a feeder thread selects on, written when the clock moves."""

    def __init__(self) -> None:
        self.r, self.w = os.pipe()
        os.set_blocking(self.r, False)
        os.set_blocking(self.w, False)

    def wake(self) -> None:
        try:
            os.write(self.w, b"x")
        except (BlockingIOError, OSError):
            pass

    def drain(self) -> None:
        try:
            while os.read(self.r, 4096):
                pass
        except (BlockingIOError, OSError):
            pass

    def close(self) -> None:
        for fd in (self.r, self.w):
            try:
                os.close(fd)
            except OSError:
                pass


def split_answers(chunks: list[SerialChunk], answer_window_s: float
                  ) -> tuple[list[tuple[float, bytes]], list[tuple[bytes, bytes]]]:
    """Separate a serial recording into the timed stream and write->answer pairs.

    An ``rx`` chunk within ``answer_window_s`` after a ``tx`` chunk (and before the
    next ``tx``) is that write's answer; all other ``rx`` chunks form the stream.
    """
    times, data, pairs = split_answer_columns(
        [c.t for c in chunks], [c.direction for c in chunks], [c.data for c in chunks],
        answer_window_s)
    return list(zip(times, data, strict=True)), pairs


def split_answer_columns(times: list[float], directions: list[str], data: list[bytes],
                         answer_window_s: float
                         ) -> tuple[list[float], list[bytes], list[tuple[bytes, bytes]]]:
    """:func:`split_answers` on a recording's columns (in time order, as the capture's
    readers give them): the stream's times and bytes, and the write->answer pairs.

    The writes are a device's handshake, at the start of the recording: past the last
    write's answer window every chunk is the stream's, taken as slices; only the chunks
    before that are looked at one by one (a bisect each was most of the 20,000 chunks
    of a 100 s MTi recording)."""
    tx_at = [i for i, d in enumerate(directions) if d == "tx"]
    tx_times = [times[i] for i in tx_at]
    answers: list[bytearray] = [bytearray() for _ in tx_at]
    # From ``end`` on every chunk is rx and past every write's window: a second past it,
    # so that the rounding of ``t - tx_time`` below can never disagree with the slice.
    end = (bisect.bisect_right(times, tx_times[-1] + answer_window_s + 1.0, tx_at[-1] + 1)
           if tx_at else 0)
    st: list[float] = []
    sd: list[bytes] = []
    for k in range(end):
        if directions[k] != "rx":
            continue
        t = times[k]
        i = bisect.bisect_right(tx_times, t) - 1
        if i >= 0 and t - tx_times[i] <= answer_window_s:
            answers[i] += data[k]
        else:
            st.append(t)
            sd.append(data[k])
    st += times[end:]
    sd += data[end:]
    return st, sd, [(data[j], bytes(a)) for j, a in zip(tx_at, answers, strict=True)]


class RecordedAnswers:
    """Default responder: answers a write that matches a recorded write with the
    recorded answer (in recorded order; the last answer repeats once all are used)."""

    def __init__(self, pairs: list[tuple[bytes, bytes]]) -> None:
        self._answers: dict[bytes, list[bytes]] = {}
        for tx, ans in pairs:
            self._answers.setdefault(tx, []).append(ans)
        self._used: dict[bytes, int] = {}
        self._buf = bytearray()

    def __call__(self, data: bytes) -> bytes | None:
        self._buf += data
        out = bytearray()
        while self._answers:
            best: tuple[int, bytes] | None = None
            for tx in self._answers:
                i = self._buf.find(tx)
                if i >= 0 and (best is None or i < best[0]):
                    best = (i, tx)
            if best is None:
                break
            i, tx = best
            del self._buf[:i + len(tx)]
            lst = self._answers[tx]
            k = self._used.get(tx, 0)
            out += lst[min(k, len(lst) - 1)]
            self._used[tx] = k + 1
        if len(self._buf) > 4096:
            del self._buf[:-1024]
        return bytes(out) or None


class _SerialFeeder:
    def __init__(self, entry: DeviceEntry, capture: Capture, clock: ReplayClock,
                 responder: Responder | None, answer_window_s: float, stall_s: float) -> None:
        self.entry = entry
        self.clock = clock
        self.stall_s = stall_s
        self._stall = (0, 0.0)
        self._stalled = False
        self.dropped = 0
        chunks = list(capture.serial_chunks(entry.name))
        self.stream, pairs = split_answers(chunks, answer_window_s)
        self.responder: Responder = responder or RecordedAnswers(pairs)
        self.end_t = self.stream[-1][0] if self.stream else 0.0
        self.link: PtyLink = open_pty_link()
        self.endpoint = SerialEndpoint(entry.name, entry.kind, self.link.slave_path,
                                       entry.settings.get("baudrate"))
        self._idx = 0
        self.released_t = -1.0
        self.written = 0
        self.driver_bytes = 0
        self._stop = threading.Event()
        self._waker = _Waker()
        clock.add_listener(self._waker.wake)
        self._thread = threading.Thread(target=self._run, name=f"replay-{entry.name}",
                                        daemon=True)

    def start(self) -> None:
        self._thread.start()

    @property
    def exhausted(self) -> bool:
        return self._idx >= len(self.stream)

    def settled(self, t: float) -> bool:
        """Released up to ``t`` and read by the driver, or the driver is not reading
        (nothing consumed for ``stall_s``: not connected, or in reconnect back-off)."""
        if self.released_t < t and not self.exhausted:
            return False
        pending = self.link.pending_to_driver()
        if pending == 0:
            return True
        consumed = self.written - pending
        now = time.monotonic()
        if consumed != self._stall[0]:  # the driver is reading: wait for it
            self._stall = (consumed, now)
            self._stalled = False
            return False
        if not self._stalled and now - self._stall[1] > self.stall_s:
            self._stalled = True  # judged once; later steps do not wait again
        return self._stalled

    def _run(self) -> None:
        link = self.link
        while not self._stop.is_set():
            now = self.clock.now()
            if self.exhausted or self.clock.stepped:
                timeout = 0.1
            else:
                timeout = max(0.0, min(0.1, (self.stream[self._idx][0] - now)
                                       / (self.clock.speed or 1.0)))
            try:
                r, _, _ = select.select([link.master_fd, self._waker.r], [], [], timeout)
            except (OSError, ValueError):
                return
            if self._waker.r in r:
                self._waker.drain()
            if link.master_fd in r:
                data = link.read(0)
                if data:
                    self.driver_bytes += len(data)
                    answer = self.responder(data)
                    if answer:
                        self.written += link.write(answer, timeout_s=0.5)
            now = self.clock.now()
            while self._idx < len(self.stream) and self.stream[self._idx][0] <= now:
                data = self.stream[self._idx][1]
                n = link.write(data, timeout_s=0.02)
                if n < len(data):  # nobody reads the port: drop, as a full UART would
                    if not self.dropped:
                        log.warning("replay %s: driver not reading; dropping bytes",
                                    self.entry.name)
                    self.dropped += len(data) - n
                self.written += n
                self._idx += 1
            self.released_t = now

    def close(self) -> None:
        self._stop.set()
        self._waker.wake()
        if self._thread.is_alive():
            self._thread.join(timeout=2)
        self._waker.close()
        self.link.close()


class _CanFeeder:
    def __init__(self, entry: DeviceEntry, capture: Capture, clock: ReplayClock) -> None:
        import uuid  # here, as can: the fast replay never needs it (2 ms of its start)

        import can

        self.entry = entry
        self.clock = clock
        self.messages = list(capture.can_messages(entry.name))
        self.end_t = self.messages[-1][0] if self.messages else 0.0
        channel = f"shoveld-replay-{entry.name}-{uuid.uuid4().hex[:8]}"
        self.endpoint = CanEndpoint(entry.name, entry.kind, channel)
        self.bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self._idx = 0
        self.released_t = -1.0
        self._stop = threading.Event()
        self._wake = threading.Event()
        clock.add_listener(self._wake.set)
        self._thread = threading.Thread(target=self._run, name=f"replay-{entry.name}",
                                        daemon=True)

    def start(self) -> None:
        self._thread.start()

    @property
    def exhausted(self) -> bool:
        return self._idx >= len(self.messages)

    def settled(self, t: float) -> bool:
        if self.released_t < t and not self.exhausted:
            return False
        mine = self.bus.queue  # type: ignore[attr-defined]
        return all(q.empty() for q in self.bus.channel if q is not mine)  # type: ignore

    def _run(self) -> None:
        while not self._stop.is_set():
            now = self.clock.now()
            while self._idx < len(self.messages) and self.messages[self._idx][0] <= now:
                self.bus.send(self.messages[self._idx][1])
                self._idx += 1
            self.released_t = now
            if self.exhausted or self.clock.stepped:
                timeout = 0.1
            else:
                timeout = max(0.0, min(0.1, (self.messages[self._idx][0] - now)
                                       / (self.clock.speed or 1.0)))
            self._wake.wait(timeout)
            self._wake.clear()

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2)
        self.bus.shutdown()


_BLOCK = operator.attrgetter("function", "address", "count")
_TIME = operator.attrgetter("t")


class _ColumnReads:
    """The records of :class:`RegisterColumns` as a sequence of :class:`RegisterRead`,
    each built when asked for (a replay asks for few: the span reader reads the words)."""

    def __init__(self, cols: RegisterColumns) -> None:
        self.cols = cols

    def __len__(self) -> int:
        return len(self.cols.times)

    def __getitem__(self, i: int) -> RegisterRead:
        if not -len(self) <= i < len(self):
            raise IndexError(i)
        return self.cols.read(i % len(self))


class RecordedRegisters:
    """Answers register reads from a recording: latest recorded outcome at capture time.

    ``reads`` is the recording as :func:`read_modbus_reads` gives it, or as
    :class:`RegisterColumns` where the file is one block always answered (the same
    answers, and :meth:`columns` for readers that take the words as an array)."""

    def __init__(self, reads: list[RegisterRead] | RegisterColumns,
                 clock: Callable[[], float]) -> None:
        self.clock = clock
        self._by_block: dict[tuple[int, int, int], tuple[list[float], Any]] = {}
        if isinstance(reads, RegisterColumns):
            key = (reads.function, reads.address, reads.count)
            self._by_block[key] = (reads.times, _ColumnReads(reads))
            self.end_t = max(reads.times, default=0.0)
            return
        keys = list(map(_BLOCK, reads))
        times = list(map(_TIME, reads))
        if len(set(keys)) == 1:  # the usual recording: one block, polled over and over
            self._by_block[keys[0]] = (times, list(reads))
        else:
            for key, t, r in zip(keys, times, reads, strict=True):
                ts, rs = self._by_block.setdefault(key, ([], []))
                ts.append(t)
                rs.append(r)
        self.end_t = max(times, default=0.0)

    def _latest(self, key: tuple[int, int, int], t: float) -> RegisterRead | None | int:
        """Latest read of ``key`` at or before ``t``; NOT_YET before the first one;
        None if that block was never read."""
        entry = self._by_block.get(key)
        if entry is None:
            return None
        ts, rs = entry
        i = bisect.bisect_right(ts, t) - 1
        return rs[i] if i >= 0 else self.NOT_YET

    def recorded(self, key: tuple[int, int, int]) -> list[RegisterRead] | None:
        """The recorded reads of block ``(function, address, count)`` in time order (None:
        that block was never read as such), for readers that answer many polls at once."""
        entry = self._by_block.get(key)
        return None if entry is None else list(entry[1])

    def columns(self, key: tuple[int, int, int]) -> RegisterColumns | None:
        """Block ``key``'s recording as columns, where it was read so (else None)."""
        entry = self._by_block.get(key)
        return entry[1].cols if entry is not None and isinstance(entry[1], _ColumnReads) \
            else None

    NOT_YET = 6
    """Answer before the first recorded read: DEVICE_BUSY, an honest "no value yet"
    that still counts as an answer (no reconnect storm at the start of a replay)."""

    def __call__(self, fc: int, address: int, count: int) -> list[int] | int | None:
        t = self.clock()
        r = self._latest((fc, address, count), t)
        if r is None:  # a different block layout: find a recorded block covering it
            for (f, a, c) in self._by_block:
                if f == fc and a <= address and address + count <= a + c:
                    r = self._latest((f, a, c), t)
                    if isinstance(r, RegisterRead) and r.registers is not None:
                        off = address - a
                        return list(r.registers[off:off + count])
                    break
            else:
                return 2  # ILLEGAL_ADDRESS: nothing recorded there
        if isinstance(r, int):
            return r
        if r is None or r.error == "timeout":
            return None
        if r.error == "exception":
            return int(r.exception_code or 4)
        return list(r.registers or ())


class _ModbusFeeder:
    def __init__(self, entry: DeviceEntry, capture: Capture, clock: ReplayClock,
                 quiet_s: float) -> None:
        from drivers.modbus_adc.server import RegisterServer

        self.entry = entry
        self.clock = clock
        self.quiet_s = quiet_s
        reads = list(capture.modbus_reads(entry.name))
        self.provider = RecordedRegisters(reads, clock)
        self.end_t = self.provider.end_t
        cfg = entry.settings.get("config") or {}
        transport = "tcp" if entry.kind == "modbus_tcp" else "rtu"
        self.server = RegisterServer(self.provider, transport=transport,
                                     baudrate=int(cfg.get("baudrate", 19200)))
        self.server.on_request = self._on_request
        # a recorded timeout is replayed as silence; the client then waits its timeout
        # in real time (over RTU twice: it watches the line for a late answer as long
        # again), during which a stepped clock must not run ahead
        waits = 1 if transport == "tcp" else 2
        self.server.drop_hold_s = waits * float(cfg.get("timeout_s", 0.1)) + 0.01
        self.endpoint = ModbusEndpoint(entry.name, entry.kind)
        self._served_t = -1.0
        self._seen: tuple[float, float] = (-1.0, 0.0)

    def _on_request(self, fc: int, address: int, count: int) -> None:
        self._served_t = self.clock.now()

    def start(self) -> None:
        self.server.start()
        if self.server.transport == "tcp":
            self.endpoint.host, self.endpoint.port = self.server.host, self.server.port
        else:
            self.endpoint.serial_port = self.server.serial_port

    @property
    def exhausted(self) -> bool:
        return self.clock.now() >= self.end_t

    def settled(self, t: float) -> bool:
        if self._seen[0] != t:
            self._seen = (t, time.monotonic())
        if self.server.in_flight or time.monotonic() < self.server.hold_until:
            return False
        return self._served_t >= t or time.monotonic() - self._seen[1] > self.quiet_s

    def close(self) -> None:
        self.server.stop()


@dataclass
class ReplaySession:
    """A running replay: endpoints to connect drivers to, the clock, and ``close()``."""

    capture: Capture
    clock: ReplayClock
    endpoints: dict[str, Endpoint] = field(default_factory=dict)
    _feeders: list[Any] = field(default_factory=list, repr=False)
    end_t: float = 0.0

    @property
    def finished(self) -> bool:
        """Everything recorded has been released (and serial bytes read by the drivers)."""
        return self.clock.now() >= self.end_t and all(
            f.exhausted for f in self._feeders) and all(
            f.settled(self.clock.now()) for f in self._feeders
            if isinstance(f, _SerialFeeder))

    def wait_connected(self, drivers: list[Any], timeout_s: float = 5.0,
                       step_s: float = 0.005) -> bool:
        """Wait until every driver reports ``health.connected``.

        Stepped clock: meanwhile advance it at about real-time pace (``step_s`` per
        ``step_s`` of real time), because drivers need data to flow to finish their
        handshake, but racing ahead would stream past them while they connect.
        Call it after starting the driver threads, before a fast loop.
        """
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if all(d.health.connected for d in drivers):
                return True
            if self.clock.stepped:
                self.clock.advance(step_s)
            time.sleep(step_s)
        return all(d.health.connected for d in drivers)

    def driver_config(self, name: str) -> dict[str, Any]:
        """The device's recorded driver config, re-pointed at its replay endpoint."""
        dev = self.capture.devices[name]
        cfg = dict(dev.settings.get("config") or {})
        ep = self.endpoints[name]
        cfg["kind"] = dev.kind
        if isinstance(ep, SerialEndpoint):
            cfg["port"] = ep.port
        elif isinstance(ep, ModbusEndpoint):
            if ep.serial_port is not None:
                cfg["port"] = ep.serial_port
            else:
                cfg["host"], cfg["port"] = ep.host, ep.port
        else:
            cfg["interface"], cfg["channel"] = ep.interface, ep.channel
        return cfg

    def close(self) -> None:
        for f in self._feeders:
            try:
                f.close()
            except Exception:  # noqa: BLE001
                log.exception("closing replay feeder")
        self._feeders.clear()

    def __enter__(self) -> ReplaySession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_replay(capture_dir: str | os.PathLike[str], speed: float | None = 1.0, *,
                devices: list[str] | None = None,
                responders: dict[str, Responder] | None = None, answer_window_s: float = 0.05,
                settle_timeout_s: float = 0.5, modbus_quiet_s: float = 0.001,
                serial_stall_s: float = 0.02, start_at: float = 0.0, hold: bool = False
                ) -> ReplaySession:
    """Start replaying ``capture_dir``; connect drivers to ``session.endpoints``.

    ``speed``: 1.0 = recorded pace, X = X times faster, None = stepped clock (the
    consumer advances it). ``devices``: replay only these (default: all).
    ``responders`` maps a device name or kind to a :data:`Responder` replacing the
    recorded-answer default. Stepped mode: ``advance`` waits at most
    ``settle_timeout_s`` for delivery; a serial port nobody reads stops counting after
    ``serial_stall_s``; a Modbus server counts as settled when it has answered at the
    new time or has seen no request for ``modbus_quiet_s``. ``hold``: a paced clock
    stands at ``start_at`` until ``session.clock.restart()`` (the drivers' handshakes are
    answered meanwhile; a stream starts when the clock does).
    """
    capture = read_capture(Path(capture_dir))
    if devices is not None:
        unknown = [d for d in devices if d not in capture.devices]
        if unknown:
            raise ValueError(f"{capture_dir}: no device(s) {unknown} in the capture; it has "
                             f"{sorted(capture.devices)}")
    clock = ReplayClock(start=start_at, speed=speed, settle_timeout_s=settle_timeout_s)
    # paced: time stands still while the feeders start (a slow machine took 0.6 s here,
    # 3 s of a recording at 5x, pushed into ports nobody read yet and dropped)
    clock.hold()
    session = ReplaySession(capture, clock)
    responders = responders or {}
    try:
        for name, dev in capture.devices.items():
            if devices is not None and name not in devices:
                continue
            feeder: Any
            if dev.kind in SERIAL_KINDS:
                feeder = _SerialFeeder(dev, capture, clock,
                                       responders.get(name) or responders.get(dev.kind),
                                       answer_window_s, serial_stall_s)
            elif dev.kind in CAN_KINDS:
                feeder = _CanFeeder(dev, capture, clock)
            elif dev.kind in MODBUS_KINDS:
                feeder = _ModbusFeeder(dev, capture, clock, modbus_quiet_s)
            else:  # pragma: no cover - read_capture rejects unknown kinds
                continue
            session._feeders.append(feeder)
            feeder.start()
            session.endpoints[name] = feeder.endpoint
            clock.add_settle_check(feeder.settled)
            session.end_t = max(session.end_t, feeder.end_t)
    except BaseException:
        session.close()
        raise
    if not hold:
        clock.restart(start_at)
    return session
