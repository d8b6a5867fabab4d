"""Register reads on a pymodbus TCP client, through its framer and its socket only.

``ModbusTcpClient.read_input_registers`` goes through the client mixin, the transaction
manager (lock, retries, packet and PDU trace hooks, debug-log calls) and a receive loop
that switches the socket to non-blocking and selects on it, for every poll. The
daemon's two modules are polled 50 times a second each, on a thread that wakes for
each poll: that path was most of their threads' CPU (each about 1 % of a core at 100
Hz, docs/daemon.md). :class:`TcpRegisterReads` does the same exchange with the same
pymodbus pieces - the request PDU's encoding, the client's framer (MBAP header,
transaction and unit checks, the decoder with the driver's strict register responses)
and the client's socket - and nothing else: 30 against 43 us of CPU per read on this
machine, back to back (more on a cold thread).

What a read gives is what the client's own read gives: the decoded response PDU (a
register response, or an exception response whose ``isError()`` is true); a late answer
to an earlier request is skipped by its transaction id, as the client skips it; no
answer within ``timeout_s`` raises :class:`TimeoutError` after ``retries`` resends; a
connection the module closed or that fails closes the client (``connected`` false, so
the driver reconnects) and raises :class:`ConnectionError` / the :class:`OSError`.
"""

from __future__ import annotations

import time
from typing import Any


class TcpRegisterReads:
    """``reads(address, count)``: one register read on ``client`` (a connected
    ``pymodbus.client.ModbusTcpClient``) of function ``function_code`` (3 or 4)."""

    def __init__(self, client: Any, unit: int, function_code: int, timeout_s: float,
                 retries: int = 0) -> None:
        from pymodbus.pdu.register_message import (
            ReadHoldingRegistersRequest,
            ReadInputRegistersRequest,
        )

        self.client = client
        self.unit = unit
        self.timeout_s = timeout_s
        self.retries = retries
        self._request = (ReadInputRegistersRequest if function_code == 4
                         else ReadHoldingRegistersRequest)
        self._pdus: dict[tuple[int, int], bytes] = {}
        self._tid = 0

    def _pdu(self, address: int, count: int) -> bytes:
        """The request PDU's bytes (function code and data), as the client sends them."""
        key = (address, count)
        pdu = self._pdus.get(key)
        if pdu is None:
            req = self._request(address=address, count=count, dev_id=self.unit)
            pdu = self._pdus[key] = req.function_code.to_bytes(1, "big") + req.encode()
        return pdu

    def __call__(self, address: int, count: int) -> Any:
        client = self.client
        sock = client.socket
        if sock is None:
            raise ConnectionError("Modbus TCP client not connected")
        framer, unit, pdu = client.framer, self.unit, self._pdu(address, count)
        for attempt in range(self.retries + 1):
            # the client's numbering: 1 .. 65000, then 1 again
            tid = self._tid = 1 if self._tid >= 65000 else self._tid + 1
            try:
                sock.sendall(framer.encode(pdu, unit, tid))
                deadline = time.monotonic() + self.timeout_s
                buf = b""
                while True:
                    left = deadline - time.monotonic()
                    if left <= 0:
                        raise TimeoutError(f"no answer within {self.timeout_s:g} s")
                    sock.settimeout(left)
                    data = sock.recv(1024)  # socket.timeout is a TimeoutError
                    if not data:
                        raise ConnectionError("the Modbus module closed the connection")
                    buf += data
                    used, response = framer.handleFrame(buf, unit, tid)
                    if response is not None:
                        return response
                    buf = buf[used:]
            except TimeoutError:
                if attempt == self.retries:
                    raise
            except OSError:
                client.close()
                raise
        raise AssertionError("unreachable")  # pragma: no cover
