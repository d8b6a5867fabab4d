"""Modbus ADC: channel map, and the driver against a real pymodbus server (TCP and RTU)."""

from __future__ import annotations

import logging
import socket
import struct
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.base import DeviceError
from drivers.capture.format import RegisterRead
from drivers.modbus_adc import Channel, ChannelMap, ModbusAdcConfig, ModbusAdcDriver
from drivers.modbus_adc.server import RegisterServer
from hil_fixtures.fault_drill import wrong_protocol
from hil_fixtures.modbus_adc import ModbusAdcEmulator, source_from_table
from hil_fixtures.virtual_shovel import MOTOR_CHANNELS, DriverRunner
from shoveld.signals import SignalsTable

CHANNELS = ChannelMap.from_config([
    {"name": "hoist1_a", "register": 0, "scale": 400.0},
    {"name": "crowd_a", "register": 1, "scale": 400.0, "offset": 5.0},
    {"name": "boom_deg", "register": 3, "raw_min": 0, "raw_max": 65535, "scale": 4.5,
     "offset": 45.0},
])
VALUES = {"hoist1_a": 2345.6, "crowd_a": -1234.5, "boom_deg": 41.25}


# --------------------------------------------------------------------------- channel map


def test_hall_transducer_scaling() -> None:
    ch = Channel("hoist1_a", 0, scale=400.0)  # 4000 A over +-10 V
    assert ch.from_raw(32767) == pytest.approx(4000.0)
    assert ch.from_raw(-32768) == pytest.approx(-4000.0, abs=0.07)
    assert ch.to_raw(0.0) in (-1, 0)
    assert ch.word_to_raw(0xFFFF) == -1 and ch.raw_to_word(-1) == 0xFFFF
    assert ch.resolution == pytest.approx(8000 / 65535)


@given(st.sampled_from(list(CHANNELS) + list(MOTOR_CHANNELS)),
       st.floats(-1.0, 1.0))
def test_to_raw_from_raw_round_trip_within_one_count(ch: Channel, frac: float) -> None:
    lo, hi = ch.from_raw(ch.raw_min), ch.from_raw(ch.raw_max)
    value = lo + (hi - lo) * (frac + 1) / 2
    back = ch.from_word(ch.to_word(value))
    assert back == pytest.approx(value, abs=ch.resolution)


def test_out_of_range_saturates() -> None:
    ch = CHANNELS["hoist1_a"]
    assert ch.to_raw(1e6) == 32767 and ch.saturated(ch.to_raw(1e6))
    assert ch.to_raw(-1e6) == -32768


def test_blocks_merge_neighbours_and_split_far_registers() -> None:
    assert [(a, n) for a, n, _ in CHANNELS.blocks()] == [(0, 4)]
    far = ChannelMap.from_config([{"name": "hoist1_a", "register": 0},
                                  {"name": "roll_deg", "register": 100}])
    assert [(a, n) for a, n, _ in far.blocks()] == [(0, 1), (100, 1)]
    assert [(a, n) for a, n, _ in far.blocks(max_gap=99)] == [(0, 101)]


def test_encode_decode_are_inverse() -> None:
    words = CHANNELS.encode(VALUES, 0, 4)
    assert words[2] == 0  # unused register keeps the fill
    got = CHANNELS.decode(0, words)
    for k, v in VALUES.items():
        assert got[k] == pytest.approx(v, abs=CHANNELS[k].resolution)


@pytest.mark.parametrize("items, text", [
    ([], "non-empty list"),
    ({"name": "hoist1_a"}, "non-empty list"),
    ([{"name": "hoist3_a", "register": 0}], "channels[0].name"),
    ([{"name": "hoist1_a"}], "register is required"),
    ([{"name": "hoist1_a", "register": 0, "gain": 2}], "unknown key 'gain'"),
    ([{"name": "hoist1_a", "register": 0, "scale": "400"}], "scale must be a finite number"),
    ([{"name": "hoist1_a", "register": 0, "scale": 0}], "scale must not be zero"),
    ([{"name": "hoist1_a", "register": 0, "raw_min": -5, "raw_max": 65535}], "raw_min/raw_max"),
    ([{"name": "hoist1_a", "register": 0, "volts_min": 10, "volts_max": -10}], "volts_min"),
    ([{"name": "hoist1_a", "register": 0}, {"name": "hoist1_a", "register": 1}], "used twice"),
    ([{"name": "hoist1_a", "register": 0}, {"name": "hoist2_a", "register": 0}], "used twice"),
])
def test_channel_map_errors_name_the_entry(items: object, text: str) -> None:
    with pytest.raises(ValueError) as e:
        ChannelMap.from_config(items)  # type: ignore[arg-type]
    assert text in str(e.value)


