"""A short run of ``bench/fuzz.py`` per parser (the bench runs 10^6 each): no crash, no
hang; and the MTi driver stops corrupted frames that pass the 8-bit Xbus checksum by
what the frame carries."""

from __future__ import annotations

import random
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
import fuzz  # noqa: E402

from drivers.xsens.mtdata2 import XDI, encode_mtdata2  # noqa: E402
from drivers.xsens.serial_driver import MtiSerialDriver  # noqa: E402


@pytest.mark.parametrize("parser", fuzz.PARSERS)
def test_no_crash_no_hang(parser: str) -> None:
    t = fuzz.Tally(parser, hang_s=1.0)
    rng = random.Random(7)
    n = 3000
    if parser == "xbus":
        fuzz.fuzz_xbus(n, rng, t)
    elif parser == "ar4000":
        fuzz.fuzz_ar4000(n, rng, t)
    elif parser == "modbus":
        fuzz.fuzz_modbus(n, rng, t)
    else:
        fuzz.fuzz_text(n, rng, t, parser)
    assert t.n >= n * 0.99
    assert (t.crashes, t.hangs) == (0, 0), t.first_crash


def frame(pc: int, stf: int, euler: tuple[float, float, float] = (1.0, -44.5, 3.0),
          acc: tuple[float, float, float] = (0.9, 0.1, 9.7)) -> bytes:
    return encode_mtdata2([(XDI.EULER_ANGLES, euler), (XDI.RATE_OF_TURN, (0.01, 0.02, 0.0)),
                           (XDI.ACCELERATION, acc), (XDI.PACKET_COUNTER, pc),
                           (XDI.SAMPLE_TIME_FINE, stf), (XDI.STATUS_WORD, 3)])


def test_frames_that_disagree_with_themselves_or_the_last_are_dropped() -> None:
    drv = MtiSerialDriver.from_config({"port": "/dev/null", "rate_hz": 100})
    assert drv.decode(frame(10, 1000)) is not None
    assert drv.decode(frame(11, 1100)) is not None
    assert drv.decode(frame(12, 1200)) is not None  # steady at 100 Hz
    assert drv.decode(frame(15, 1500)) is not None  # two dropped: counter and time agree
    assert drv.decode(frame(16, 9999)) is None  # the time disagrees with the counter
    assert drv.decode(frame(17, 1700)) is None  # (its successor checks against it)
    assert drv.decode(frame(18, 1800)) is not None
    assert drv.decode(frame(19, 1900, euler=(1.0, -30.0, 3.0))) is None  # 14.5 deg in 10 ms
    assert drv.decode(frame(20, 2000)) is None
    assert drv.decode(frame(21, 2100, acc=(0.9, 1e3, 9.7))) is None  # out of range
    partial = encode_mtdata2([(XDI.EULER_ANGLES, (1.0, -44.5, 3.0)), (XDI.PACKET_COUNTER, 22)])
    assert drv.decode(partial) is None  # the configured packet, cut: not this device's
    assert drv.health.extra["inconsistent_frames"] == 6
