"""Virtual Xsens MTi on a real pseudo-terminal: the serial driver's hardware-in-the-loop.

The driver under test opens :attr:`MtiEmulator.port` with pyserial exactly as it would
open a USB-serial adapter. The emulator speaks the same Xbus subset the driver uses
(:mod:`drivers.xsens.xbus`): WakeUp at power-up and the 500 ms acknowledgement window,
GoToConfig, ReqDID, ReqFWRev, ReqProductCode, SetOutputConfiguration (honouring the
requested items, precisions, coordinate-frame bits and rates), GoToMeasurement, Reset,
and Error 0x04 for anything it does not understand. In Measurement state it streams
MTData2 built from a source of joint values, ``angles_at(t) -> (roll, pitch, yaw)``
in degrees, where ``t`` is the emulator's sample time (SampleTimeFine / 10 kHz).

Faults to test against:

* :meth:`unplug` / :meth:`plug`: the port disappears and reappears (a stable symlink,
  like ``/dev/serial/by-id``, keeps the path the same); plugging back is a power-up;
* :meth:`go_silent` / :meth:`come_back`: device off / on with the port still there;
* ``garbage_probability`` / ``corrupt_probability`` / :meth:`emit_garbage`: noise
  between frames and bit flips inside them;
* ``fail_commands``: answer chosen requests with an Error message;
* a wrong baud rate: the emulator reads the baud rate the driver set on the pty
  (``tcgetattr`` on the master) and, when it differs from :attr:`baudrate` (or
  ``wrong_baud`` is set), turns its output into byte noise and ignores commands -
  what a real device at another baud rate looks like from the host.

Emulated sensor physics is deliberately simple (rate of turn from the Euler-angle
derivative, acceleration = gravity only, a fixed magnetic field): enough for the
driver and the daemon, not a sensor model. RotationMatrix is sent column-major; that
layout is not confirmed from a vendor document.
"""

from __future__ import annotations

import math
import os
import queue
import random
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

from drivers.xsens.mtdata2 import (
    MAX_FREQUENCY,
    TYPE_MASK,
    XDI,
    UtcTime,
    decode_output_configuration,
    encode_item,
    encode_output_configuration,
)
from drivers.xsens.orientation import (
    body_rates,
    euler_deg_to_matrix,
    euler_deg_to_quat,
    gravity_in_sensor,
)
from drivers.xsens.xbus import MID, XbusMessage, XbusParser, encode_frame
from hil_fixtures.pty import close_pty_pair, open_pty_pair
from shoveld.installation import Installation
from shoveld.signals import SignalsTable

AnglesAt = Callable[[float], tuple[float, float, float]]

SUPPORTED = frozenset((
    XDI.PACKET_COUNTER, XDI.SAMPLE_TIME_FINE, XDI.SAMPLE_TIME_COARSE, XDI.UTC_TIME,
    XDI.STATUS_WORD, XDI.STATUS_BYTE, XDI.TEMPERATURE, XDI.QUATERNION, XDI.ROTATION_MATRIX,
    XDI.EULER_ANGLES, XDI.ACCELERATION, XDI.FREE_ACCELERATION, XDI.DELTA_V, XDI.RATE_OF_TURN,
    XDI.DELTA_Q, XDI.MAGNETIC_FIELD, XDI.VELOCITY_XYZ, XDI.LAT_LON, XDI.ALTITUDE_ELLIPSOID))

DEFAULT_OUTPUTS: tuple[tuple[int, int], ...] = (
    (XDI.PACKET_COUNTER, MAX_FREQUENCY), (XDI.SAMPLE_TIME_FINE, MAX_FREQUENCY),
    (XDI.EULER_ANGLES, 100), (XDI.ACCELERATION, 100), (XDI.RATE_OF_TURN, 100),
    (XDI.STATUS_WORD, MAX_FREQUENCY))

WAKEUP_WINDOW_S = 0.5
"""A WakeUpAck within this time after WakeUp puts the device in Config state."""