@pytest.mark.parametrize("cfg, key", [
    ({"kind": "modbus_tcp", "channels": CHANNELS.to_config()}, "host"),
    ({"kind": "modbus_tcp", "host": "h", "port": 0, "channels": CHANNELS.to_config()}, "port"),
    ({"kind": "modbus_tcp", "host": "h"}, "channels"),
    ({"kind": "modbus_tcp", "host": "h", "baudrate": 9600,
      "channels": CHANNELS.to_config()}, "baudrate"),
    ({"kind": "modbus_rtu", "channels": CHANNELS.to_config()}, "port"),
    ({"kind": "modbus_rtu", "port": "/dev/x", "parity": "X",
      "channels": CHANNELS.to_config()}, "parity"),
    ({"kind": "modbus_tcp", "host": "h", "poll_hz": 0, "channels": CHANNELS.to_config()},
     "poll_hz"),
    ({"kind": "modbus_tcp", "host": "h", "function": "coil",
      "channels": CHANNELS.to_config()}, "function"),
    ({"kind": "modbus_tcp", "host": "h", "unit": "1", "channels": CHANNELS.to_config()},
     "unit"),
    ({"kind": "modbus", "host": "h", "channels": CHANNELS.to_config()}, "kind"),
])
def test_driver_config_errors_name_the_key(cfg: dict[str, object], key: str) -> None:
    with pytest.raises(ValueError, match=f"'{key}'"):
        ModbusAdcConfig.from_config(cfg)


def test_config_round_trips() -> None:
    cfg = ModbusAdcConfig.from_config({"kind": "modbus_rtu", "port": "/dev/ttyUSB0",
                                       "baudrate": 38400, "parity": "E",
                                       "channels": CHANNELS.to_config()})
    assert ModbusAdcConfig.from_config(cfg.to_config()) == cfg


# --------------------------------------------------------------------------- driver


def client_errors(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    """pymodbus's warnings and errors from the driver's client, not from the emulator's
    server (its threads are ``modbus-tcp-server`` and ``modbus-rtu-server``)."""
    return [r for r in caplog.records if r.name.startswith("pymodbus")
            and r.levelno >= logging.WARNING and not (r.threadName or "").startswith("modbus-")]


def fast(emu: ModbusAdcEmulator, **kw: object) -> ModbusAdcDriver:
    cfg = emu.driver_config(poll_hz=100, timeout_s=0.05, stale_after_s=0.2, **kw)
    return ModbusAdcDriver.from_config("adc", cfg, backoff_s=(0.05, 0.2))


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_values_through_the_channel_map(transport: str) -> None:
    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS, transport=transport) as emu, \
            DriverRunner(fast(emu)) as run:
        assert run.wait_for(lambda: len(run.readings) >= 10, 5)
        r = run.readings[-1]
        assert not r.invalid
        for k, v in VALUES.items():
            assert r.values[k] == pytest.approx(v, abs=CHANNELS[k].resolution)
        chans = run.driver.health.extra["channels"]
        assert all(c["state"] == "ok" and not c["stale"] for c in chans.values())


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_module_that_stops_answering(transport: str) -> None:
    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS, transport=transport) as emu, \
            DriverRunner(fast(emu, reconnect_after=1000)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 5, 5)
        emu.silent = True
        assert run.wait_for(lambda: h.timeouts >= 5, 5)
        chans = h.extra["channels"]
        assert run.wait_for(lambda: all(c["stale"] for c in chans.values()), 2)
        for name in CHANNELS.names:
            assert chans[name]["state"] == "timeout" and chans[name]["timeouts"] >= 5
            assert "no answer" in chans[name]["last_error"]
        dead = run.readings[-3:]
        # the old values are not repeated and nothing became zero
        assert all(r.values == {} and r.invalid == set(CHANNELS.names) for r in dead)
        n = len(run.readings)
        emu.silent = False
        assert run.wait_for(lambda: len(run.readings) > n + 3 and not run.readings[-1].invalid,
                            5)
        assert all(c["state"] == "ok" and not c["stale"] for c in chans.values())


