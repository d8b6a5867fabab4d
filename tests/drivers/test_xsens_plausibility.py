"""The MTi driver's checks on what a frame carries, each against real frames.

Every rule ``MtiSerialDriver`` applies to a frame that passed the one-byte checksum
(identifiers as configured, finite values in the sensor's range, none next to zero,
the status word's reserved bits clear and its self-test bit steady) must never drop
a frame a real device sent: every packet of the real MTi-G-710 captures
(tests/fixtures/xsens-mti-g710) and of the committed emulator capture passes all of
them. Each rule also has a frame that fails it: a real frame with the corruption the
fuzz bench (``bench/fuzz.py``) found getting through before the rule, the checksum
recomputed so that only the rule can catch it.
"""

from __future__ import annotations

import math
import struct
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import fuzz  # noqa: E402

from drivers.xsens.mtdata2 import (  # noqa: E402
    XDI,
    decode_mtdata2,
    decode_output_configuration,
    encode_item,
    iter_packets,
    mtdata2_values,
    mtdata2_values_ids,
)
from drivers.xsens.orientation import euler_deg_to_quat  # noqa: E402
from drivers.xsens.serial_driver import (  # noqa: E402
    EXTRA_OUTPUTS,
    STATUS_RESERVED,
    TINY,
    MtiSerialDriver,
)
from drivers.xsens.xbus import XbusParser  # noqa: E402

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "xsens-mti-g710"


def _real(folder: str) -> tuple[list[bytes], frozenset[int]]:
    """The MTData2 payloads of a real capture and the identifiers it was configured with."""
    base = FIXTURES / folder
    conf = frozenset(s.xdi for s in decode_output_configuration(
        (base / "outputconfig.bin").read_bytes()))
    msgs = XbusParser().feed((base / "output.bin").read_bytes())
    return [m.data for m in msgs if m.mid == 0x36], conf


def _matrix_euler(r: tuple[float, ...]) -> tuple[float, float, float]:
    """Euler angles of a rotation matrix sent column by column (R = Rz Ry Rx)."""
    r11, r21, r31, _, _, r32, _, _, r33 = r
    return (math.degrees(math.atan2(r32, r33)), -math.degrees(math.asin(r31)),
            math.degrees(math.atan2(r21, r11)))


@pytest.mark.parametrize("folder", ["1", "3", "5"])
def test_every_real_packet_passes_every_check(folder: str) -> None:
    """A real MTi-G-710 (float32 and fp16.32, at rest and with its GNSS filter stepping
    its angles): every packet's identifiers are configured ones, no float in any item is
    within TINY of zero, no reserved status bit is set, ``_consistent`` takes every packet
    (capture 5 has no Euler angles, rate or acceleration: its rotation matrix gives the
    angles, its quaternion the second orientation, its free acceleration the vector).
    This device was also configured for GNSS data at 4 Hz, which it sends in packets of
    their own that take a packet counter value between two 100 Hz packets; the driver
    never configures those, so the chain of packets is checked between them."""
    payloads, conf = _real(folder)
    prec = "fp1632" if folder == "3" else "float32"
    drv = MtiSerialDriver(orientation="euler+quaternion" if folder == "5" else "euler",
                          precision=prec, baudrate=921600)
    drv.health.extra["output_rate_hz"] = 100
    floats = checked = 0
    for p in payloads:
        vals, ids = mtdata2_values_ids(p)
        assert ids is not None and ids <= conf
        for item in decode_mtdata2(p):
            if isinstance(item.value, tuple) and all(isinstance(v, float) for v in item.value):
                floats += len(item.value)
                assert not any(0.0 < abs(v) < TINY for v in item.value), item
        if XDI.ROTATION_MATRIX not in vals and XDI.EULER_ANGLES not in vals:
            drv._prev_frame = None  # a GNSS packet between two (see the docstring)
            continue
        sw = vals.get(XDI.STATUS_WORD, vals.get(XDI.STATUS_BYTE))
        assert sw is not None and not sw & STATUS_RESERVED
        if folder == "5":
            e, q = _matrix_euler(vals[XDI.ROTATION_MATRIX]), vals[XDI.QUATERNION]
            g, acc = (0.0, 0.0, 0.0), vals[XDI.FREE_ACCELERATION]
        else:
            e, q = vals[XDI.EULER_ANGLES], None
            g, acc = vals[XDI.RATE_OF_TURN], vals[XDI.ACCELERATION]
        assert drv._consistent(vals[XDI.PACKET_COUNTER], vals[XDI.SAMPLE_TIME_FINE], e, g,
                               acc, q, sw), (checked, vals)
        checked += 1
    assert checked == (92 if folder == "5" else 95)
    assert floats > 1500
    assert drv.health.extra["inconsistent_frames"] == 0