def angles_from_signals(table: SignalsTable, installation: Installation | None = None,
                        loop: bool = True) -> AnglesAt:
    """``angles_at(t)`` from a signals table: pitch from handle_deg, yaw from swing_deg.

    ``t`` counts from the table's first row; with ``loop`` the table repeats, otherwise
    the ends are held. Rows where handle or swing is unknown (blank) are skipped. Roll
    is 0 (the saddle block does not roll against the handle).
    """
    inst = installation or Installation()
    time_s = table["time_s"]
    ok = ~(np.isnan(table["handle_deg"]) | np.isnan(table["swing_deg"]))
    t = time_s[ok]
    if len(t) < 2:
        raise ValueError(f"{table.source}: need two rows with handle_deg and swing_deg")
    handle = table["handle_deg"][ok]
    swing = table["swing_deg"][ok]
    t0, span = float(t[0]), float(t[-1] - t[0])

    def angles_at(tq: float) -> tuple[float, float, float]:
        x = t0 + (math.fmod(tq, span) if loop else tq)
        if x < t0:
            x += span if loop else 0.0
        h = float(np.interp(x, t, handle))
        s = float(np.interp(x, t, swing))
        return (0.0, inst.mti_pitch_deg(h), inst.mti_yaw_deg(s))

    return angles_at


