"""MtiCanDriver against MtiCanEmulator on python-can's virtual bus (one channel per test)."""

from __future__ import annotations

import itertools
import math
import threading
import time

import can
import pytest

from drivers.base import DeviceError, Reading
from drivers.xsens.can_driver import MtiCanCodec, MtiCanDriver, MtiCanLayout
from drivers.xsens.orientation import gravity_in_sensor
from hil_fixtures.mti_can import MtiCanEmulator
from shoveld.installation import wrap_deg

from .conftest import collect, t_device, wait_for

_channels = itertools.count()


def channel() -> str:
    return f"mti-test-{time.monotonic_ns()}-{next(_channels)}"


def source(t: float) -> tuple[float, float, float]:
    return (0.5 * math.sin(0.7 * t), 20.0 * math.sin(1.3 * t) - 5.0, wrap_deg(170.0 + 40.0 * t))


def test_default_ids_and_scalings() -> None:
    lay = MtiCanLayout()
    assert (lay.sample_time_id, lay.group_counter_id, lay.status_word_id) == (0x05, 0x06, 0x11)
    assert (lay.quaternion_id, lay.euler_angles_id) == (0x21, 0x22)
    assert (lay.rate_of_turn_id, lay.acceleration_id) == (0x32, 0x34)
    assert lay.euler_scale_deg == 2 ** -7 and lay.rate_of_turn_scale == 2 ** -9
    assert lay.acceleration_scale == 2 ** -8 and lay.quaternion_scale == 2 ** -15


@pytest.mark.parametrize("byteorder", ["big", "little"])
def test_codec_round_trip_and_saturation(byteorder: str) -> None:
    codec = MtiCanCodec(MtiCanLayout(byteorder=byteorder))
    m = codec.encode("euler_angles", (12.5, -3.25, -90.0))
    assert m.arbitration_id == 0x22 and len(m.data) == 6
    assert codec.decode(0x22, bytes(m.data)) == ("euler_angles", (12.5, -3.25, -90.0))
    big = codec.encode("acceleration", (1000.0, -1000.0, 9.80859375))
    assert codec.decode(0x34, bytes(big.data)) == ("acceleration", (32767 / 256, -128.0,
                                                                     9.80859375))
    q = codec.encode("quaternion", (1.0, 0.0, -1.0, 0.5))
    quat = codec.decode(0x21, bytes(q.data))
    assert quat is not None and quat[1] == (32767 / 32768, 0.0, -1.0, 0.5)
    assert codec.decode(0x05, bytes(codec.encode("sample_time", 123456.0).data)) == (
        "sample_time", (123456.0,))
    assert codec.decode(0x22, b"\x00") is None  # too short
    assert codec.decode(0x123, b"\x00" * 8) is None  # foreign id
    if byteorder == "big":
        assert bytes(m.data) == bytes.fromhex("0640fe60d300")


def test_driver_against_emulator_values_match() -> None:
    ch = channel()
    with MtiCanEmulator(source, ch):
        drv = MtiCanDriver.from_config({"interface": "virtual", "channel": ch,
                                        "data_timeout_s": 0.3})
        drv.open()
        readings = collect(drv, 0.35)
        drv.close()
    assert len(readings) >= 25
    counters = [int(r.values["packet_counter"]) for r in readings]
    assert all(b - a == 1 for a, b in zip(counters, counters[1:], strict=False))
    for r in readings:
        assert not r.invalid
        want = source(t_device(r))
        for k, w in zip(("roll_deg", "pitch_deg", "yaw_deg"), want, strict=True):
            assert abs(wrap_deg(r.values[k] - w)) <= 2 ** -8 + 1e-9  # half an LSB of 2^-7
        for k, g in zip(("acc_x", "acc_y", "acc_z"), gravity_in_sensor(want[0], want[1]),
                        strict=True):
            assert abs(r.values[k] - g) <= 2 ** -9 + 1e-9
    assert drv.health.extra["dropped_packets"] == 0


def test_quaternion_mode_and_custom_ids() -> None:
    ch = channel()
    lay = MtiCanLayout(quaternion_id=0x121, rate_of_turn_id=0x132)
    msgs = ("sample_time", "group_counter", "quaternion", "rate_of_turn", "acceleration")
    with MtiCanEmulator(source, ch, layout=lay, messages=msgs):
        drv = MtiCanDriver.from_config({"interface": "virtual", "channel": ch,
                                        "messages": list(msgs), "quaternion_id": "0x121",
                                        "rate_of_turn_id": 0x132})
        drv.open()
        readings = collect(drv, 0.25)
        drv.close()
    assert len(readings) >= 15
    for r in readings:
        want = source(t_device(r))
        for k, w in zip(("roll_deg", "pitch_deg", "yaw_deg"), want, strict=True):
            assert abs(wrap_deg(r.values[k] - w)) < 0.01
        assert "status_word" not in r.values and not r.invalid