@pytest.mark.parametrize("orientation", ["euler", "euler+quaternion"])
def test_every_frame_of_the_committed_capture_passes(orientation: str) -> None:
    """The emulator's 10,309 frames (exact zeros included: roll and the y acceleration
    of a machine that does not roll), as recorded and with their quaternion added."""
    drv, msgs = _capture(orientation)
    got = [drv.decode(m) for m in msgs]
    assert all(r is not None for r in got)
    assert drv.health.extra["inconsistent_frames"] == 0
    assert len(got) == 10309


def _capture(orientation: str) -> tuple[MtiSerialDriver, list[bytes]]:
    payloads = [m.data for m in XbusParser().feed(fuzz.rx_bytes("mti.serial.jsonl"))
                if m.mid == 0x36]
    if orientation == "euler+quaternion":
        payloads = [p + encode_item(XDI.QUATERNION, euler_deg_to_quat(
            *mtdata2_values(p)[XDI.EULER_ANGLES])) for p in payloads]
    # the emulator was asked for its rate of turn, acceleration and status word too
    return MtiSerialDriver(orientation=orientation, extra_outputs=EXTRA_OUTPUTS), payloads


def _replace(payload: bytes, xdi: int, value: bytes, at: int = 0) -> bytes:
    """``payload`` with bytes of an item's data replaced (as a hit that passed the
    checksum leaves it)."""
    for x, off, _size in iter_packets(payload):
        if x & 0xFFF0 == xdi:
            return payload[:off + at] + value + payload[off + at + len(value):]
    raise KeyError(xdi)


def _head(payload: bytes, xdi: int, new_xdi: int) -> bytes:
    """``payload`` with an item's identifier replaced."""
    for x, off, _size in iter_packets(payload):
        if x & 0xFFF0 == xdi:
            return payload[:off - 3] + struct.pack(">H", new_xdi) + payload[off - 1:]
    raise KeyError(xdi)


def _f32(v: float) -> bytes:
    return struct.pack(">f", v)


CORRUPTIONS: dict[str, Callable[[bytes], bytes]] = {
    # a status byte hit: bit 29 (reserved) or the self-test bit
    "reserved status bit": lambda p: _replace(p, XDI.STATUS_WORD, b"\x20\x00\x00\x03"),
    "self-test bit": lambda p: _replace(p, XDI.STATUS_WORD, b"\x00\x00\x00\x02"),
    # an exponent byte hit: 0.0 turned subnormal, a rate of 0.1 rad/s into 2e-24
    "acceleration next to zero": lambda p: _replace(p, XDI.ACCELERATION, b"\x00\x40", at=4),
    "rate next to zero": lambda p: _replace(p, XDI.RATE_OF_TURN, b"\x18", at=8),
    "angle next to zero": lambda p: _replace(p, XDI.EULER_ANGLES, _f32(-1e-40), at=0),
    "NaN rate": lambda p: _replace(p, XDI.RATE_OF_TURN, b"\x7f\xc0\x00\x00", at=4),
    "rate out of range": lambda p: _replace(p, XDI.RATE_OF_TURN, _f32(-36.0), at=8),
    # an identifier byte hit: another precision (the same bytes read as fp12.20), another
    # coordinate frame (the same numbers meant otherwise)
    "rate as fp12.20": lambda p: _head(p, XDI.RATE_OF_TURN, XDI.RATE_OF_TURN | 1),
    "Euler angles as NED": lambda p: _head(p, XDI.EULER_ANGLES, XDI.EULER_ANGLES | 4),
    "status as another item": lambda p: _head(p, XDI.STATUS_WORD, XDI.DEVICE_ID),
    "an item twice": lambda p: p + encode_item(XDI.STATUS_WORD, 3),
}


@pytest.mark.parametrize("orientation", ["euler", "euler+quaternion"])
@pytest.mark.parametrize("kind", sorted(CORRUPTIONS))
def test_a_real_frame_passes_and_its_corruption_does_not(kind: str, orientation: str) -> None:
    drv, msgs = _capture(orientation)
    k = 1000
    bad = CORRUPTIONS[kind](msgs[k])
    assert bad != msgs[k] and len(bad) >= len(msgs[k])
    assert drv.decode(msgs[k - 1]) is not None
    assert drv.decode(bad) is None
    assert drv.health.extra["inconsistent_frames"] == 1
    # and the clean frame itself, after its predecessor, is taken
    drv2, _ = _capture(orientation)
    assert drv2.decode(msgs[k - 1]) is not None and drv2.decode(msgs[k]) is not None


def test_zero_is_not_next_to_zero_and_the_self_test_bit_may_stay_clear() -> None:
    """An exact 0.0 is a value a device sends (the emulator does, for roll); a device
    that failed its self-test keeps sending bit 0 clear, frame after frame."""
    drv, msgs = _capture("euler")
    failed = [_replace(p, XDI.STATUS_WORD, b"\x00\x00\x00\x02") for p in msgs[:50]]
    assert all(drv.decode(p) is not None for p in failed)
    assert mtdata2_values(msgs[0])[XDI.EULER_ANGLES][0] == 0.0
