"""Xsens MTi driver over a serial port (RS-232/RS-422/USB-serial), Xbus protocol.

``open()`` walks the documented configuration sequence, each step with a timeout
and a clear :class:`DeviceError`:

1. open the port, drop stale input; answer any WakeUp (0x3E) with WakeUpAck (0x3F)
   (a device that just powered up enters Config state if acknowledged within 500 ms,
   MTi documentation "States");
2. GoToConfig (0x30) -> GoToConfigAck (0x31), resent a few times because a streaming
   device may be mid-packet; silence or noise here means a wrong baud rate or a
   device that is off, and says so;
3. ReqDID (0x00) -> DeviceID (0x01) and ReqFWRev (0x12) -> FirmwareRev (0x13), logged
   and published in ``health.extra``;
4. SetOutputConfiguration (0xC0) for exactly what the loop needs - EulerAngles and
   Quaternion (``orientation = "euler+quaternion"``, the default: two encodings of one
   orientation, so a corrupted angle that passes the one-byte checksum disagrees with
   the other), or either alone, RateOfTurn, Acceleration at ``rate_hz``, PacketCounter,
   SampleTimeFine and StatusWord in every packet - and check the acknowledgement (0xC1);
5. GoToMeasurement (0x10) -> 0x11.

An Error (0x42) answer to any step raises with the decoded error code. In
measurement, ``read()`` decodes MTData2 into :class:`Reading` objects, counts gaps in
the packet counter as ``health.extra["dropped_packets"]``, and raises (so that
``Driver.run`` reconnects and reconfigures) when valid data stops for
``data_timeout_s`` or the device restarts (a WakeUp in the stream).

Not confirmed from vendor documents and therefore configurable: whether a given MTi
model accepts a particular ``rate_hz`` (the device's acknowledgement is checked and
a different rate is logged), and the device's serial framing other than 8N1 (the
default here; legacy devices used 8N2 - ``stopbits`` is configurable).
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections.abc import Callable, Mapping
from typing import Any

import serial

from drivers.base import DeviceError, Driver, Reading, Sink, check_keys, port_error_words
from drivers.serialio import direct_reader
from drivers.xsens.mtdata2 import (
    FRAME_BY_NAME,
    MAX_FREQUENCY,
    PRECISION_BY_NAME,
    XDI,
    decode_output_configuration,
    encode_output_configuration,
    item_label,
    item_size,
    mtdata2_values_ids,
)
from drivers.xsens.orientation import euler_deg_to_quat, quat_to_euler_deg
from drivers.xsens.xbus import MID, MID_NAMES, XbusMessage, XbusParser, describe_error, encode_frame

log = logging.getLogger(__name__)

BAUD_RATES = (4800, 9600, 14400, 19200, 28800, 38400, 57600, 115200, 230400, 460800, 921600,
              2000000, 3686400, 4000000)
"""Baud rates of the MTi SetBaudrate table (MT Low Level Communication Protocol)."""

VALUE_KEYS = ("roll_deg", "pitch_deg", "yaw_deg", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y",
              "acc_z", "packet_counter", "sample_time_fine", "status_word")
_NO_INVALID: frozenset[str] = frozenset()
_EULER, _RATE_OF_TURN, _ACCELERATION = XDI.EULER_ANGLES, XDI.RATE_OF_TURN, XDI.ACCELERATION
_PACKET_COUNTER, _SAMPLE_TIME_FINE, _STATUS_WORD = (XDI.PACKET_COUNTER, XDI.SAMPLE_TIME_FINE,
                                                    XDI.STATUS_WORD)
_QUATERNION = XDI.QUATERNION
ORIENTATIONS = ("euler+quaternion", "euler", "quaternion")
"""What the MTi is asked to send for its orientation; the first is the default."""
EXTRA_OUTPUTS = ("rate_of_turn", "acceleration", "status_word")
"""What the MTi may also be asked to send (``extra_outputs``). The loop uses only the
orientation, so by default none is sent: every byte of a frame then either feeds the
loop or checks what does (the 8-bit checksum lets 1 in 256 corrupted frames through,
and a hit on an item nobody checks against anything reaches the loop unseen)."""
RECORDED_BEFORE_EXTRAS = EXTRA_OUTPUTS
"""What the driver asked for before ``extra_outputs`` existed (2026-11-29): captures
whose manifest names no ``extra_outputs`` were recorded with all three."""
AGREEMENT_DEG = 0.005
"""How far the Euler angles and the quaternion of one packet may disagree (as a rotation):
both come from the device's one orientation, so only rounding separates them (about
1e-5 deg in float32). A corrupted angle byte moves one of them by more than this; half
the 0.01 deg the loop's angles resolve."""
SAMPLE_TIME_FINE_S = 1e-4
"""SampleTimeFine counts a 10 kHz clock (MTi documentation; CAN 'SampleTime' note)."""
GYR_MAX = 35.0
"""rad/s: above 2000 deg/s (34.9 rad/s), the widest gyroscope range of the MTi family
(MTi 1-series datasheet MT0512P and MTi 600-series datasheet MT1603P: +-2000 deg/s; MTi
10/100-series, MT0605P: +-450 deg/s; MTx: +-1200 deg/s). A model's own range is not
used: the device id does not tell it for every model."""
ACC_MAX = 200.0
"""m/s^2: above the widest accelerometer range found in the MTi documents (+-180 m/s^2,
the 18 g option of the MTi/MTx, MT0100P; +-16 g on the MTi 1-series; +-10 g on the
600-series)."""
TINY = 1e-20
"""No measured value lies this close to zero without being zero: each carries the
sensor's noise (a real MTi-G-710 at rest: 0.0013 rad/s, 0.007 m/s^2, 0.001 deg sample
to sample; its smallest magnitudes in 300 packets, fixture ``xsens-mti-g710``, are
8.6e-6 rad/s and 4e-8 in a DeltaQ), so one lands inside 1e-20 with a chance of about
1e-17, once in 10^6 years of packets; fixed point outputs step by 2^-32 at the finest.
What lands there is a float whose exponent byte was hit: 0.0 turned into 1e-40, a
rate of 0.04 into 3e-25."""
STATUS_RESERVED = 0xE0020000
"""StatusWord bits no Xsens document defines: 17 and 29-31. The SDK's
``XsStatusFlag`` (xsstatusflag.h, 2021) names bits 0-16 and 18-28 (selftest, filter
valid, GNSS fix, no-rotation, clip flags, clipping, sync in/out, filter mode, GNSS
time pulse, RTK status); the MTi user manual (MT0605P, 'Status byte') bits 0-16 and
19-25, and Xsens' ROS driver's ``XsStatusWord`` message marks 17-18, 20 and 29-31
reserved. A device sends them clear; a corrupted status byte mostly sets one."""
STATUS_SELFTEST = 0x1
"""StatusWord bit 0: the device passed its latest self-test (RunSelftest, a Config
state command, or at power-up): it cannot change between two packets of one
measurement."""


