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
from drivers.xsens.orientation import euler_deg_to_quat  # noqa: E402
from drivers.xsens.serial_driver import (  # noqa: E402
    EXTRA_OUTPUTS,
    MtiSerialDriver,
    orientations_agree,
)


@pytest.mark.parametrize("parser", fuzz.PARSERS)
def test_no_crash_no_hang(parser: str) -> None:
    t = fuzz.Tally(parser, hang_s=1.0)
    rng = random.Random(7)
    n = 3000
    if parser.startswith("xbus"):
        fuzz.fuzz_xbus(n, rng, t, "euler" if parser == "xbus-euler" else "euler+quaternion")
    elif parser == "mti-can":
        fuzz.fuzz_mti_can(n, rng, t)
    elif parser == "ar4000":
        fuzz.fuzz_ar4000(n, rng, t)
    elif parser == "modbus":
        fuzz.fuzz_modbus(n, rng, t)
    else:
        fuzz.fuzz_text(n, rng, t, parser)
    assert t.n >= n * 0.99
    assert (t.crashes, t.hangs) == (0, 0), t.first_crash


def frame(pc: int, stf: int, euler: tuple[float, float, float] = (1.0, -44.5, 3.0),
          acc: tuple[float, float, float] = (0.9, 0.1, 9.7),
          quat: tuple[float, ...] | None = None) -> bytes:
    items = [(XDI.EULER_ANGLES, euler), (XDI.RATE_OF_TURN, (0.01, 0.02, 0.0)),
             (XDI.ACCELERATION, acc), (XDI.PACKET_COUNTER, pc), (XDI.SAMPLE_TIME_FINE, stf),
             (XDI.STATUS_WORD, 3)]
    if quat is not None:
        items.append((XDI.QUATERNION, quat))
    return encode_mtdata2(items)


@pytest.mark.parametrize("orientation", ["euler", "euler+quaternion"])
def test_frames_that_disagree_with_themselves_or_the_last_are_dropped(orientation: str) -> None:
    drv = MtiSerialDriver.from_config({"port": "/dev/null", "rate_hz": 100,
                                       "orientation": orientation,
                                       "extra_outputs": list(EXTRA_OUTPUTS)})
    both = orientation == "euler+quaternion"

    def f(pc: int, stf: int, euler: tuple[float, float, float] = (1.0, -44.5, 3.0),
          acc: tuple[float, float, float] = (0.9, 0.1, 9.7)) -> bytes:
        return frame(pc, stf, euler, acc, euler_deg_to_quat(*euler) if both else None)

    assert drv.decode(f(10, 1000)) is not None
    assert drv.decode(f(11, 1100)) is not None
    assert drv.decode(f(12, 1200)) is not None  # steady at 100 Hz
    assert drv.decode(f(15, 1500)) is not None  # two dropped: counter and time agree
    assert drv.decode(f(16, 9999)) is None  # the time disagrees with the counter
    assert drv.decode(f(17, 1700)) is None  # (its successor checks against it)
    assert drv.decode(f(18, 1800)) is not None
    assert drv.decode(f(19, 1900, euler=(1.0, -30.0, 3.0))) is None  # 14.5 deg in 10 ms
    assert drv.decode(f(20, 2000)) is None
    assert drv.decode(f(21, 2100, acc=(0.9, 1e3, 9.7))) is None  # out of range
    partial = encode_mtdata2([(XDI.EULER_ANGLES, (1.0, -44.5, 3.0)), (XDI.PACKET_COUNTER, 22)])
    assert drv.decode(partial) is None  # the configured packet, cut: not this device's
    assert drv.health.extra["inconsistent_frames"] == 6
    if both:  # a packet without its quaternion is not the configured one either
        assert drv.decode(frame(23, 2300)) is None


def test_euler_angles_that_disagree_with_the_quaternion_are_dropped() -> None:
    """Sent both, a corruption of either that passes the checksum and every continuity
    check (0.02 deg is well inside the 2 deg a real filter may step) still shows."""
    drv = MtiSerialDriver.from_config({"port": "/dev/null",
                                       "extra_outputs": list(EXTRA_OUTPUTS)})
    e = (1.0, -44.5, 3.0)
    q = euler_deg_to_quat(*e)
    assert drv.decode(frame(10, 1000, e, quat=q)) is not None
    assert drv.decode(frame(11, 1100, (1.0, -44.52, 3.0), quat=q)) is None  # pitch moved
    assert drv.decode(frame(12, 1200, e, quat=q)) is not None
    assert drv.decode(frame(13, 1300, e, quat=euler_deg_to_quat(1.0, -44.5, 3.02))) is None
    assert drv.decode(frame(14, 1400, e, quat=tuple(1.001 * c for c in q))) is None  # norm
    # float32 rounding of either encoding is far inside the agreement
    assert drv.decode(frame(15, 1500, (1.0, -44.5, 3.004), quat=q)) is not None
    assert drv.health.extra["inconsistent_frames"] == 3


