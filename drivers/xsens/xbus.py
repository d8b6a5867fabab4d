"""Xbus framing of Xsens MTi devices: message ids, encoder, streaming parser.

Frame layout (MT Low Level Communication Protocol, MT0101P; MTi and MTx user manual
MT0100P section 5.3.1)::

    PRE=0xFA  BID=0xFF  MID  LEN  [EXT_LEN_H EXT_LEN_L if LEN == 0xFF]  DATA  CS

The checksum makes the low byte of the sum of every byte after the preamble zero.
All multi-byte values are big-endian. Message ids are those of the vendor's SDK
``XsXbusMessageId`` enum (xsxbusmessageid.h) and the MTi user manual (MT0605P
section 5.3.3); error codes those of the SDK's ``XsResultValue`` (xsresultvalue.h).

Not confirmed from a vendor document: the largest extended payload a device sends.
:class:`XbusParser` takes ``max_payload`` (default 2048, far above any MTData2 this
project configures) so a noise byte pair that looks like an extended header cannot
stall the stream for long.
"""

from __future__ import annotations

import struct
from typing import NamedTuple
from zlib import adler32 as _adler32

from drivers.sniffer import BAD_FRAME, NEED_MORE, NOT_A_FRAME, PacketSniffer

PREAMBLE = 0xFA
BID_MASTER = 0xFF
EXTENDED_LENGTH = 0xFF
SYNC = bytes((PREAMBLE, BID_MASTER))


class MID:
    """Xbus message identifiers used by shoveld (requests and their acknowledgements)."""

    REQ_DID = 0x00
    DEVICE_ID = 0x01
    GOTO_MEASUREMENT = 0x10
    GOTO_MEASUREMENT_ACK = 0x11
    REQ_FW_REV = 0x12
    FIRMWARE_REV = 0x13
    REQ_PRODUCT_CODE = 0x1C
    PRODUCT_CODE = 0x1D
    GOTO_CONFIG = 0x30
    GOTO_CONFIG_ACK = 0x31
    MTDATA2 = 0x36
    WAKEUP = 0x3E
    WAKEUP_ACK = 0x3F
    RESET = 0x40
    RESET_ACK = 0x41
    ERROR = 0x42
    REQ_OUTPUT_CONFIGURATION = 0xC0
    SET_OUTPUT_CONFIGURATION = 0xC0
    OUTPUT_CONFIGURATION = 0xC1


MID_NAMES: dict[int, str] = {
    MID.REQ_DID: "ReqDID", MID.DEVICE_ID: "DeviceID", MID.GOTO_MEASUREMENT: "GoToMeasurement",
    MID.GOTO_MEASUREMENT_ACK: "GoToMeasurementAck", MID.REQ_FW_REV: "ReqFWRev",
    MID.FIRMWARE_REV: "FirmwareRev", MID.REQ_PRODUCT_CODE: "ReqProductCode",
    MID.PRODUCT_CODE: "ProductCode", MID.GOTO_CONFIG: "GoToConfig",
    MID.GOTO_CONFIG_ACK: "GoToConfigAck", MID.MTDATA2: "MTData2", MID.WAKEUP: "WakeUp",
    MID.WAKEUP_ACK: "WakeUpAck", MID.RESET: "Reset", MID.RESET_ACK: "ResetAck",
    MID.ERROR: "Error", MID.SET_OUTPUT_CONFIGURATION: "SetOutputConfiguration",
    MID.OUTPUT_CONFIGURATION: "OutputConfiguration",
}

# Error codes carried in the first data byte of an Error (0x42) message.
ERROR_CODES: dict[int, str] = {
    0x03: "invalid period",
    0x04: "invalid message (not valid or not implemented)",
    0x1E: "timer overflow during measurement",
    0x20: "baud rate out of valid range",
    0x21: "invalid parameter",
    0x23: "TX PC buffer full",
    0x24: "TX PC buffer overflow, message does not fit",
    0x28: "device error (see the 4-byte device error code; try updating the firmware)",
    0x29: "data overflow: more data than the baud rate can carry",
    0x2A: "sample buffer overflow during a communication outage",
}

# Sub-codes of error 0x28 (XsDeviceErrorType), 4 bytes after the error code.
DEVICE_ERROR_TYPES: dict[int, str] = {
    0: "unknown", 1: "IMCU timeout", 2: "IMCU settings invalid", 3: "IMCU settings failure",
    4: "IMCU eMTS write failure", 5: "IMCU eMTS read failure", 6: "DSP crashed",
    7: "DSP booting timeout",
}