def test_lost_groups_lost_frames_and_errors() -> None:
    ch = channel()
    with MtiCanEmulator(source, ch) as emu:
        drv = MtiCanDriver(channel=ch, interface="virtual")
        drv.open()
        collect(drv, 0.1)
        emu.drop_groups(4)
        emu.drop_next("rate_of_turn")
        emu.send_error(0x01)
        readings = collect(drv, 0.25)
        drv.close()
    assert drv.health.extra["dropped_packets"] == 4
    assert drv.health.extra["device_errors"] == 1
    partial = [r for r in readings if r.invalid]
    assert len(partial) == 1 and partial[0].invalid == {"gyr_x", "gyr_y", "gyr_z"}
    assert "gyr_x" not in partial[0].values


def test_silence_raises_and_run_reconnects() -> None:
    ch = channel()
    with MtiCanEmulator(source, ch) as emu:
        drv = MtiCanDriver(channel=ch, interface="virtual", data_timeout_s=0.2,
                           backoff_s=(0.05, 0.1))
        readings: list[Reading] = []
        stop = threading.Event()
        th = threading.Thread(target=drv.run, args=(readings.append, stop), daemon=True)
        th.start()
        try:
            wait_for(lambda: len(readings) > 5)
            emu.go_silent()
            wait_for(lambda: not drv.health.connected, 2.0)
            assert "no MTi frames on CAN virtual:" in (drv.health.last_error or "")
            assert drv.health.timeouts >= 1
            for _ in range(5):  # reopening a silent bus does not count as connected
                time.sleep(0.06)
                assert not drv.health.connected and drv.health.reconnects == 0
            emu.come_back()
            n = len(readings)
            wait_for(lambda: len(readings) > n + 5 and drv.health.reconnects >= 1, 3.0)
        finally:
            stop.set()
            th.join(3.0)
    assert not th.is_alive()


def test_bus_open_failure_is_a_device_error() -> None:
    def broken(**kw: object) -> can.BusABC:
        raise can.CanError("no such interface")

    drv = MtiCanDriver(channel="can9", bus_factory=broken)
    with pytest.raises(DeviceError, match="cannot open CAN socketcan:can9"):
        drv.open()
    drv.close()


@pytest.mark.parametrize("cfg,key", [
    ({"euler_angles_id": 0x800}, "euler_angles_id"),
    ({"euler_angles_id": "zz"}, "euler_angles_id"),
    ({"acceleration_scale": 0}, "acceleration_scale"),
    ({"byteorder": "middle"}, "byteorder"),
    ({"messages": ["euler_angles", "gps"]}, "messages"),
    ({"messages": "euler_angles"}, "messages"),
    ({"data_timeout_s": 0}, "data_timeout_s"),
    ({"bitrate": -5}, "bitrate"),
    ({"chanel": "can0"}, "chanel"),
])
def test_from_config_names_the_bad_key(cfg: dict[str, object], key: str) -> None:
    with pytest.raises(ValueError, match=f"'{key}'"):
        MtiCanDriver.from_config(cfg)


def test_open_waits_for_the_device() -> None:
    drv = MtiCanDriver(channel=channel(), interface="virtual", data_timeout_s=0.1)
    with pytest.raises(DeviceError, match="no MTi frames on CAN virtual:.* within 0.1 s"):
        drv.open()
    drv.close()


@pytest.mark.parametrize("kind", ["euler_angles", "quaternion", "sample_time", "group_counter"])
def test_a_frame_of_the_wrong_length_is_not_its_message(kind: str) -> None:
    codec = MtiCanCodec(MtiCanLayout())
    values = (1.0, 2.0, 3.0, 0.5) if kind == "quaternion" else (
        (1.0, 2.0, 3.0) if kind == "euler_angles" else (7.0,))
    msg = codec.encode(kind, values[0] if len(values) == 1 else values)
    assert codec.decode(msg.arbitration_id, bytes(msg.data)) is not None
    assert codec.decode(msg.arbitration_id, bytes(msg.data) + b"\x00") is None
    assert codec.decode(msg.arbitration_id, bytes(msg.data)[:-1]) is None