def test_the_orientation_alone_is_checked_without_a_rate_of_turn() -> None:
    """The default packet: counter, sample time and both orientations, nothing the loop
    does not use. An angle may then jump as far as the fastest rate the family
    measures (35 rad/s) turns in the time between the frames, plus the 2 deg slack."""
    drv = MtiSerialDriver.from_config({"port": "/dev/null", "rate_hz": 100})
    assert [x & 0xFFF0 for x, _ in drv.requested_outputs()] == [
        XDI.PACKET_COUNTER, XDI.SAMPLE_TIME_FINE, XDI.EULER_ANGLES, XDI.QUATERNION]

    def f(pc: int, stf: int, euler: tuple[float, float, float] = (1.0, -44.5, 3.0)) -> bytes:
        return encode_mtdata2([(XDI.PACKET_COUNTER, pc), (XDI.SAMPLE_TIME_FINE, stf),
                               (XDI.EULER_ANGLES, euler),
                               (XDI.QUATERNION, euler_deg_to_quat(*euler))])

    r = drv.decode(f(10, 1000))
    assert r is not None and sorted(r.values) == sorted(
        ["roll_deg", "pitch_deg", "yaw_deg", "packet_counter", "sample_time_fine"])
    assert not r.invalid
    assert drv.decode(f(11, 1100, (1.0, -30.0, 3.0))) is not None  # 14.5 deg: < 22 deg
    assert drv.decode(f(12, 1200, (1.0, -60.0, 3.0))) is None  # 30 deg in 10 ms
    assert drv.decode(f(13, 1300, (1.0, -60.0, 3.0))) is not None
    assert drv.decode(f(14, 1400, (1.0, -60.01, 3.0))[:-4] + b"\0\0\0\0") is None  # q
    assert drv.decode(frame(15, 1500, quat=euler_deg_to_quat(1.0, -44.5, 3.0))) is None
    assert drv.health.extra["inconsistent_frames"] == 3  # (the last: not its packet)


def test_the_sample_time_advances_to_the_tick_where_a_period_is_whole_ticks() -> None:
    """At 100 Hz a real MTi's packets are exactly 100 ticks of its 10 kHz clock apart, so
    a sample time one tick off is a corrupted one; at 30 Hz a period is 333.3 ticks and
    the device rounds it, 333 or 334."""
    def f(pc: int, stf: int) -> bytes:
        e = (1.0, -44.5, 3.0)
        return encode_mtdata2([(XDI.PACKET_COUNTER, pc), (XDI.SAMPLE_TIME_FINE, stf),
                               (XDI.EULER_ANGLES, e), (XDI.QUATERNION, euler_deg_to_quat(*e))])

    drv = MtiSerialDriver.from_config({"port": "/dev/null", "rate_hz": 100})
    assert drv.decode(f(10, 1000)) is not None
    assert drv.decode(f(11, 1101)) is None  # one tick late
    assert drv.decode(f(12, 1200)) is None  # (checked against the one before)
    assert drv.decode(f(13, 1300)) is not None
    assert drv.decode(f(15, 1500)) is not None  # a packet lost: two periods exactly
    odd = MtiSerialDriver.from_config({"port": "/dev/null", "rate_hz": 30})
    assert all(odd.decode(f(10 + i, 1000 + t)) is not None
               for i, t in enumerate((0, 333, 667, 1000, 1333, 1667, 2000)))
    assert odd.decode(f(17, 2335)) is None  # 2 ticks off 333.3


@pytest.mark.parametrize("e", [(0.0, 89.9, 30.0), (179.99, 0.0, -179.99), (-120.0, -60.0, 90.0)])
def test_agreement_holds_where_euler_angles_are_singular_or_wrap(
        e: tuple[float, float, float]) -> None:
    q = euler_deg_to_quat(*e)
    assert orientations_agree(e, q)
    assert not orientations_agree((e[0], e[1] - 0.01, e[2]), q)
    assert not orientations_agree((e[0] + 0.01, e[1], e[2]), q)


def test_at_pitch_90_only_the_orientation_counts_not_its_angles() -> None:
    """There roll and yaw turn about one axis: other angles, the same orientation."""
    assert orientations_agree((20.0, 90.0, 50.0), euler_deg_to_quat(0.0, 90.0, 30.0))
    assert not orientations_agree((20.0, 90.0, 50.0), euler_deg_to_quat(0.0, 90.0, 29.98))


def test_a_corrupted_laser_line_reaches_the_loop_only_within_the_handles_reach() -> None:
    """The AR4000 has no checksum; a corrupted line's distance is used only within what
    the handle moves in one 20 ms sample (3 m/s + 10 mm) of the last distance used, so
    no reading is further off the clean line than that and the clean lines' own step."""
    t = fuzz.Tally("ar4000", hang_s=1.0)
    errors: list[float] = []
    fuzz.fuzz_ar4000(3000, random.Random(11), t, errors)
    lines = fuzz.rx_bytes("laser.serial.jsonl").split(b"\r\n")[1:-1]
    step = max(abs(int(a) - int(b)) for a, b in zip(lines, lines[1:], strict=False)) * 1e-3
    assert t.checked > 300 and errors  # corrupted distances there were, some got through
    assert max(errors) <= 3.0 * 0.02 + 0.01 + step + 1e-9
    off: list[float] = []
    fuzz.fuzz_ar4000(3000, random.Random(11), fuzz.Tally("ar4000", 1.0), off, 1e9)
    assert max(off) > 1.0  # (without the rule, metres)
