"""Recording taps: what a driver's transport reads and writes, with host timestamps.

A serial driver that wants to be recordable opens its port through
:func:`open_serial` (or wraps its own object in :class:`TappedSerial`) and leaves
``tap`` as ``None`` in normal operation; ``shoveld record`` sets a tap and every
chunk the driver reads (``rx``) or writes (``tx``) lands in the capture exactly as
it crossed the wire, stamped when the host saw it. The tap sits below the parser
so the recording holds the bytes, not the driver's interpretation of them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import serial


class ByteTap(Protocol):
    """Receiver of raw transport traffic (implemented by the capture writer)."""

    def rx(self, data: bytes) -> None:
        """Bytes the host received from the device."""

    def tx(self, data: bytes) -> None:
        """Bytes the host sent to the device."""


class TappedSerial:
    """A pyserial-like object that copies every read and write to a :class:`ByteTap`.

    Only the methods shoveld's serial drivers use are forwarded explicitly; any
    other attribute falls through to the wrapped port.
    """

    def __init__(self, port: Any, tap: ByteTap) -> None:
        self._port = port
        self._tap = tap

    def read(self, size: int = 1) -> bytes:
        data: bytes = self._port.read(size)
        if data:
            self._tap.rx(bytes(data))
        return data

    def write(self, data: bytes) -> int | None:
        n = self._port.write(data)
        self._tap.tx(bytes(data))
        return n

    @property
    def in_waiting(self) -> int:
        return int(self._port.in_waiting)

    def reset_input_buffer(self) -> None:
        self._port.reset_input_buffer()

    def flush(self) -> None:
        self._port.flush()

    def close(self) -> None:
        self._port.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._port, name)


SerialFactory = Callable[..., Any]


def open_serial(port: str, baudrate: int, timeout: float, tap: ByteTap | None = None,
                factory: SerialFactory = serial.serial_for_url, **kwargs: Any) -> Any:
    """Open ``port`` (a device path or a pyserial URL), tapped when ``tap`` is given."""
    ser = factory(port, baudrate=baudrate, timeout=timeout, **kwargs)
    return TappedSerial(ser, tap) if tap is not None else ser