def firmware_text(data: bytes) -> str:
    """FirmwareRev data: major, minor, revision, and (newer firmware) build and SVN revision."""
    if len(data) < 3:
        return data.hex()
    text = f"{data[0]}.{data[1]}.{data[2]}"
    if len(data) >= 11:
        build, rev = struct.unpack_from(">II", data, 3)
        text += f" build {build} rev {rev}"
    return text


class MtiSerialDriver(Driver):
    """One Xsens MTi on a serial port; emits roll/pitch/yaw (and rates, accelerations and
    the status word where ``extra_outputs`` asks for them)."""

    CONFIG_KEYS: tuple[str, ...] = (
        "name", "port", "baudrate", "rate_hz", "orientation", "extra_outputs", "precision",
        "coordinate_frame", "stopbits", "command_timeout_s", "data_timeout_s",
        "read_timeout_s", "backoff_s")

    def __init__(self, name: str = "mti", port: str = "/dev/ttyUSB0", baudrate: int = 115200,
                 rate_hz: int = 100, orientation: str = ORIENTATIONS[0],
                 extra_outputs: tuple[str, ...] | list[str] = (),
                 precision: str = "float32",
                 coordinate_frame: str = "ENU", stopbits: int = 1,
                 command_timeout_s: float = 1.0, data_timeout_s: float = 1.0,
                 read_timeout_s: float = 0.05, clock: Callable[[], float] = time.monotonic,
                 backoff_s: tuple[float, float] = (0.2, 5.0),
                 serial_factory: Callable[..., serial.Serial] = serial.Serial,
                 timeout_clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(name, clock=clock, backoff_s=backoff_s)
        self.timeout_clock = timeout_clock
        """The clock ``data_timeout_s`` runs on: host time live; a replay stepped by its
        loop passes its capture clock, so a recorded silence is judged in capture time and
        the host's speed cannot change the outcome."""
        _check("port", port, isinstance(port, str) and bool(port), "a device path")
        _check("baudrate", baudrate, baudrate in BAUD_RATES, f"one of {BAUD_RATES}")
        _check("rate_hz", rate_hz, isinstance(rate_hz, int) and 1 <= rate_hz <= 2000,
               "an integer in 1..2000 Hz")
        _check("orientation", orientation, orientation in ORIENTATIONS,
               f"one of {ORIENTATIONS}")
        _check("extra_outputs", extra_outputs,
               isinstance(extra_outputs, (list, tuple))
               and all(isinstance(x, str) and x in EXTRA_OUTPUTS for x in extra_outputs)
               and len(set(extra_outputs)) == len(extra_outputs),
               f"a list of distinct items of {list(EXTRA_OUTPUTS)}")
        _check("precision", precision, precision in PRECISION_BY_NAME,
               f"one of {sorted(PRECISION_BY_NAME)}")
        _check("coordinate_frame", coordinate_frame, coordinate_frame in FRAME_BY_NAME,
               f"one of {sorted(FRAME_BY_NAME)}")
        _check("stopbits", stopbits, stopbits in (1, 2), "1 or 2")
        for key, v in (("command_timeout_s", command_timeout_s),
                       ("data_timeout_s", data_timeout_s), ("read_timeout_s", read_timeout_s)):
            _check(key, v, isinstance(v, (int, float)) and 0 < v <= 60, "seconds in (0, 60]")
        self.port = port
        self.baudrate = baudrate
        self.rate_hz = rate_hz
        self.orientation = orientation
        self._redundant = orientation == "euler+quaternion"
        self.extra_outputs = tuple(x for x in EXTRA_OUTPUTS if x in extra_outputs)
        self._want_g, self._want_acc, self._want_sw = (x in self.extra_outputs
                                                       for x in EXTRA_OUTPUTS)
        self.value_keys = tuple(k for k in VALUE_KEYS if not (
            (k.startswith("gyr") and not self._want_g)
            or (k.startswith("acc") and not self._want_acc)
            or (k == "status_word" and not self._want_sw)))
        """The quantities of this configuration's readings, in :data:`VALUE_KEYS` order."""
        self.precision = precision
        self.coordinate_frame = coordinate_frame
        self.stopbits = stopbits
        self.command_timeout_s = float(command_timeout_s)
        self.data_timeout_s = float(data_timeout_s)
        self.read_timeout_s = float(read_timeout_s)
        need = self.line_load() * baudrate  # the device drops what the line cannot carry
        _check("baudrate", baudrate, need <= baudrate,
               f"at least {need:.0f} baud for {self.packet_bytes()}-byte packets at "
               f"{rate_hz} Hz (raise 'baudrate' or lower 'rate_hz')")
        self.serial_factory = serial_factory
        self.device_id: int | None = None
        self.firmware: str | None = None
        self.output_configuration: list[tuple[int, int]] = []
        self._ser: serial.Serial | None = None
        self._direct: Callable[[float], bytes] | None = None
        self._parser = XbusParser()
        self._counted = (0, 0)
        self._prev_counter: int | None = None
        self._prev_frame: tuple[int, int, tuple[float, float, float], int] | None = None
        """(packet counter, sample time fine, euler, status word) of the last full frame
        seen."""
        self._ids = frozenset(x for x, _ in self.requested_outputs())
        """The identifiers the device sends, precision and frame bits included: those
        requested, then (``open``) those it acknowledged, which include them."""
        self._last_valid = 0.0
        self.health.extra.setdefault("dropped_packets", 0)
        self.health.extra.setdefault("inconsistent_frames", 0)
        self.health.extra.setdefault("device_errors", 0)

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], **kwargs: Any) -> MtiSerialDriver:
        """Build from a config mapping; ValueError names the first bad or unknown key."""
        check_keys("mti config", cfg, cls.CONFIG_KEYS, {"port": "serial device path"})
        args = dict(cfg)
        if "backoff_s" in args:
            b = args["backoff_s"]
            ok = (isinstance(b, (list, tuple)) and len(b) == 2
                  and all(isinstance(x, (int, float)) and x > 0 for x in b) and b[0] <= b[1])
            _check("backoff_s", b, ok, "[initial, maximum] seconds")
            args["backoff_s"] = (float(b[0]), float(b[1]))
        return cls(**args, **kwargs)

    # --- transport ------------------------------------------------------------------

    def _where(self) -> str:
        return f"{self.port} at {self.baudrate} baud"

    def _write(self, mid: int, data: bytes = b"") -> None:
        if self._ser is None:
            raise DeviceError(f"MTi port {self.port} is not open")
        try:
            self._ser.write(encode_frame(mid, data))
            self._ser.flush()
        except (OSError, serial.SerialException) as e:
            raise DeviceError(f"MTi on {self.port} disconnected: {e}") from e

    def _account(self) -> None:
        """Move the parser's loss counters into health (they survive reconnects)."""
        rb, bf = self._parser.rejected_bytes, self._parser.bad_frames
        self.health.rejected_bytes += rb - self._counted[0]
        self.health.bad_frames += bf - self._counted[1]
        self._counted = (rb, bf)

    def _receive(self) -> list[XbusMessage]:
        if self._ser is None:
            raise DeviceError(f"MTi port {self.port} is not open")
        try:
            if self._direct is not None:  # a plain port: one select, one read
                data = self._direct(self.read_timeout_s)
            else:
                ser = self._ser
                data = ser.read(max(1, ser.in_waiting))
                if len(data) == 1:  # woke on a message's first byte: the rest came with it
                    n = ser.in_waiting
                    if n:
                        data += ser.read(n)
        except (OSError, serial.SerialException) as e:
            raise DeviceError(f"MTi on {self.port} disconnected: {e}") from e
        if not data:
            return []
        msgs = self._parser.feed(data)
        self._account()  # counters move only when bytes were fed
        return msgs

    def _command(self, mid: int, data: bytes, expect: int, retries: int = 1) -> XbusMessage:
        """Send a request and wait for its acknowledgement; handle WakeUp and Error."""
        name = MID_NAMES.get(mid, f"0x{mid:02X}")
        rejected0 = self._parser.rejected_bytes
        seen = 0
        deadline = time.monotonic() + self.command_timeout_s
        resend_every = self.command_timeout_s / max(1, retries)
        next_send = 0.0
        while True:
            now = time.monotonic()
            if now >= deadline:
                break
            if now >= next_send:
                self._write(mid, data)
                next_send = now + resend_every
            for msg in self._receive():
                seen += 1
                if msg.mid == expect:
                    return msg
                if msg.mid == MID.ERROR:
                    self.health.extra["device_errors"] += 1
                    raise DeviceError(f"MTi on {self.port} answered {name} with error "
                                      f"{describe_error(msg.data)}")
                if msg.mid == MID.WAKEUP:
                    log.info("%s: WakeUp from MTi on %s, acknowledging", self.name, self.port)
                    self._write(MID.WAKEUP_ACK)
        noise = self._parser.rejected_bytes - rejected0
        if seen == 0:
            extra = f" ({noise} bytes of noise received)" if noise else ""
            raise DeviceError(f"no answer from MTi on {self._where()}: wrong baud rate or "
                              f"device off?{extra}")
        raise DeviceError(f"MTi on {self.port} did not acknowledge {name} within "
                          f"{self.command_timeout_s:g} s ({seen} other messages received)")

    # --- Driver interface ---------------------------------------------------------------

    def requested_outputs(self) -> list[tuple[int, int]]:
        """The (XDI, frequency) list sent with SetOutputConfiguration."""
        prec = PRECISION_BY_NAME[self.precision]
        frame = FRAME_BY_NAME[self.coordinate_frame]
        ori = XDI.QUATERNION if self.orientation == "quaternion" else XDI.EULER_ANGLES
        out = [(XDI.PACKET_COUNTER, MAX_FREQUENCY), (XDI.SAMPLE_TIME_FINE, MAX_FREQUENCY),
               (ori | frame | prec, self.rate_hz)]  # the orientation third: its rate is read
        if self._want_acc:
            out.append((XDI.ACCELERATION | prec, self.rate_hz))
        if self._want_g:
            out.append((XDI.RATE_OF_TURN | prec, self.rate_hz))
        if self._want_sw:
            out.append((XDI.STATUS_WORD, MAX_FREQUENCY))
        if self._redundant:
            out.append((XDI.QUATERNION | frame | prec, self.rate_hz))
        return out

    def packet_bytes(self) -> int:
        """Bytes on the line of one MTData2 packet of :meth:`requested_outputs`."""
        payload = sum(3 + (item_size(xdi) or 0) for xdi, _ in self.requested_outputs())
        return payload + 5 + (2 if payload > 254 else 0)  # FA FF 36 LEN .. checksum

    def line_load(self) -> float:
        """Share of the serial line the configured packets take (start, 8 data, stop
        bits per byte)."""
        return self.packet_bytes() * (9 + self.stopbits) * self.rate_hz / self.baudrate

    def open(self) -> None:
        self.close()
        try:
            self._ser = self.serial_factory(
                self.port, self.baudrate, timeout=self.read_timeout_s, write_timeout=1.0,
                stopbits=serial.STOPBITS_TWO if self.stopbits == 2 else serial.STOPBITS_ONE)
            self._ser.reset_input_buffer()
        except (OSError, serial.SerialException, ValueError) as e:
            self._ser = None
            raise DeviceError(f"cannot open MTi port {self.port}: {port_error_words(e)}"
                              ) from e
        self._direct = direct_reader(self._ser)
        self._parser.reset()
        self._command(MID.GOTO_CONFIG, b"", MID.GOTO_CONFIG_ACK, retries=4)
        did = self._command(MID.REQ_DID, b"", MID.DEVICE_ID)
        self.device_id = int.from_bytes(did.data, "big") if did.data else None
        fw = self._command(MID.REQ_FW_REV, b"", MID.FIRMWARE_REV)
        self.firmware = firmware_text(fw.data)
        log.info("%s: MTi on %s: device id %s, firmware %s", self.name, self._where(),
                 f"{self.device_id:08X}" if self.device_id is not None else "?", self.firmware)
        self.health.extra["device_id"] = (f"{self.device_id:08X}"
                                          if self.device_id is not None else None)
        self.health.extra["firmware"] = self.firmware
        wanted = self.requested_outputs()
        ack = self._command(MID.SET_OUTPUT_CONFIGURATION, encode_output_configuration(wanted),
                            MID.OUTPUT_CONFIGURATION)
        got = {s.xdi: s.frequency for s in decode_output_configuration(ack.data)}
        missing = [item_label(x) for x, _ in wanted if got.get(x, 0) == 0]
        if missing:
            raise DeviceError(f"MTi on {self.port} refused output {', '.join(missing)} "
                              f"(acknowledged {[item_label(x) for x in got]})")
        for x, f in wanted:
            if got[x] != f:
                log.warning("%s: MTi set %s to %s Hz instead of %s Hz", self.name,
                            item_label(x), got[x], f)
        self.output_configuration = sorted(got.items())
        self._ids = frozenset(x for x, f in got.items() if f)  # what it will send
        self.health.extra["output_rate_hz"] = got[wanted[2][0]]
        self._command(MID.GOTO_MEASUREMENT, b"", MID.GOTO_MEASUREMENT_ACK)
        self._prev_counter = None
        self._prev_frame = None
        self._last_valid = self.timeout_clock()
        log.info("%s: MTi on %s measuring at %s Hz", self.name, self.port,
                 self.health.extra["output_rate_hz"])

    def read(self, sink: Sink) -> None:
        msgs = self._receive()
        now = self.timeout_clock()
        for msg in msgs:
            if msg.mid == MID.MTDATA2:
                self._last_valid = now
                reading = self.decode(msg.data)
                if reading is not None:
                    self.emit(sink, reading)
            elif msg.mid == MID.ERROR:
                self.health.extra["device_errors"] += 1
                self.health.last_error = f"MTi error {describe_error(msg.data)}"
                log.warning("%s: %s", self.name, self.health.last_error)
            elif msg.mid == MID.WAKEUP:
                self._write(MID.WAKEUP_ACK)
                raise DeviceError(f"MTi on {self.port} restarted (WakeUp); reconfiguring")
        if now - self._last_valid > self.data_timeout_s:
            self.health.timeouts += 1
            raise DeviceError(f"no data from MTi on {self.port} for "
                              f"{now - self._last_valid:.1f} s")

    def decode(self, payload: bytes) -> Reading | None:
        """One MTData2 payload -> Reading (quantities the packet lacks are marked invalid)."""
        t_host = self.clock()
        items, ids = mtdata2_values_ids(payload)
        get = items.get
        e, pc, stf = get(_EULER), get(_PACKET_COUNTER), get(_SAMPLE_TIME_FINE)
        g = get(_RATE_OF_TURN) if self._want_g else None
        acc = get(_ACCELERATION) if self._want_acc else None
        sw = get(_STATUS_WORD) if self._want_sw else None
        q = get(_QUATERNION) if self._redundant else None
        if (e is not None and pc is not None and stf is not None  # the configured packet
                and (q is not None or not self._redundant)
                and (g is not None or not self._want_g)
                and (acc is not None or not self._want_acc)
                and (sw is not None or not self._want_sw)):
            if ids is None or not ids <= self._ids:
                # not the configured packet: an identifier byte was hit (a precision or
                # frame bit decodes the same bytes another way, or in another frame)
                self._inconsistent()
                return None
            if not self._consistent(pc, stf, e, g, acc, q, sw):
                return None
            self._count_gap(pc)
            values: dict[str, float] = {
                "roll_deg": e[0], "pitch_deg": e[1], "yaw_deg": e[2],
                "packet_counter": float(pc), "sample_time_fine": float(stf)}
            if g is not None:
                values["gyr_x"], values["gyr_y"], values["gyr_z"] = g
            if acc is not None:
                values["acc_x"], values["acc_y"], values["acc_z"] = acc
            if sw is not None:
                values["status_word"] = float(sw)
            return Reading(self.name, t_host, values, _NO_INVALID, stf * SAMPLE_TIME_FINE_S)
        if self._prev_frame is not None:
            # This device sends the configured packet; one with other or missing items is
            # a corrupted frame that happened to pass the checksum.
            self._inconsistent()
            return None
        values = {}
        v = items.get(XDI.EULER_ANGLES)
        if v is None and XDI.QUATERNION in items:
            v = quat_to_euler_deg(items[XDI.QUATERNION])
        if v is not None:
            values["roll_deg"], values["pitch_deg"], values["yaw_deg"] = v
        v = items.get(XDI.RATE_OF_TURN)
        if v is not None:
            values["gyr_x"], values["gyr_y"], values["gyr_z"] = v
        v = items.get(XDI.ACCELERATION)
        if v is not None:
            values["acc_x"], values["acc_y"], values["acc_z"] = v
        v = items.get(XDI.PACKET_COUNTER)
        if v is not None:
            values["packet_counter"] = float(v)
            self._count_gap(v)
        stf = items.get(XDI.SAMPLE_TIME_FINE)
        if stf is not None:
            values["sample_time_fine"] = float(stf)
        v = items.get(XDI.STATUS_WORD)
        if v is not None:
            values["status_word"] = float(v)
        if not values:
            return None
        invalid = frozenset(k for k in self.value_keys if k not in values)
        return Reading(device=self.name, t_host=t_host, values=values, invalid=invalid,
                       t_device=stf * SAMPLE_TIME_FINE_S if stf is not None else None)

    MAX_GAP = 50
    """Packets a frame may follow the previous one by (dropped ones in between)."""

    def _consistent(self, pc: int, stf: int, e: tuple[float, ...],
                    g: tuple[float, ...] | None, acc: tuple[float, ...] | None,
                    q: tuple[float, ...] | None = None, sw: int | None = 0) -> bool:
        """Does the frame agree with itself and with the one before? The Xbus checksum is
        one byte, so about 1 in 256 corrupted frames pass it; what the frame carries
        catches them: the Euler angles and the quaternion (when both are sent) must be
        one orientation, the packet counter and the 10 kHz sample time must advance
        together (:func:`sample_time_slack_s`), the values must be finite, in the
        sensor's range (:data:`GYR_MAX`, :data:`ACC_MAX`) and not next to zero
        (:data:`TINY`), the status word's reserved bits clear and its self-test bit
        unchanged, and the angles cannot jump further than the measured rate of turn
        allows (with 2 deg of slack: a real MTi-G-710's filter corrects its angles in
        steps of up to 0.4 deg, fixture ``xsens-mti-g710``; without a rate of turn,
        :data:`GYR_MAX`). The items not
        configured (``g``, ``acc``, ``sw`` None) are not checked. A frame that fails is
        counted and dropped; it still becomes the reference, so after a real reset of the
        device one frame is lost, not all.
        :func:`drivers.xsens.serial_span.consistent` is this rule on columns."""
        if sw is None:
            sw = 0
        prev, self._prev_frame = self._prev_frame, (pc, stf, (e[0], e[1], e[2]), sw)
        # (a NaN fails every comparison, so each bound is written to hold, not to fail)
        if not (abs(e[0]) <= 180.0 and abs(e[1]) <= 90.0 and abs(e[2]) <= 180.0
                and (g is None or (abs(g[0]) <= GYR_MAX and abs(g[1]) <= GYR_MAX
                                   and abs(g[2]) <= GYR_MAX))
                and (acc is None or (abs(acc[0]) <= ACC_MAX and abs(acc[1]) <= ACC_MAX
                                     and abs(acc[2]) <= ACC_MAX))
                and not sw & STATUS_RESERVED):
            return self._inconsistent()
        for v in (e, g, acc, q):
            if v is not None and (0.0 < abs(v[0]) < TINY or 0.0 < abs(v[1]) < TINY
                                  or 0.0 < abs(v[2]) < TINY):
                return self._inconsistent()
        if q is not None and (0.0 < abs(q[3]) < TINY or not orientations_agree(e, q)):
            return self._inconsistent()
        if prev is None:
            return True
        n = (pc - prev[0]) & 0xFFFF
        dt = ((stf - prev[1]) & 0xFFFFFFFF) * SAMPLE_TIME_FINE_S
        rate = float(self.health.extra.get("output_rate_hz") or self.rate_hz)
        # the sample time counts a 10 kHz clock: packets n apart are n/rate apart
        if (not 1 <= n <= self.MAX_GAP or abs(dt - n / rate) > sample_time_slack_s(rate)
                or (sw ^ prev[3]) & STATUS_SELFTEST):
            return self._inconsistent()
        # 2 deg of slack, plus three times what the fastest measured rate could turn
        gmax = GYR_MAX / 3.0 if g is None else max(abs(g[0]), abs(g[1]), abs(g[2]))
        limit = 2.0 + 3.0 * 57.3 * gmax * dt
        for a, b in zip(e, prev[2], strict=False):
            if abs((a - b + 180.0) % 360.0 - 180.0) > limit:
                return self._inconsistent()
        return True

    def _inconsistent(self) -> bool:
        self.health.bad_frames += 1
        self.health.extra["inconsistent_frames"] += 1
        return False

    def _count_gap(self, counter: int) -> None:
        prev = self._prev_counter
        self._prev_counter = counter
        if prev is None:
            return
        gap = (counter - prev - 1) & 0xFFFF
        if gap and gap < 0x8000:
            self.health.extra["dropped_packets"] += gap
        elif gap:
            log.warning("%s: packet counter jumped back from %d to %d", self.name, prev, counter)

    def close(self) -> None:
        self._direct = None
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except (OSError, serial.SerialException):
                pass