def _noise(answer: bytes) -> bytes:
    """An RTU answer with one bit flipped on the line, in its first register."""
    return answer[:4] + bytes([answer[4] ^ 0x10]) + answer[5:]


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_a_module_that_babbles_is_named_in_health(transport: str,
                                                  caplog: pytest.LogCaptureFixture) -> None:
    """Answers that are not Modbus are bad frames and set ``babbling``, which health's
    problems name; until 2026-11-30 the driver saw only timeouts and said "not
    answering" of a module that answers garbage, while pymodbus wrote an ERROR line per
    answer over TCP."""
    from shoveld.daemon.health import problems

    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS, transport=transport) as emu, \
            DriverRunner(fast(emu, reconnect_after=1000)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 5, 5)
        assert h.bad_frames == 0 and not h.extra["babbling"]
        emu.server.garble = wrong_protocol if transport == "tcp" else _noise
        with caplog.at_level(logging.DEBUG):
            assert run.wait_for(lambda: h.bad_frames >= 5 and h.extra["babbling"], 5)
        what = "not Modbus TCP (protocol id 4660)" if transport == "tcp" else "CRC is wrong"
        chans = h.extra["channels"]
        assert all(what in c["last_error"] and c["state"] == "timeout"
                   for c in chans.values()), chans
        assert h.last_error is not None and what in h.last_error
        assert "adc: babbling (malformed data)" in problems(
            {"adc": {"state": "invalid", **h.extra}}, {}, {"open": True}, {})
        assert not client_errors(caplog), caplog.text
        said = [r for r in caplog.records if "babbling" in r.getMessage()]
        assert len(said) == 1 and said[0].levelno == logging.WARNING, caplog.text  # once
        n = len(run.readings)
        assert isinstance(run.driver, ModbusAdcDriver)
        run.driver.fault_hold_s = 0.3
        emu.server.garble = None
        assert run.wait_for(lambda: len(run.readings) > n + 3 and not run.readings[-1].invalid,
                            5)
        assert run.wait_for(lambda: not h.extra["babbling"], 2)


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_a_module_that_answers_after_the_timeout_is_named_in_health(
        transport: str, caplog: pytest.LogCaptureFixture) -> None:
    """A module whose answers come after the driver's timeout. Over TCP each lands in a
    later request's wait, where its transaction id shows it late; until 2026-11-30 the
    channels were only "not answering" now and then, and pymodbus wrote an ERROR line
    with a dump of twenty frames for each. Over RTU an answer says nothing of which
    request it answers: until 2026-12-02 each was taken as a later request's, its values
    published as new (answers to requests sent 0.3 s before here) and health said
    nothing; now the line is watched after a timeout, the late answer is counted, and the
    channels are invalid while the fault lasts. Either way it is counted and health says
    so, once."""
    from shoveld.daemon.health import problems

    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS, transport=transport) as emu, \
            DriverRunner(fast(emu, reconnect_after=1000)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 5, 5)
        assert not h.extra["answering_late"]
        emu.server.delay_s = 0.3  # the driver's timeout is 0.05 s
        with caplog.at_level(logging.DEBUG):
            # an answer is counted late only when it lands in a later request's wait;
            # on a loaded machine fewer do (at 5 s, 3 of 8 runs had fewer than three
            # beside three busy processes on two cores, 2026-11-30)
            assert run.wait_for(lambda: h.extra["late_answers"] >= 3, 20), h.extra
        assert h.extra["answering_late"] and h.last_error is not None \
            and "answers after the 0.05 s timeout" in h.last_error
        said = problems({"adc": {"state": "ok", **h.extra}}, {}, {"open": True}, {})
        assert [p for p in said if p.startswith("adc: answering after its timeout (")], said
        assert not client_errors(caplog), caplog.text
        warned = [r for r in caplog.records if "answering late" in r.getMessage()]
        assert len(warned) == 1, caplog.text  # once, not once a poll
        if transport == "rtu":
            # no answer is taken while the module is late: every reading since is
            # invalid, and the channels say why
            n = len(run.readings)
            assert run.wait_for(lambda: len(run.readings) >= n + 5, 10)
            assert all(r.invalid == set(VALUES) and not r.values
                       for r in run.readings[n:]), run.readings[n:]
            assert all(c["state"] in ("late", "timeout")
                       for c in h.extra["channels"].values()), h.extra["channels"]
        assert isinstance(run.driver, ModbusAdcDriver)
        run.driver.fault_hold_s = 0.3
        emu.server.delay_s = 0.0
        assert run.wait_for(lambda: not h.extra["answering_late"], 3)
        n = len(run.readings)
        assert run.wait_for(lambda: len(run.readings) > n + 3 and not run.readings[-1].invalid,
                            5)


