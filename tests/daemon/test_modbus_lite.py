"""The small Modbus TCP client the ADC driver uses live (drivers/modbus_adc/tcplite.py):
the cases the module emulator does not produce - a late answer to a request that timed
out, a garbled header - against a scripted server on loopback."""

from __future__ import annotations

import socket
import struct
import threading
from collections.abc import Callable, Iterator

import pytest
from pymodbus.exceptions import ModbusIOException

from drivers.modbus_adc.tcplite import ModbusTcpLite

Handler = Callable[[socket.socket, int, int, int, int, int], None]


def answer(conn: socket.socket, tid: int, unit: int, fc: int, words: list[int]) -> None:
    pdu = struct.pack(f">BB{len(words)}H", fc, 2 * len(words), *words)
    conn.sendall(struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu)


@pytest.fixture
def server() -> Iterator[Callable[[Handler], int]]:
    """``start(handler)`` -> port; ``handler(conn, tid, unit, fc, address, count)`` per request."""
    socks: list[socket.socket] = []

    def start(handler: Handler) -> int:
        srv = socket.socket()
        srv.bind(("127.0.0.1", 0))
        srv.listen()
        socks.append(srv)

        def serve() -> None:
            while True:
                try:
                    conn, _ = srv.accept()
                except OSError:
                    return
                socks.append(conn)
                buf = b""
                while True:
                    try:
                        data = conn.recv(4096)
                    except OSError:
                        break
                    if not data:
                        break
                    buf += data
                    while len(buf) >= 12:
                        tid, _, _, unit, fc, addr, count = struct.unpack(">HHHBBHH", buf[:12])
                        buf = buf[12:]
                        handler(conn, tid, unit, fc, addr, count)
        threading.Thread(target=serve, daemon=True).start()
        return int(srv.getsockname()[1])

    yield start
    for s in socks:
        s.close()


def test_reads_and_exception_answers(server: Callable[[Handler], int]) -> None:
    def handler(conn: socket.socket, tid: int, unit: int, fc: int, addr: int, count: int
                ) -> None:
        if addr == 99:
            conn.sendall(struct.pack(">HHHBBB", tid, 0, 3, unit, fc | 0x80, 2))
        else:
            answer(conn, tid, unit, fc, [addr + k for k in range(count)])

    c = ModbusTcpLite("127.0.0.1", server(handler), timeout=1.0)
    assert not c.connected and c.connect() and c.connected
    r = c.read_input_registers(10, count=3, device_id=2)
    assert not r.isError() and r.registers == [10, 11, 12]
    assert c.read_holding_registers(0, count=1).registers == [0]
    e = c.read_input_registers(99, count=2)
    assert e.isError() and e.exception_code == 2
    c.close()
    assert not c.connected


def test_a_late_answer_is_not_taken_for_the_next_request(server: Callable[[Handler], int]
                                                         ) -> None:
    held: list[tuple[int, int, int, int]] = []

    def handler(conn: socket.socket, tid: int, unit: int, fc: int, addr: int, count: int
                ) -> None:
        if not held:  # the first request: answered only after the client gave up on it
            held.append((tid, unit, fc, addr))
            return
        answer(conn, *held[0][:3], [held[0][3]])  # the late answer comes first
        answer(conn, tid, unit, fc, [addr])

    c = ModbusTcpLite("127.0.0.1", server(handler), timeout=0.1)
    assert c.connect()
    with pytest.raises(ModbusIOException):
        c.read_input_registers(1)
    c.timeout = 2.0
    assert c.read_input_registers(2).registers == [2]


def test_retries_resend_after_a_timeout(server: Callable[[Handler], int]) -> None:
    n = [0]

    def handler(conn: socket.socket, tid: int, unit: int, fc: int, addr: int, count: int
                ) -> None:
        n[0] += 1
        if n[0] > 1:  # the first request is lost
            answer(conn, tid, unit, fc, [7])

    c = ModbusTcpLite("127.0.0.1", server(handler), timeout=0.1, retries=1)
    assert c.connect()
    assert c.read_input_registers(0).registers == [7] and n[0] == 2


def test_a_garbled_header_drops_the_connection(server: Callable[[Handler], int]) -> None:
    n = [0]

    def handler(conn: socket.socket, tid: int, unit: int, fc: int, addr: int, count: int
                ) -> None:
        n[0] += 1
        if n[0] == 1:
            conn.sendall(b"\x00\x01\x12\x34\x00\x05garbage")  # protocol id not 0
        else:
            answer(conn, tid, unit, fc, [5])

    c = ModbusTcpLite("127.0.0.1", server(handler), timeout=0.5)
    assert c.connect()
    with pytest.raises(ModbusIOException):
        c.read_input_registers(0)
    assert not c.connected
    assert c.connect() and c.read_input_registers(0).registers == [5]


def test_connection_refused() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, not listening: refused
        assert not ModbusTcpLite("127.0.0.1", port, timeout=0.2).connect()
