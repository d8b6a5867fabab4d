"""Reading a POSIX serial port with one ``select`` and one ``os.read`` per wake-up.

pyserial's ``Serial.read`` is general (timeouts objects, an abort pipe, a loop until
``size`` bytes) and costs about as much CPU per call as the wake-up itself; a driver
thread that wakes 100 times a second for a small packet pays it every time. For a
plain pyserial port on POSIX, :func:`direct_reader` returns a reader that waits for
the port to become readable and takes everything that is waiting, with pyserial's own
rule for a vanished device (readable but no data). Anything else - a replay's
in-memory port, a recorder's tapped port, another platform - gets None and keeps
using ``read``.
"""

from __future__ import annotations

import os
import select
from collections.abc import Callable
from typing import Any

import serial

try:
    from serial.serialposix import Serial as _PosixSerial
except ImportError:  # pragma: no cover - not POSIX
    _PosixSerial = None


def direct_reader(ser: Any, max_bytes: int = 4096) -> Callable[[float], bytes] | None:
    """``read(timeout_s) -> bytes`` (empty on timeout) for a plain pyserial POSIX port,
    or None when ``ser`` is anything else (then use ``ser.read``)."""
    if _PosixSerial is None or type(ser) is not _PosixSerial:  # exact: wrappers keep read
        return None
    fd = getattr(ser, "fd", None)
    if not isinstance(fd, int):
        return None
    sel, rd = select.select, os.read

    def read(timeout_s: float) -> bytes:
        ready, _, _ = sel((fd,), (), (), timeout_s)
        if not ready:
            return b""
        try:
            data = rd(fd, max_bytes)
        except (BlockingIOError, InterruptedError):
            return b""
        if not data:  # pyserial's words for it
            raise serial.SerialException("device reports readiness to read but returned no "
                                         "data (device disconnected or multiple access on "
                                         "port?)")
        return data
    return read