def test_pymodbus_repeating_a_line_the_driver_says_itself_is_not_logged() -> None:
    """pymodbus writes "Repeating...." in place of an ERROR line it wrote just before,
    with its dump of the frames sent and received since when there were any; the repeat
    of a line the driver says itself (an unanswered request) is dropped with it, dump or
    not. Until 2026-12-02 the repeat with a dump went to the journal (seen in the fault
    drill over RTU: "Repeating...." and four ">>>>> recv/send" lines)."""
    from drivers.modbus_adc.driver import _SaidByTheDriver

    def record(text: str) -> logging.LogRecord:
        return logging.LogRecord("pymodbus.logging", logging.ERROR, __file__, 1, text,
                                 None, None)

    said = _SaidByTheDriver()
    dump = "\n>>>>> recv: 0x2 0x4 0x0 0x0 0x0 0x3 0xb0 0x38 extra data: "
    assert not said.filter(record("No response received after 0 retries, continue" + dump))
    assert not said.filter(record("Repeating...." + dump))
    assert not said.filter(record("Repeating...."))
    # a line the driver does not say, and its repeat, pass
    assert said.filter(record("Unable to decode frame" + dump))
    assert said.filter(record("Repeating...." + dump))


def test_an_answer_to_a_client_that_left_is_not_an_error_in_the_log(
        caplog: pytest.LogCaptureFixture) -> None:
    """A late answer whose client has gone (it timed out and reconnected): pymodbus's
    server wrote an ERROR line with a frame dump ("Cancel send, because not connected!"),
    seen in the fault drill's output; the module, and so the emulator, says nothing."""
    srv = RegisterServer(lambda fc, a, c: [1] * c).start()
    try:
        srv.delay_s = 0.2
        with caplog.at_level(logging.DEBUG), \
                socket.create_connection(("127.0.0.1", srv.port)) as s:
            s.sendall(struct.pack(">HHHBBHH", 1, 0, 6, 1, 4, 0, 2))  # read 2 input regs
            end = time.monotonic() + 5.0
            while srv.requests < 1 and time.monotonic() < end:
                time.sleep(0.005)
        with caplog.at_level(logging.DEBUG):
            time.sleep(0.4)  # the answer is due after the client closed
    finally:
        srv.stop()
    assert srv.requests == 1
    assert not [r for r in caplog.records if r.name.startswith("pymodbus")
                and r.levelno >= logging.WARNING], caplog.text


def test_exception_responses_reported_per_channel() -> None:
    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS) as emu, DriverRunner(fast(emu)) as run:
        assert run.wait_for(lambda: len(run.readings) >= 3, 5)
        emu.exception_code = 4
        h = run.driver.health
        assert run.wait_for(lambda: h.extra["exceptions"] >= 3, 5)
        c = h.extra["channels"]["hoist1_a"]
        assert c["state"] == "exception" and c["last_error"] == "Modbus exception code 4"
        assert run.readings[-1].values == {}
        assert h.reconnects == 0  # the module answered: no reason to reconnect


