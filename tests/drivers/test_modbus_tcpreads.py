"""TcpRegisterReads against a real pymodbus server: what the client's own read gives."""

from __future__ import annotations

import time
from typing import Any

import pytest

from drivers.modbus_adc import ModbusAdcConfig, ModbusAdcDriver
from drivers.modbus_adc.server import RegisterServer
from drivers.modbus_adc.strict import strict_registers
from drivers.modbus_adc.tcpreads import TcpRegisterReads


def _client(port: int, timeout: float = 0.2) -> Any:
    from pymodbus.client import ModbusTcpClient

    c = strict_registers(ModbusTcpClient("127.0.0.1", port=port, timeout=timeout, retries=0))
    assert c.connect()
    return c


def _outcome(r: Any) -> tuple[Any, ...]:
    return (type(r).__name__, r.isError(), getattr(r, "exception_code", None),
            list(getattr(r, "registers", []) or []), r.function_code, r.dev_id)


@pytest.mark.parametrize("fc", [3, 4])
def test_answers_and_exceptions_as_the_clients_own_read(fc: int) -> None:
    answers: dict[int, Any] = {0: [1, 65535, 32768, 7], 10: 2, 20: 4}
    with RegisterServer(lambda f, a, c: answers[a][:c] if isinstance(answers[a], list)
                        else answers[a]) as srv:
        c = _client(srv.port)
        reads = TcpRegisterReads(c, 1, fc, 0.2)
        own = c.read_input_registers if fc == 4 else c.read_holding_registers
        for address, count in ((0, 4), (0, 2), (10, 1), (20, 3), (0, 4)):
            assert _outcome(reads(address, count)) == _outcome(
                own(address, count=count, device_id=1))
        c.close()


def test_a_late_answer_is_not_taken_for_the_next_one() -> None:
    """The module answers the first request after the timeout: that answer, arriving
    while the next request waits, is skipped by its transaction id."""
    calls = {"n": 0}

    def slow_first(f: int, a: int, c: int) -> list[int]:
        calls["n"] += 1
        if calls["n"] == 1:
            time.sleep(0.3)
        return [calls["n"]] * c

    with RegisterServer(slow_first) as srv:
        c = _client(srv.port, timeout=0.1)
        reads = TcpRegisterReads(c, 1, 4, 0.1)
        with pytest.raises(TimeoutError):
            reads(0, 2)
        time.sleep(0.35)  # the late answer (1, 1) is in the socket now
        assert list(reads(0, 2).registers) == [2, 2]
        c.close()


def test_silence_times_out_after_the_retries_then_answers_again() -> None:
    with RegisterServer(lambda f, a, c: [5] * c) as srv:
        c = _client(srv.port, timeout=0.05)
        reads = TcpRegisterReads(c, 1, 4, 0.05, retries=2)
        srv.silent = True
        t0 = time.monotonic()
        with pytest.raises(TimeoutError):
            reads(0, 1)
        assert time.monotonic() - t0 >= 0.15  # three tries of 50 ms
        assert srv.requests >= 3
        srv.silent = False
        time.sleep(0.05)
        assert list(reads(0, 1).registers) == [5]
        c.close()


def test_a_closed_connection_closes_the_client() -> None:
    srv = RegisterServer(lambda f, a, c: [1] * c).start()
    c = _client(srv.port)
    reads = TcpRegisterReads(c, 1, 4, 0.2)
    assert list(reads(0, 1).registers) == [1]
    srv.stop()
    with pytest.raises(OSError):
        for _ in range(3):  # the first send may still be accepted by the kernel
            reads(0, 1)
    assert not c.connected
    with pytest.raises(ConnectionError):
        reads(0, 1)


def test_the_driver_reads_its_tcp_client_this_way_and_others_their_own_way() -> None:
    with RegisterServer(lambda f, a, c: [100] * c) as srv:
        cfg = ModbusAdcConfig.from_config(
            {"kind": "modbus_tcp", "host": "127.0.0.1", "port": srv.port,
             "channels": [{"name": "hoist1_a", "register": 0, "scale": 400.0}]})
        d = ModbusAdcDriver("adc", cfg)
        d.open()
        assert d._reads is not None
        got: list[Any] = []
        d.poll(got.append)
        assert got[0].values["hoist1_a"] == pytest.approx(cfg.channels["hoist1_a"].from_word(100))
        d.close()
        own = ModbusAdcDriver("adc", cfg, client_factory=lambda c: _client(srv.port))
        own.open()
        assert own._reads is None  # a client of its own: its read methods
        own.close()