class XbusMessage(NamedTuple):
    """One checked Xbus message: message id and data bytes (no header, no checksum)."""

    mid: int
    data: bytes


_new_tuple = tuple.__new__


def encode_frame(mid: int, data: bytes = b"", bid: int = BID_MASTER,
                 extended: bool | None = None) -> bytes:
    """Build a complete Xbus frame; the extended length form is used for >= 255 data bytes
    (or always/never with ``extended=True/False``; the parser accepts both forms)."""
    n = len(data)
    if extended is None:
        extended = n >= EXTENDED_LENGTH
    if not extended:
        if n >= EXTENDED_LENGTH:
            raise ValueError(f"{n} data bytes need the extended length form")
        head = bytes((bid, mid & 0xFF, n))
    elif n <= 0xFFFF:
        head = bytes((bid, mid & 0xFF, EXTENDED_LENGTH, n >> 8, n & 0xFF))
    else:
        raise ValueError(f"Xbus data too long: {n} bytes")
    body = head + bytes(data)
    return bytes((PREAMBLE,)) + body + bytes(((-sum(body)) & 0xFF,))


def checksum_ok(frame: bytes | bytearray) -> bool:
    """True if ``frame`` (preamble included) has a valid checksum."""
    return len(frame) >= 5 and (sum(frame[1:]) & 0xFF) == 0


def describe_error(data: bytes) -> str:
    """Human text for the data of an Error message."""
    if not data:
        return "error message without code"
    code = data[0]
    text = f"0x{code:02X} ({ERROR_CODES.get(code, 'unknown error code')})"
    if code == 0x28 and len(data) >= 5:
        sub = struct.unpack_from(">I", data, 1)[0]
        text += f", device error {sub}: {DEVICE_ERROR_TYPES.get(sub, 'unknown')}"
    return text


class XbusParser:
    """Streaming Xbus parser: feed bytes, get checked :class:`XbusMessage` objects.

    Resynchronises on garbage and bad checksums without losing the next good frame
    (see :mod:`drivers.sniffer`); ``rejected_bytes`` and ``bad_frames`` count the
    losses for :class:`drivers.base.DriverHealth`. Only bus id 0xFF (master) frames
    are accepted, as every MTi uses it.
    """

    def __init__(self, max_payload: int = 2048) -> None:
        if not 254 <= max_payload <= 0xFFFF:
            raise ValueError(f"max_payload must be in [254, 65535], got {max_payload}")
        self.max_payload = max_payload
        self._sniffer = PacketSniffer(SYNC, self._measure, max_pending=max_payload + 16,
                                      make=self._make)

    def _measure(self, buf: bytearray, i: int) -> int:
        n = len(buf)
        if n - i < 5:
            return NEED_MORE
        ln = buf[i + 3]
        if ln == EXTENDED_LENGTH:
            if n - i < 7:
                return NEED_MORE
            ln = (buf[i + 4] << 8) | buf[i + 5]
            if ln > self.max_payload:
                return NOT_A_FRAME
            total = ln + 7
        else:
            total = ln + 5
        if n - i < total:
            return NEED_MORE
        if total <= 257:  # <= 256 bytes summed: adler32's low half is exactly 1 + their sum
            if (_adler32(buf[i + 1:i + total]) - 1) & 0xFF:  # (C speed; sum() is 3x slower)
                return BAD_FRAME
        elif sum(buf[i + 1:i + total]) & 0xFF:
            return BAD_FRAME
        return total

    @staticmethod
    def _make(buf: bytearray, i: int, n: int) -> XbusMessage:
        # tuple.__new__ directly: the NamedTuple's generated __new__ is a Python call
        if buf[i + 3] == EXTENDED_LENGTH:
            return _new_tuple(XbusMessage, (buf[i + 2], bytes(buf[i + 6:i + n - 1])))
        return _new_tuple(XbusMessage, (buf[i + 2], bytes(buf[i + 4:i + n - 1])))

    def feed(self, data: bytes | bytearray | memoryview) -> list[XbusMessage]:
        """Add received bytes; return the complete checked messages, in order."""
        return self._sniffer.feed(data)

    def finish(self) -> int:
        """End of stream: count a trailing partial frame as rejected; return its size."""
        return self._sniffer.finish()

    def reset(self) -> None:
        """Drop buffered bytes (after reopening the port); counters are kept."""
        self._sniffer.reset()

    @property
    def rejected_bytes(self) -> int:
        return self._sniffer.rejected_bytes

    @property
    def bad_frames(self) -> int:
        return self._sniffer.bad_frames

    @property
    def frames(self) -> int:
        return self._sniffer.frames

    @property
    def pending(self) -> int:
        return self._sniffer.pending