def test_dead_module_leads_to_reconnect_and_recovery() -> None:
    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS) as emu, \
            DriverRunner(fast(emu, reconnect_after=3)) as run:
        h = run.driver.health
        assert run.wait_for(lambda: len(run.readings) >= 3, 5)
        emu.silent = True
        assert run.wait_for(lambda: "answered none of the last 3 polls" in (h.last_error or ""),
                            5)
        emu.silent = False
        assert run.wait_for(lambda: h.reconnects >= 1 and h.connected
                            and not run.readings[-1].invalid, 5)


@pytest.mark.parametrize("transport", ["tcp", "rtu"])
def test_a_module_powered_off_and_on_is_said_by_the_driver_alone(
        transport: str, caplog: pytest.LogCaptureFixture) -> None:
    """A module powered off (its server gone: connections refused) and on again on the
    same port: the driver says it cannot connect and reconnects; pymodbus's own ERROR
    lines for the same, each with a dump of twenty frames, are not in the log (until
    2026-11-30 one came at every retry)."""
    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS, transport=transport) as emu:
        if transport == "rtu":  # a USB adapter pulled: its port vanishes
            emu.stop()
            drv = fast(emu)
            with caplog.at_level(logging.DEBUG):
                with pytest.raises(DeviceError, match="cannot connect to Modbus module at"):
                    drv.open()
            emu.start()
        else:
            with DriverRunner(fast(emu, reconnect_after=3)) as run:
                h = run.driver.health
                assert run.wait_for(lambda: len(run.readings) >= 3, 5)
                with caplog.at_level(logging.DEBUG):
                    emu.stop()
                    assert run.wait_for(lambda: "cannot connect to Modbus module at" in
                                        (h.last_error or ""), 5), h.last_error
                    emu.start()
                    n = h.reconnects
                    assert run.wait_for(lambda: h.reconnects > n and h.connected
                                        and not run.readings[-1].invalid, 5)
    assert not client_errors(caplog), caplog.text


def test_a_module_that_takes_the_link_and_never_answers_is_retried_less_and_less(
        caplog: pytest.LogCaptureFixture) -> None:
    """A module (or a TCP gateway whose serial side is dead) that accepts the connection
    and answers no poll: each open succeeds, so until 2026-11-30 the back-off started
    again at every open and the driver reconnected every 0.2 s for ever, two log lines
    each. The back-off now starts again only after a link that gave a measurement: it
    doubles up to its ceiling; once the module answers, the next fault starts from the
    floor again."""
    import logging
    import re

    def delays() -> list[float]:
        return [float(m.group(1)) for r in caplog.records
                if (m := re.search(r"retrying in ([0-9.]+) s", r.getMessage()))]

    with caplog.at_level(logging.ERROR, logger="drivers.base"), \
            ModbusAdcEmulator(lambda t: VALUES, CHANNELS) as emu:
        emu.silent = True
        drv = ModbusAdcDriver.from_config(
            "adc", emu.driver_config(poll_hz=100, timeout_s=0.05, reconnect_after=3),
            backoff_s=(0.1, 0.8))
        with DriverRunner(drv) as run:
            assert run.wait_for(lambda: len(delays()) >= 5, 10)
            assert delays()[:5] == [0.1, 0.2, 0.4, 0.8, 0.8], delays()
            assert drv.health.reconnects >= 4 and not any(r.values for r in run.readings)
            emu.silent = False
            assert run.wait_for(lambda: bool(run.readings and run.readings[-1].values), 10)
            n = len(delays())
            emu.silent = True
            assert run.wait_for(lambda: len(delays()) > n, 10)
            assert delays()[n] == 0.1, delays()