def _wrap(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


class MtiEmulator:
    """A virtual MTi behind a pty; run it in a thread with :meth:`start` / :meth:`stop`.

    ``clock`` drives sample times (pass a scaled clock to run faster than real time);
    protocol timeouts such as the WakeUp window use real time.
    """

    def __init__(self, angles_at: AnglesAt, *, link: str | Path | None = None,
                 baudrate: int = 115200, device_id: int = 0x06301234,
                 firmware: tuple[int, int, int, int, int] = (1, 8, 2, 37, 70964),
                 product_code: str = "MTi-630-EMU", clock: Callable[[], float] = time.monotonic,
                 send_wakeup: bool = True, outputs: tuple[tuple[int, int], ...] | None = None,
                 max_rate_hz: int = 400, garbage_probability: float = 0.0,
                 corrupt_probability: float = 0.0, seed: int = 0, tick_s: float = 0.002,
                 status_word: int = 0x00000003, t0: float | None = None) -> None:
        self.angles_at = angles_at
        self._own_dir: str | None = None
        if link is None:
            self._own_dir = tempfile.mkdtemp(prefix="mti-emu-")
            link = Path(self._own_dir) / "ttyMTI"
        self.link = Path(link)
        self.baudrate = baudrate
        self.device_id = device_id
        self.firmware = firmware
        self.product_code = product_code
        self.clock = clock
        self.send_wakeup = send_wakeup
        self.max_rate_hz = max_rate_hz
        self.garbage_probability = garbage_probability
        self.corrupt_probability = corrupt_probability
        self.wrong_baud = False
        self.fail_commands: dict[int, int] = {}
        """Message id -> error code to answer that request with (Error 0x42)."""
        self.status_word = status_word
        self.tick_s = tick_s
        self.temperature_c = 25.0
        self.outputs: list[tuple[int, int]] = []
        self._set_outputs(list(outputs or DEFAULT_OUTPUTS))
        self.state = "off"
        self.received: list[XbusMessage] = []
        self.sent_packets = 0
        self.dropped_bytes = 0
        self._rng = random.Random(seed)
        self._parser = XbusParser()
        self._master: int | None = None
        self._slave_path: str | None = None
        self._silent = False
        self._wakeup_t = 0.0
        # Sample k is taken at t0 + k / rate on the clock. A virtual shovel passes its
        # clock's origin so every emulator shares one time line with the table.
        self._t0 = clock() if t0 is None else t0
        self._next_k = 0
        self._counter = 0
        self._drop = 0
        self._requests: queue.Queue[tuple[Callable[[], Any], threading.Event]] = queue.Queue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # --- public control ---------------------------------------------------------------

    @property
    def port(self) -> str:
        """Path the driver opens (a symlink that survives unplug/plug)."""
        return str(self.link)

    def start(self) -> MtiEmulator:
        self._do(self._plug)
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="mti-emulator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._unplug()
        if self._own_dir is not None:
            shutil.rmtree(self._own_dir, ignore_errors=True)

    def __enter__(self) -> MtiEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def unplug(self) -> None:
        """Pull the cable: the pty closes (the driver's reads fail) and the path vanishes."""
        self._do(self._unplug)

    def plug(self) -> None:
        """Plug back in: a new pty behind the same path, and a device power-up."""
        self._do(self._plug)

    def go_silent(self) -> None:
        """Device off with the port present: no output, commands ignored."""
        self._do(lambda: setattr(self, "_silent", True))

    def come_back(self) -> None:
        """Device on again: a power-up (WakeUp, then Measurement with its stored config)."""
        def on() -> None:
            self._silent = False
            self._power_up()
        self._do(on)

    def emit_garbage(self, n: int) -> None:
        """Write ``n`` random bytes now (they may contain 0xFA)."""
        self._do(lambda: self._write(self._rng.randbytes(n)))

    def drop_packets(self, n: int) -> None:
        """Lose the next ``n`` MTData2 packets on the line (the packet counter still advances)."""
        def drop() -> None:
            self._drop += n
        self._do(drop)

    def send_error(self, code: int) -> None:
        """Send an Error message with ``code`` now."""
        self._do(lambda: self._send(MID.ERROR, bytes((code,))))

    def commands(self) -> list[int]:
        """Message ids received so far (for asserting the configuration sequence)."""
        return [m.mid for m in list(self.received)]

    # --- thread -------------------------------------------------------------------------

    def _do(self, fn: Callable[[], Any]) -> None:
        if self._thread is None or not self._thread.is_alive():
            fn()
            return
        done = threading.Event()
        self._requests.put((fn, done))
        if not done.wait(2.0):
            raise TimeoutError("MTi emulator did not process the request")

    def _run(self) -> None:
        while not self._stop.is_set():
            while True:
                try:
                    fn, done = self._requests.get_nowait()
                except queue.Empty:
                    break
                try:
                    fn()
                finally:
                    done.set()
            fd = self._master
            if fd is None:
                time.sleep(self.tick_s)
                continue
            try:
                ready, _, _ = select.select([fd], [], [], self._wait_s())
                data = os.read(fd, 4096) if ready else b""
            except OSError:
                data = b""
                time.sleep(self.tick_s)
            if data:
                self._on_bytes(data)
            self._step()

    def _wait_s(self) -> float:
        """Real seconds until the next packet is due, at most ``tick_s``: a real MTi sends
        on its own clock's schedule, not on the next poll of a loop."""
        if self.state != "measurement" or self._silent:
            return self.tick_s
        speed = getattr(self.clock, "speed", 1.0)
        if not speed or getattr(self.clock, "stepped", False):
            return self.tick_s
        due_t = self._t0 + self._next_k / self.packet_rate_hz
        left = (due_t - self.clock()) / speed + 2e-5  # wake just after it is due
        return min(self.tick_s, max(0.0, left))

    def _plug(self) -> None:
        self._unplug()
        master, slave_path = open_pty_pair()
        os.set_blocking(master, False)
        self._master, self._slave_path = master, slave_path
        tmp = self.link.with_name(self.link.name + ".new")
        if tmp.is_symlink() or tmp.exists():
            tmp.unlink()
        os.symlink(slave_path, tmp)
        os.replace(tmp, self.link)
        self._parser = XbusParser()
        self._power_up()

    def _unplug(self) -> None:
        if self._master is not None:
            close_pty_pair(self._master)
            self._master = None
        if self.link.is_symlink():
            self.link.unlink()
        self.state = "off"

    def _power_up(self) -> None:
        if self._silent:
            self.state = "off"
            return
        if self.send_wakeup:
            self.state = "wakeup"
            self._wakeup_t = time.monotonic()
            self._send(MID.WAKEUP)
        else:
            self._enter_measurement()

    def _baud_ok(self) -> bool:
        if self.wrong_baud or self._master is None:
            return not self.wrong_baud
        try:
            speed = termios.tcgetattr(self._master)[5]
        except termios.error:
            return True
        return speed == getattr(termios, f"B{self.baudrate}", None)

    def _write(self, data: bytes) -> None:
        if self._master is None:
            return
        if not self._baud_ok():
            data = self._rng.randbytes(len(data)).replace(b"\xfa", b"\x5f")
        try:
            n = os.write(self._master, data)
        except OSError:  # nobody reading and the buffer is full: bytes are lost, like a line
            n = 0
        self.dropped_bytes += len(data) - n

    def _send(self, mid: int, data: bytes = b"") -> None:
        frame = encode_frame(mid, data)
        if self.corrupt_probability and self._rng.random() < self.corrupt_probability:
            b = bytearray(frame)
            k = self._rng.randrange(1, len(b))
            b[k] ^= 1 << self._rng.randrange(8)
            frame = bytes(b)
        if self.garbage_probability and self._rng.random() < self.garbage_probability:
            frame = self._rng.randbytes(self._rng.randint(1, 24)) + frame
        self._write(frame)

    # --- protocol -----------------------------------------------------------------------

    def _on_bytes(self, data: bytes) -> None:
        if self._silent or self.state == "off" or not self._baud_ok():
            return  # off, or at the wrong baud rate the device cannot decode anything
        for msg in self._parser.feed(data):
            self.received.append(msg)
            self._handle(msg)

    def _handle(self, msg: XbusMessage) -> None:
        mid = msg.mid
        if mid in self.fail_commands:
            self._send(MID.ERROR, bytes((self.fail_commands[mid],)))
            return
        if mid == MID.WAKEUP_ACK:
            if self.state == "wakeup":
                self.state = "config"
            return
        if mid == MID.GOTO_CONFIG:
            self.state = "config"
            self._send(MID.GOTO_CONFIG_ACK)
            return
        if mid == MID.RESET:
            self._send(MID.RESET_ACK)
            self._power_up()
            return
        if self.state != "config":
            if self.state == "measurement":
                self._send(MID.ERROR, b"\x04")
            return
        if mid == MID.REQ_DID:
            self._send(MID.DEVICE_ID, struct.pack(">I", self.device_id))
        elif mid == MID.REQ_FW_REV:
            self._send(MID.FIRMWARE_REV, struct.pack(">BBBII", *self.firmware))
        elif mid == MID.REQ_PRODUCT_CODE:
            self._send(MID.PRODUCT_CODE, self.product_code.encode().ljust(20, b" "))
        elif mid == MID.SET_OUTPUT_CONFIGURATION:
            if msg.data:
                if len(msg.data) % 4:
                    self._send(MID.ERROR, b"\x21")
                    return
                self._set_outputs(decode_output_configuration(msg.data))
            self._send(MID.OUTPUT_CONFIGURATION, encode_output_configuration(self.outputs))
        elif mid == MID.GOTO_MEASUREMENT:
            # in measurement before the ack goes out (the emulator's thread sends both, so
            # no data packet can precede the ack), so whoever got the ack sees the new state
            self._enter_measurement()
            self._send(MID.GOTO_MEASUREMENT_ACK)
        else:
            self._send(MID.ERROR, b"\x04")

    def _set_outputs(self, wanted: Iterable[tuple[int, int]]) -> None:
        out = []
        for xdi, f in wanted:
            if xdi & TYPE_MASK not in SUPPORTED or f == 0:
                continue
            if f != MAX_FREQUENCY:
                f = max(1, min(self.max_rate_hz, f))
                f = round(self.max_rate_hz / round(self.max_rate_hz / f))
            out.append((xdi, f))
        self.outputs = out
        rates = [f for _, f in out if f != MAX_FREQUENCY]
        self.packet_rate_hz = max(rates) if rates else 100

    def _enter_measurement(self) -> None:
        self.state = "measurement"
        t = self.clock() - self._t0
        self._next_k = math.floor(t * self.packet_rate_hz) + 1

    def _step(self) -> None:
        if self.state == "wakeup" and time.monotonic() - self._wakeup_t > WAKEUP_WINDOW_S:
            self._enter_measurement()
        if self.state != "measurement" or self._silent:
            return
        rate = self.packet_rate_hz
        due = math.floor((self.clock() - self._t0) * rate)
        if due - self._next_k > rate:  # far behind (e.g. a stalled host): skip, like a device
            self._next_k = due
        while self._next_k <= due:
            payload = self.packet(self._next_k)
            self._next_k += 1
            if self._drop:
                self._drop -= 1
                continue
            self._send(MID.MTDATA2, payload)
            self.sent_packets += 1

    def packet(self, k: int) -> bytes:
        """MTData2 payload of sample ``k`` with the configured items."""
        rate = self.packet_rate_hz
        stf = round(k / rate * 1e4)
        t = stf * 1e-4
        r, p, y = self.angles_at(t)
        counter = self._counter & 0xFFFF
        self._counter += 1
        items: list[tuple[int, Any]] = []
        for xdi, f in self.outputs:
            if f != MAX_FREQUENCY and k > 0 and math.floor(k * f / rate) == math.floor(
                    (k - 1) * f / rate):
                continue
            items.append((xdi, self._value(xdi, t, stf, counter, (r, p, y), rate)))
        payload = b"".join(encode_item(x, v) for x, v in items)
        return payload

    def _value(self, xdi: int, t: float, stf: int, counter: int,
               euler: tuple[float, float, float], rate: float) -> Any:
        typ = xdi & TYPE_MASK
        r, p, y = euler
        if typ == XDI.PACKET_COUNTER:
            return counter
        if typ == XDI.SAMPLE_TIME_FINE:
            return stf & 0xFFFFFFFF
        if typ == XDI.SAMPLE_TIME_COARSE:
            return int(t) & 0xFFFFFFFF
        if typ == XDI.UTC_TIME:
            ts = 1.7e9 + t
            g = time.gmtime(ts)
            return UtcTime(int((ts % 1.0) * 1e9), g.tm_year, g.tm_mon, g.tm_mday, g.tm_hour,
                           g.tm_min, g.tm_sec, 0x07)
        if typ == XDI.STATUS_WORD:
            return self.status_word & 0xFFFFFFFF
        if typ == XDI.STATUS_BYTE:
            return self.status_word & 0xFF
        if typ == XDI.TEMPERATURE:
            return (self.temperature_c,)
        if typ == XDI.EULER_ANGLES:
            return euler
        if typ == XDI.QUATERNION:
            return euler_deg_to_quat(r, p, y)
        if typ == XDI.ROTATION_MATRIX:
            m = euler_deg_to_matrix(r, p, y)
            return tuple(m[i][j] for j in range(3) for i in range(3))
        if typ == XDI.ACCELERATION:
            return gravity_in_sensor(r, p)
        if typ == XDI.DELTA_V:
            return tuple(a / rate for a in gravity_in_sensor(r, p))
        if typ in (XDI.RATE_OF_TURN, XDI.DELTA_Q):
            w = self._body_rates(t, euler)
            if typ == XDI.RATE_OF_TURN:
                return w
            ang = math.sqrt(sum(c * c for c in w)) / rate
            if ang == 0.0:
                return (1.0, 0.0, 0.0, 0.0)
            s = math.sin(ang / 2) / (ang * rate)
            return (math.cos(ang / 2), w[0] * s, w[1] * s, w[2] * s)
        if typ == XDI.MAGNETIC_FIELD:
            m = euler_deg_to_matrix(r, p, y)
            field = (0.0, 0.5, -math.sqrt(0.75))  # 1 a.u., 60 degrees inclination, ENU
            return tuple(sum(m[i][j] * field[i] for i in range(3)) for j in range(3))
        if typ == XDI.LAT_LON:
            return (-23.36, 119.73)
        if typ == XDI.ALTITUDE_ELLIPSOID:
            return (550.0,)
        return (0.0, 0.0, 0.0)  # FreeAcceleration, VelocityXYZ: the machine is "still"

    def _body_rates(self, t: float, euler: tuple[float, float, float]) -> tuple[float, ...]:
        h = 0.005
        a = self.angles_at(t - h)
        b = self.angles_at(t + h)
        rates = tuple(_wrap(bv - av) / (2 * h) for av, bv in zip(a, b, strict=True))
        return body_rates(euler, rates)  # type: ignore[arg-type]

