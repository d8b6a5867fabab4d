"""MtiSerialDriver against MtiEmulator over a real pseudo-terminal.

Covers the configuration sequence, values against their source in every precision,
quaternion output, a signals-table source through the installation geometry, noise and
corruption, dropped packets, Error messages, a device restart, unplug/replug and a
silent device with reconnect back-off, and the wrong-baud-rate message.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from drivers.base import DeviceError, Reading
from drivers.xsens.mtdata2 import FP1632, MAX_FREQUENCY, NED, XDI
from drivers.xsens.orientation import gravity_in_sensor
from drivers.xsens.serial_driver import EXTRA_OUTPUTS, MtiSerialDriver
from drivers.xsens.xbus import MID
from hil_fixtures.mti import MtiEmulator, angles_from_signals
from shoveld.installation import Installation, wrap_deg
from shoveld.signals import SignalsTable

from .conftest import collect, t_device, wait_for


def source(t: float) -> tuple[float, float, float]:
    """A swinging, hoisting saddle block: smooth and crossing the yaw wrap."""
    return (0.5 * math.sin(0.7 * t), 20.0 * math.sin(1.3 * t) - 5.0, wrap_deg(170.0 + 40.0 * t))


@pytest.fixture
def emu() -> Iterator[MtiEmulator]:
    with MtiEmulator(source, send_wakeup=False) as e:
        yield e


def make_driver(port: str, **kw: object) -> MtiSerialDriver:
    args: dict[str, object] = {"port": port, "command_timeout_s": 0.4, "data_timeout_s": 0.3,
                               "backoff_s": (0.05, 0.2)}
    args.update(kw)
    return MtiSerialDriver.from_config(args)


def ang_err(a: float, b: float) -> float:
    return abs(wrap_deg(a - b))


def test_configuration_sequence_and_identity(emu: MtiEmulator) -> None:
    drv = make_driver(emu.port)
    drv.open()
    try:
        assert [m for m in emu.commands() if m != MID.WAKEUP_ACK] == [
            MID.GOTO_CONFIG, MID.REQ_DID, MID.REQ_FW_REV, MID.SET_OUTPUT_CONFIGURATION,
            MID.GOTO_MEASUREMENT]
        assert emu.state == "measurement"
        assert sorted(emu.outputs) == sorted(drv.requested_outputs())
        assert dict(emu.outputs)[XDI.EULER_ANGLES] == 100
        assert dict(emu.outputs)[XDI.PACKET_COUNTER] == MAX_FREQUENCY
        # by default the orientation (twice, to check one by the other) and its clock
        assert sorted(x & 0xFFF0 for x, _ in emu.outputs) == sorted(
            [XDI.PACKET_COUNTER, XDI.SAMPLE_TIME_FINE, XDI.EULER_ANGLES, XDI.QUATERNION])
        # the identifiers its frames are checked against: those it acknowledged
        assert drv._ids == frozenset(x for x, _ in emu.outputs)
        assert drv.health.extra["device_id"] == "06301234"
        assert drv.health.extra["firmware"] == "1.8.2 build 37 rev 70964"
    finally:
        drv.close()
        drv.close()  # safe twice


@pytest.mark.parametrize("precision,tol", [("float32", 2e-5), ("fp1220", 1e-6),
                                           ("fp1632", 1e-9), ("float64", 1e-12)])
def test_streaming_values_match_the_source(emu: MtiEmulator, precision: str, tol: float) -> None:
    # float64 Euler angles and quaternion at 100 Hz need more than 115200 baud
    emu.baudrate = 230400 if precision == "float64" else 115200
    drv = make_driver(emu.port, precision=precision, baudrate=emu.baudrate,
                      extra_outputs=list(EXTRA_OUTPUTS))
    drv.open()
    readings = collect(drv, 0.35)
    drv.close()
    assert len(readings) >= 25
    counters = [int(r.values["packet_counter"]) for r in readings]
    assert all((b - a) & 0xFFFF == 1 for a, b in zip(counters, counters[1:], strict=False))
    steps = np.diff([r.t_device for r in readings])
    assert np.allclose(steps, 0.01)
    assert drv.health.extra["dropped_packets"] == 0 and drv.health.rejected_bytes == 0
    for r in readings:
        assert not r.invalid
        want = source(t_device(r))
        got = (r.values["roll_deg"], r.values["pitch_deg"], r.values["yaw_deg"])
        assert max(ang_err(a, b) for a, b in zip(got, want, strict=True)) <= tol * 10
        g = gravity_in_sensor(want[0], want[1])
        assert max(abs(r.values[k] - v) for k, v in zip(("acc_x", "acc_y", "acc_z"), g,
                                                         strict=True)) <= tol
        assert abs(r.values["gyr_z"] - math.radians(40.0) * math.cos(math.radians(want[1]))
                   * math.cos(math.radians(want[0]))) < 0.02
        assert r.values["status_word"] == 3.0


def test_quaternion_fp1632_ned_is_converted_to_euler(emu: MtiEmulator) -> None:
    drv = make_driver(emu.port, orientation="quaternion", precision="fp1632",
                      coordinate_frame="NED")
    drv.open()
    readings = collect(drv, 0.25)
    drv.close()
    assert XDI.QUATERNION | NED | FP1632 in dict(emu.outputs)
    assert len(readings) >= 15
    for r in readings:
        want = source(t_device(r))
        for k, w in zip(("roll_deg", "pitch_deg", "yaw_deg"), want, strict=True):
            assert ang_err(r.values[k], w) < 1e-6


class _HandClock:
    """A clock moved by the test (``stepped``: the emulator does not pace itself by it)."""

    stepped = True

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_the_emulator_sends_on_the_clock_it_is_given() -> None:
    """A replay at five times real time gives the emulator a clock that runs ahead of the
    wall's: it sends every sample due on that clock, each once, whatever the wall time.
    (Until 2026-12-01 this was timed on the wall clock, "100 samples in 0.3 s at 5x", and
    failed on a loaded machine with 58: a figure for a bench, not a test.)"""
    clock = _HandClock()
    with MtiEmulator(source, send_wakeup=False, clock=clock) as e:
        drv = make_driver(e.port)
        drv.open()  # measurement from t = 0: the first sample due is at 0.01 s
        readings: list[Reading] = []
        for step in range(1, 11):
            clock.t = step / 10  # a tenth of a second of the device's time at once
            end = time.monotonic() + 10.0
            while len(readings) < 10 * step and time.monotonic() < end:
                drv.read(readings.append)
        clock.t += 0.005  # nothing more is due: nothing more comes
        readings += collect(drv, 0.1)
        drv.close()
    assert [round(t_device(r), 4) for r in readings] == [k / 100 for k in range(1, 101)]
    for r in readings[::10]:
        assert ang_err(r.values["yaw_deg"], source(t_device(r))[2]) < 1e-4


def test_signals_table_source_through_the_installation() -> None:
    t = np.arange(0.0, 20.0, 0.1)
    table = SignalsTable.from_arrays(time_s=t, handle_deg=10.0 + 30.0 * np.sin(0.3 * t),
                                     swing_deg=150.0 * np.sin(0.2 * t))
    inst = Installation(handle_pitch_offset_deg=4.0, handle_pitch_sign=-1.0,
                        swing_yaw_zero_deg=120.0)
    with MtiEmulator(angles_from_signals(table, inst), send_wakeup=False) as e:
        drv = make_driver(e.port)
        drv.open()
        readings = collect(drv, 0.3)
        drv.close()
    assert len(readings) >= 20
    for r in readings:
        ts = t_device(r)
        assert r.values["roll_deg"] == 0.0
        assert inst.handle_deg(r.values["pitch_deg"]) == pytest.approx(
            np.interp(ts, t, table["handle_deg"]), abs=1e-4)
        assert inst.swing_deg(r.values["yaw_deg"]) == pytest.approx(
            np.interp(ts, t, table["swing_deg"]), abs=1e-3)


def test_noise_and_corruption_are_counted_and_survived() -> None:
    with MtiEmulator(source, send_wakeup=False, seed=3) as e:
        drv = make_driver(e.port)
        drv.open()
        e.garbage_probability, e.corrupt_probability = 0.3, 0.1
        readings = collect(drv, 0.8)
        drv.close()
    h = drv.health
    assert len(readings) >= 50
    assert h.rejected_bytes > 0 and h.bad_frames > 0
    assert h.extra["dropped_packets"] > 0  # corrupted packets are lost, and counted
    for r in readings:
        if not r.invalid:
            assert ang_err(r.values["yaw_deg"], source(t_device(r))[2]) < 1e-4


def test_dropped_packets_and_device_errors(emu: MtiEmulator) -> None:
    drv = make_driver(emu.port)
    drv.open()
    collect(drv, 0.1)
    emu.drop_packets(5)
    emu.send_error(0x29)
    readings = collect(drv, 0.2)
    drv.close()
    assert drv.health.extra["dropped_packets"] == 5
    assert drv.health.extra["device_errors"] == 1
    assert "data overflow" in (drv.health.last_error or "")
    assert readings


def test_error_answer_during_configuration(emu: MtiEmulator) -> None:
    emu.fail_commands[MID.SET_OUTPUT_CONFIGURATION] = 0x21
    drv = make_driver(emu.port)
    with pytest.raises(DeviceError, match=r"answered SetOutputConfiguration with error 0x21 "
                                          r"\(invalid parameter\)"):
        drv.open()
    drv.close()


def test_refused_output_is_reported(emu: MtiEmulator) -> None:
    drv = make_driver(emu.port)
    drv.requested_outputs = lambda: [(XDI.PACKET_COUNTER, MAX_FREQUENCY),  # type: ignore
                                     (XDI.SAMPLE_TIME_FINE, MAX_FREQUENCY),
                                     (XDI.EULER_ANGLES, 100), (XDI.BARO_PRESSURE, 50)]
    with pytest.raises(DeviceError, match="refused output BaroPressure"):
        drv.open()
    drv.close()


def test_device_restart_is_acknowledged_and_reconfigured(emu: MtiEmulator) -> None:
    emu.send_wakeup = True
    drv = make_driver(emu.port)
    drv.open()
    collect(drv, 0.1)
    emu.come_back()  # power cycle: the device sends WakeUp
    with pytest.raises(DeviceError, match="restarted"):
        collect(drv, 0.3)
    wait_for(lambda: emu.state == "config", 1.0)  # our WakeUpAck arrived within 500 ms
    drv.open()
    assert collect(drv, 0.1)
    drv.close()


def run_in_thread(drv: MtiSerialDriver, sink: Callable[[Reading], None]
                  ) -> tuple[threading.Thread, threading.Event]:
    stop = threading.Event()
    th = threading.Thread(target=drv.run, args=(sink, stop), daemon=True)
    th.start()
    return th, stop


def test_unplug_and_plug_back_reconnects_with_backoff(emu: MtiEmulator) -> None:
    drv = make_driver(emu.port)
    readings: list[Reading] = []
    th, stop = run_in_thread(drv, readings.append)
    try:
        wait_for(lambda: len(readings) > 10 and drv.health.connected)
        emu.unplug()
        wait_for(lambda: not drv.health.connected, 2.0)
        n = len(readings)
        time.sleep(0.4)  # several failed reopen attempts (the path is gone)
        assert len(readings) == n and not drv.health.connected
        assert "MTi" in (drv.health.last_error or "")
        emu.plug()
        wait_for(lambda: drv.health.connected and drv.health.reconnects >= 1, 5.0)
        wait_for(lambda: len(readings) > n + 10, 2.0)
    finally:
        stop.set()
        th.join(3.0)
    assert not th.is_alive() and not drv.health.connected
    late = readings[-1]
    assert ang_err(late.values["yaw_deg"], source(t_device(late))[2]) < 1e-4


def test_silent_device_times_out_and_comes_back(emu: MtiEmulator) -> None:
    drv = make_driver(emu.port)
    readings: list[Reading] = []
    errors: list[str] = []
    th, stop = run_in_thread(drv, readings.append)
    try:
        wait_for(lambda: len(readings) > 10)
        emu.go_silent()
        wait_for(lambda: not drv.health.connected, 2.0)
        assert drv.health.timeouts >= 1
        wait_for(lambda: "no answer from MTi" in (drv.health.last_error or ""), 3.0)
        errors.append(drv.health.last_error or "")
        emu.come_back()
        wait_for(lambda: drv.health.connected and drv.health.reconnects >= 1, 5.0)
        n = len(readings)
        wait_for(lambda: len(readings) > n + 5, 2.0)
    finally:
        stop.set()
        th.join(3.0)
    assert f"no answer from MTi on {emu.port} at 115200 baud" in errors[0]


@pytest.mark.parametrize("device_state", ["measurement", "config"])
def test_wrong_baud_rate_gives_a_clear_error(device_state: str) -> None:
    with MtiEmulator(source, send_wakeup=False, baudrate=921600) as e:
        if device_state == "config":
            e.go_silent()  # a device sitting in Config state sends nothing unprompted
        drv = make_driver(e.port, baudrate=115200)
        with pytest.raises(DeviceError) as exc:
            drv.open()
        drv.close()
        assert e.received == []  # it could not understand a single command
    msg = str(exc.value)
    assert msg.startswith(f"no answer from MTi on {e.port} at 115200 baud: wrong baud rate "
                          "or device off?")
    if device_state == "measurement":
        assert "bytes of noise received" in msg


def test_unopenable_port() -> None:
    """Said once: pyserial's own text named the port twice more after the driver's."""
    drv = make_driver("/nonexistent/ttyMTI")
    with pytest.raises(DeviceError) as e:
        drv.open()
    assert str(e.value) == "cannot open MTi port /nonexistent/ttyMTI: No such file or directory"


def test_a_port_the_user_may_not_open_says_what_gives_it(tmp_path: Path) -> None:
    """A permission refused (the daemon's user not in dialout) says what gives it (the
    words checked on the error itself: these tests run as root, whom no port refuses);
    any other reason is said once, as for a folder given as the port."""
    import errno

    from drivers.base import port_error_words

    err = OSError(errno.EACCES, "Permission denied")
    assert port_error_words(err) == ("Permission denied (the daemon's user needs the group "
                                     "of the port, dialout, and the unit's DeviceAllow its "
                                     "kind of device)")
    drv = make_driver(str(tmp_path))
    with pytest.raises(DeviceError) as e:
        drv.open()
    assert str(e.value).startswith(f"cannot open MTi port {tmp_path}: ")
    assert "could not open port" not in str(e.value)


@pytest.mark.parametrize("cfg,key", [
    ({}, "port"),
    ({"port": "/dev/x", "baudrate": 12345}, "baudrate"),
    ({"port": "/dev/x", "baudrate": "fast"}, "baudrate"),
    ({"port": "/dev/x", "rate_hz": 0}, "rate_hz"),
    ({"port": "/dev/x", "orientation": "matrix"}, "orientation"),
    ({"port": "/dev/x", "extra_outputs": ["gyro"]}, "extra_outputs"),
    ({"port": "/dev/x", "extra_outputs": "rate_of_turn"}, "extra_outputs"),
    ({"port": "/dev/x", "extra_outputs": ["acceleration", "acceleration"]}, "extra_outputs"),
    ({"port": "/dev/x", "precision": "float16"}, "precision"),
    ({"port": "/dev/x", "coordinate_frame": "XYZ"}, "coordinate_frame"),
    ({"port": "/dev/x", "data_timeout_s": -1}, "data_timeout_s"),
    ({"port": "/dev/x", "backoff_s": [1.0]}, "backoff_s"),
    ({"port": "/dev/x", "bauds": 9600}, "bauds"),
])
def test_from_config_names_the_bad_key(cfg: dict[str, object], key: str) -> None:
    with pytest.raises(ValueError, match=f"'{key}'"):
        MtiSerialDriver.from_config(cfg)


def test_from_config_accepts_a_full_config() -> None:
    drv = MtiSerialDriver.from_config({
        "name": "arm", "port": "/dev/ttyUSB3", "baudrate": 921600, "rate_hz": 50,
        "orientation": "quaternion", "precision": "fp1220", "coordinate_frame": "NWU",
        "extra_outputs": ["status_word", "rate_of_turn"],
        "stopbits": 2, "command_timeout_s": 2, "data_timeout_s": 0.5, "read_timeout_s": 0.02,
        "backoff_s": [0.5, 10]})
    assert drv.name == "arm" and drv.backoff_s == (0.5, 10.0)
    assert (XDI.QUATERNION | 0x8 | 0x1, 50) in drv.requested_outputs()
    assert {x & 0xFFF0 for x, _ in drv.requested_outputs()} == {
        XDI.PACKET_COUNTER, XDI.SAMPLE_TIME_FINE, XDI.QUATERNION, XDI.RATE_OF_TURN,
        XDI.STATUS_WORD}
    assert drv.value_keys == ("roll_deg", "pitch_deg", "yaw_deg", "gyr_x", "gyr_y", "gyr_z",
                              "packet_counter", "sample_time_fine", "status_word")


def test_pty_pair_is_binary_clean_and_shows_the_baud_rate() -> None:
    import os
    import termios

    import serial

    from hil_fixtures.pty import pty_pair

    with pty_pair() as (master, slave_path):
        os.write(master, b"\xfa\r\n before the port opens: not echoed back to the master")
        ser = serial.Serial(slave_path, 921600, timeout=0.2)  # pyserial flushes input
        try:
            os.write(master, b"\xfa\r\n\x00")
            assert ser.read(4) == b"\xfa\r\n\x00"  # no CR/LF translation
            ser.write(bytes(range(256)))
            ser.flush()
            got = b""
            while len(got) < 256:
                got += os.read(master, 512)
            assert got == bytes(range(256))  # and nothing echoed back into the stream
            assert termios.tcgetattr(master)[5] == termios.B921600
        finally:
            ser.close()


def test_angles_from_signals_loops_holds_and_skips_unknown_rows() -> None:
    t = np.array([0.0, 1.0, 2.0, 3.0])
    table = SignalsTable.from_arrays(time_s=t + 100.0, handle_deg=[0.0, 10.0, np.nan, 30.0],
                                     swing_deg=[170.0, 190.0, 0.0, 210.0])
    looped = angles_from_signals(table)
    assert looped(0.5) == pytest.approx((0.0, 5.0, -180.0))  # swing 180 wraps to -180
    assert looped(2.0) == pytest.approx((0.0, 20.0, -160.0))  # the blank row is skipped
    assert looped(3.5) == pytest.approx(looped(0.5))
    held = angles_from_signals(table, loop=False)
    assert held(10.0) == pytest.approx((0.0, 30.0, -150.0))
    with pytest.raises(ValueError, match="need two rows"):
        angles_from_signals(SignalsTable.from_arrays(time_s=[0.0, 1.0], handle_deg=[1.0, 2.0]))


def test_a_non_finite_value_in_a_frame_is_invalid_not_a_number() -> None:
    """A float field whose bits decode to NaN or infinity never reaches the loop."""
    from drivers.xsens.mtdata2 import encode_mtdata2

    drv = make_driver("/dev/null")
    payload = encode_mtdata2([(XDI.EULER_ANGLES, (float("nan"), 2.0, float("inf"))),
                              (XDI.PACKET_COUNTER, 7)])
    r = drv.decode(payload)
    assert r is not None
    got: list[Reading] = []
    drv.emit(got.append, r)
    assert got[0].values == {"pitch_deg": 2.0, "packet_counter": 7.0}
    assert {"roll_deg", "yaw_deg"} <= got[0].invalid
    assert drv.health.bad_frames == 1