def test_connection_refused_is_a_clear_error() -> None:
    from drivers.base import DeviceError

    cfg = {"kind": "modbus_tcp", "host": "127.0.0.1", "port": 1, "timeout_s": 0.2,
           "channels": CHANNELS.to_config()}
    drv = ModbusAdcDriver.from_config("adc", cfg)
    with pytest.raises(DeviceError, match="cannot connect to Modbus module at 127.0.0.1:1"):
        drv.open()


def test_register_log_sees_every_read() -> None:
    log: list[RegisterRead] = []
    with ModbusAdcEmulator(lambda t: VALUES, CHANNELS) as emu:
        drv = fast(emu)
        drv.register_log = log.append
        with DriverRunner(drv) as run:
            assert run.wait_for(lambda: len(log) >= 3, 5)
            emu.silent = True
            assert run.wait_for(lambda: any(r.error == "timeout" for r in log), 5)
    ok = [r for r in log if r.registers is not None]
    assert ok[0].function == 4 and ok[0].address == 0 and ok[0].count == 4
    assert ok[0].registers is not None
    assert CHANNELS.decode(0, ok[0].registers)["hoist1_a"] == pytest.approx(2345.6, abs=0.2)


def test_holding_registers_and_table_source() -> None:
    table = SignalsTable.from_arrays(time_s=[0.0, 100.0], hoist1_a=[1000.0, 2000.0],
                                     crowd_a=[0.0, 0.0], boom_deg=[45.0, 45.0])
    src = source_from_table(table, CHANNELS)
    assert src(50.0)["hoist1_a"] == pytest.approx(1500.0)
    with ModbusAdcEmulator(src, CHANNELS) as emu, \
            DriverRunner(fast(emu, function="holding")) as run:
        assert run.wait_for(lambda: len(run.readings) >= 3, 5)
        assert 1000.0 <= run.readings[-1].values["hoist1_a"] <= 1100.0


@pytest.mark.parametrize("reply", ["holding", "short", "long"])
def test_an_answer_to_another_question_is_a_bad_frame(reply: str) -> None:
    """A reply whose function code or length is not the request's carries no values."""
    from pymodbus.pdu.register_message import (
        ReadHoldingRegistersResponse,
        ReadInputRegistersResponse,
    )

    class Client:
        connected = True

        def read_input_registers(self, address: int, count: int, device_id: int) -> object:
            if reply == "holding":
                return ReadHoldingRegistersResponse(registers=[1000] * count)
            return ReadInputRegistersResponse(
                registers=[1000] * (count - 1 if reply == "short" else count + 1))

        def connect(self) -> bool:
            return True

        def close(self) -> None:
            pass

    cfg = ModbusAdcConfig.from_config({"kind": "modbus_tcp", "host": "127.0.0.1", "port": 1502,
                                       "function": "input", "channels": CHANNELS.to_config()})
    drv = ModbusAdcDriver("adc", cfg, client_factory=lambda c: Client())
    drv.open()
    r = drv.poll(lambda _: None)
    assert r.values == {} and r.invalid == {c.name for c in CHANNELS}  # no value taken
    assert drv.health.bad_frames >= 1
    assert "another function code" in drv.health.extra["channels"]["hoist1_a"]["last_error"]


def test_an_odd_byte_count_is_refused_by_the_drivers_decoder() -> None:
    """pymodbus alone rounds an odd byte count down; the driver's client refuses it."""
    from pymodbus.pdu import DecodePDU

    from drivers.modbus_adc.strict import strict_registers

    assert DecodePDU(False).decode(bytes([4, 3, 0, 1, 0])) is not None
    assert strict_registers(DecodePDU(False)).decode(bytes([4, 3, 0, 1, 0])) is None
    assert strict_registers(DecodePDU(False)).decode(bytes([3, 3, 0, 1, 0])) is None
    assert strict_registers(DecodePDU(False)).decode(bytes([4, 2, 0, 1])).registers == [1]
    client = ModbusAdcDriver("adc", ModbusAdcConfig.from_config(
        {"kind": "modbus_tcp", "host": "127.0.0.1", "port": 1502,
         "channels": CHANNELS.to_config()}))._make_client()
    assert client.framer.decoder.decode(bytes([4, 3, 0, 1, 0])) is None  # the real client
