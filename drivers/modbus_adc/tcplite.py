"""A small synchronous Modbus TCP client for what the ADC driver does: read registers.

pymodbus' synchronous client is general (framers, transaction manager, PDU classes,
logging hooks); per poll it costs several times the socket exchange itself, and the
driver polls two modules 50 times a second each. :class:`ModbusTcpLite` speaks the
same protocol for function codes 3 and 4 only, with the interface subset the driver
uses (``connect``, ``connected``, ``close``, ``read_input_registers``,
``read_holding_registers``; responses with ``registers``, ``isError()``,
``exception_code``) and pymodbus' exceptions, so the driver's error handling is
unchanged.

Protocol (Modbus Messaging on TCP/IP Implementation Guide V1.0b): each request and
response starts with the MBAP header - transaction id, protocol id 0, length of what
follows, unit id - then the PDU: function code, address, count (request) or function
code, byte count, register words big-endian (response); an exception response has
the function code with bit 7 set and the exception code. A response is matched to its
request by transaction id, so a late answer to a request that timed out is skipped
rather than taken for the next one.
"""

from __future__ import annotations

import socket
import struct
import time
from typing import Any

from pymodbus.exceptions import ConnectionException, ModbusIOException

_REQUEST = struct.Struct(">HHHBBHH")
_MAX_LENGTH = 254
"""Longest MBAP length field (unit id + a 253-byte PDU)."""


class LiteResponse:
    """What the driver reads from a response (pymodbus' names)."""

    __slots__ = ("registers", "exception_code")

    def __init__(self, registers: list[int], exception_code: int | None = None) -> None:
        self.registers = registers
        self.exception_code = exception_code

    def isError(self) -> bool:  # noqa: N802 - pymodbus' name
        return self.exception_code is not None


class ModbusTcpLite:
    """Register reads over one TCP connection; ``timeout`` per request, ``retries``
    resends after a timeout (as pymodbus' client)."""

    def __init__(self, host: str, port: int = 502, timeout: float = 0.1, retries: int = 0
                 ) -> None:
        self.host = host
        self.port = int(port)
        self.timeout = float(timeout)
        self.retries = int(retries)
        self._sock: socket.socket | None = None
        self._buf = bytearray()
        self._tid = 0

    @property
    def connected(self) -> bool:
        return self._sock is not None

    def connect(self) -> bool:
        if self._sock is not None:
            return True
        try:
            s = socket.create_connection((self.host, self.port), timeout=self.timeout)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except OSError:
            return False
        self._sock = s
        self._buf.clear()
        return True

    def close(self) -> None:
        s, self._sock = self._sock, None
        self._buf.clear()
        if s is not None:
            try:
                s.close()
            except OSError:
                pass

    def read_input_registers(self, address: int, count: int = 1, device_id: int = 1,
                             **_: Any) -> LiteResponse:
        return self._request(4, address, count, device_id)

    def read_holding_registers(self, address: int, count: int = 1, device_id: int = 1,
                               **_: Any) -> LiteResponse:
        return self._request(3, address, count, device_id)

    # -- exchange ------------------------------------------------------------------------
    def _request(self, fc: int, address: int, count: int, unit: int) -> LiteResponse:
        for _attempt in range(self.retries + 1):
            s = self._sock
            if s is None:
                raise ConnectionException(f"Modbus TCP {self.host}:{self.port}: not connected")
            self._tid = tid = (self._tid + 1) & 0xFFFF
            try:
                s.sendall(_REQUEST.pack(tid, 0, 6, unit, fc, address, count))
            except OSError as e:
                self.close()
                raise ConnectionException(f"Modbus TCP {self.host}:{self.port}: {e}") from e
            deadline = time.monotonic() + self.timeout
            while True:
                frame = self._frame(deadline)
                if frame is None:
                    break  # timed out: resend, or give up below
                if frame[0] != tid >> 8 or frame[1] != tid & 0xFF:
                    continue  # the late answer to an earlier request
                rfc = frame[7]
                if rfc == fc | 0x80:
                    return LiteResponse([], frame[8] if len(frame) > 8 else 4)
                if rfc != fc or len(frame) < 9:
                    raise ModbusIOException(f"unexpected response function {rfc} to {fc}")
                n = min(frame[8], len(frame) - 9) // 2
                return LiteResponse(list(struct.unpack_from(f">{n}H", frame, 9)))
        raise ModbusIOException(f"no response from {self.host}:{self.port} within "
                                f"{self.timeout:g} s")

    def _frame(self, deadline: float) -> bytes | None:
        """The next whole MBAP frame from the connection, None at ``deadline``."""
        buf = self._buf
        s = self._sock
        while True:
            if len(buf) >= 7:
                length = (buf[4] << 8) | buf[5]
                if buf[2] or buf[3] or not 2 <= length <= _MAX_LENGTH:
                    self.close()  # not Modbus TCP any more: start a clean connection
                    raise ModbusIOException(f"Modbus TCP {self.host}:{self.port}: garbled "
                                            "response header")
                total = 6 + length
                if len(buf) >= total:
                    frame = bytes(buf[:total])
                    del buf[:total]
                    return frame
            left = deadline - time.monotonic()
            if left <= 0 or s is None:
                return None
            try:
                s.settimeout(left)
                data = s.recv(4096)
            except TimeoutError:
                return None
            except OSError as e:
                self.close()
                raise ConnectionException(f"Modbus TCP {self.host}:{self.port}: {e}") from e
            if not data:
                self.close()
                raise ConnectionException(f"Modbus TCP {self.host}:{self.port}: connection "
                                          "closed by the module")
            buf += data