def sample_time_slack_s(rate: float) -> float:
    """How far two packets' sample times may be from ``n / rate`` apart: half a tick
    (so: exactly) where a period is a whole number of 10 kHz ticks, as for every rate
    that divides the MTi's 400 Hz (a real MTi-G-710 at 100 Hz: 100 ticks between
    every two packets of fixtures ``xsens-mti-g710/1``, ``/3`` and ``/5``); otherwise
    1.5 ticks, for the rounding of a period that is not."""
    ticks = round(1.0 / SAMPLE_TIME_FINE_S) / rate  # 10000 / rate, exact where whole
    return (0.5 if ticks == round(ticks) else 1.5) * SAMPLE_TIME_FINE_S


def orientations_agree(e: tuple[float, ...], q: tuple[float, ...],
                       tol_deg: float = AGREEMENT_DEG) -> bool:
    """Are Euler angles ``e`` (deg) and quaternion ``q`` one orientation within ``tol_deg``?
    Compared as quaternions (the angle of the rotation between them), which has no
    singularity at pitch +-90 deg as a comparison of angles would; a quaternion whose
    norm is off by more than rounding is itself corrupted."""
    n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]
    if not abs(n2 - 1.0) <= 1e-4:
        return False
    r = euler_deg_to_quat(e[0], e[1], e[2])
    dot = r[0] * q[0] + r[1] * q[1] + r[2] * q[2] + r[3] * q[3]
    # sin(half the angle between them) = sqrt(1 - cos^2), exact near zero
    s2 = 1.0 - dot * dot / n2
    return s2 <= math.sin(math.radians(tol_deg) / 2.0) ** 2


def _check(key: str, value: object, ok: bool, expected: str) -> None:
    if not ok:
        raise ValueError(f"mti config: '{key}' must be {expected}, got {value!r}")
