"""The MTi driver's span reads do what its per-tick reads do, frame for frame and count
for count: on the committed capture, on a stream with the redundant orientation, and
with the damage a serial line does (bit errors, noise, lost and truncated frames,
frames that pass the checksum but not the driver's checks, NaN fields, error
messages, a silence that times out)."""

from __future__ import annotations

import copy
import math
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.base import DriverHealth, Reading
from drivers.capture.format import read_capture
from drivers.xsens.bulk import FrameLayout, clean_run
from drivers.xsens.mtdata2 import FP1632, PRECISION_BY_NAME, XDI
from drivers.xsens.serial_driver import EXTRA_OUTPUTS, VALUE_KEYS, MtiSerialDriver
from drivers.xsens.serial_span import MtiSpanReader, consistent
from drivers.xsens.xbus import MID, encode_frame
from hil_fixtures.mti import MtiEmulator
from shoveld.daemon.config import DeviceConfig, device_signals
from shoveld.replay.sync import MemorySerial, StepClock, SyncDevice, SyncReplay

from .span_play import play

CAPTURE = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e"
PERIOD = 0.01
Edit = Callable[[bytearray, list[int], FrameLayout], bytearray]


def _health(h: DriverHealth) -> dict[str, Any]:
    return copy.deepcopy(h.as_dict())


def _play(driver: MtiSerialDriver, port: MemorySerial, clock: StepClock, ticks: int,
          window: int | None) -> tuple[list[tuple[Any, ...]], list[dict[str, Any]], bytes]:
    """Readings (tick, values, invalid) and health after every tick; span reads of up to
    ``window`` ticks wherever they can start (None: the per-tick reads only)."""
    readings: list[tuple[Any, ...]] = []
    at = [0]

    def sink(r: Reading) -> None:
        readings.append((at[0], r.t_host, tuple(r.values.get(k, "-") for k in VALUE_KEYS),
                         tuple(sorted(r.invalid))))

    def span_rows(got: Any) -> None:
        for i, tick in enumerate(got.reading_ticks.tolist()):
            readings.append((tick, tick * PERIOD, tuple(
                float(got.values[key][i]) if key in got.values else "-"
                for key in VALUE_KEYS), ()))

    dev = SyncDevice("mti", driver, port, sink, clock)
    reader = MtiSpanReader(driver, port, PERIOD) if window else None
    health = play(dev, reader, clock, ticks, window, PERIOD, span_rows, at)
    return readings, health, bytes(driver._parser._sniffer._buf)


def _frames(data: bytes | bytearray) -> list[int]:
    """Starts of the MTData2 frames (by their header) in ``data``."""
    out, i = [], data.find(b"\xfa\xff\x36")
    while i >= 0:
        out.append(i)
        i = data.find(b"\xfa\xff\x36", i + 1)
    return out


def _edit(stream: list[tuple[float, bytes]], t0: float, t1: float, edit: Edit) -> None:
    """Apply ``edit`` to the bytes recorded in [t0, t1); they keep the chunks' times (the
    last chunk takes any bytes more or fewer)."""
    idx = [i for i, (t, _) in enumerate(stream) if t0 <= t < t1]
    data = bytearray(b"".join(stream[i][1] for i in idx))
    starts = _frames(data)
    lay = FrameLayout(np.frombuffer(bytes(data[starts[0]:starts[1]]), np.uint8), 4)
    new = edit(data, starts[1:-2], lay)
    pos = 0
    for n, i in enumerate(idx):
        size = len(stream[i][1]) if n < len(idx) - 1 else len(new) - pos
        stream[i] = (stream[i][0], bytes(new[pos:pos + size]))
        pos += size


def _resum(data: bytearray, start: int, length: int) -> None:
    data[start + length - 1] = (-sum(data[start + 1:start + length - 1])) & 0xFF


def _put(data: bytearray, f: int, lay: FrameLayout, xdi: int, value: bytes, at: int = 0,
         ) -> None:
    """Overwrite bytes of an item (at byte ``at`` of it) and fix the checksum; nothing if
    the layout does not have the item."""
    if xdi not in lay.fields:
        return
    off = f + lay.fields[xdi].offset + at
    data[off:off + len(value)] = value
    _resum(data, f, lay.length)


def damage(data: bytearray, fs: list[int], lay: FrameLayout) -> bytearray:
    """One of each: the kinds of damage a frame stream shows, in one stretch."""
    n = lay.length
    data[fs[3] + 9] ^= 0x40  # a bit error: bad checksum
    _put(data, fs[8], lay, XDI.EULER_ANGLES, b"\x43", at=4)  # pitch far off, checksum good
    _put(data, fs[12], lay, XDI.EULER_ANGLES, b"\x01", at=7)  # pitch a hair off: passes
    _put(data, fs[15], lay, XDI.RATE_OF_TURN, b"\x7f\xc0\x00\x00", at=4)  # NaN gyr_y
    _put(data, fs[18], lay, XDI.ACCELERATION, b"\x7f\x80\x00\x00", at=0)  # inf acc_x
    _put(data, fs[21], lay, XDI.PACKET_COUNTER, b"\x00\x00")  # counter jumps back
    _put(data, fs[48], lay, XDI.STATUS_WORD, b"\x20")  # a reserved status bit
    _put(data, fs[50], lay, XDI.STATUS_WORD, b"\x02", at=3)  # the self-test bit drops
    _put(data, fs[52], lay, XDI.RATE_OF_TURN, b"\x18", at=8)  # a rate to ~1e-24
    head = f = fs[55]  # an identifier hit: the Euler angles' frame bits say NED
    head += lay.fields[XDI.EULER_ANGLES].offset - 2
    data[head] |= 0x04
    _resum(data, f, n)
    data[fs[27]:fs[27]] = encode_frame(MID.ERROR, b"\x29")  # a device error message
    del data[fs[24] + n - 6:fs[24] + n]  # a truncated frame
    del data[fs[30]:fs[33]]  # three frames lost
    data[fs[36]:fs[36]] = b"\x00\xfa\x12\xfa\xff\x36\x07"  # noise, false headers
    data[fs[40] + 3] = 0xFF  # a length byte hit: an extended header, too long
    data[fs[45]:fs[45] + 1] = b""  # a lost preamble
    return data


def _capture_driver(ticks_s: float, edits: list[tuple[float, float, Edit]]
                    ) -> tuple[MtiSerialDriver, MemorySerial, StepClock]:
    cap = read_capture(CAPTURE)
    d = dict(cap.devices["mti"].settings["config"])
    sync = SyncReplay(cap, {"mti": DeviceConfig("mti", "mti_serial", d, 0.5,
                                                device_signals("mti_serial", d))})
    port = sync.transports["mti"]
    for t0, t1, edit in edits:
        _edit(port.stream, t0, t1, edit)
    port._times[:] = [c[0] for c in port.stream]
    port._chunks[:] = [c[1] for c in port.stream]
    return sync.drivers["mti"], port, sync.clock  # type: ignore[return-value]


def silence(data: bytearray, fs: list[int], lay: FrameLayout) -> bytearray:
    """1.5 s without a byte: the driver times out and reconnects."""
    return data[:fs[2]]


@pytest.mark.parametrize("window", [1000, 37])
def test_span_reads_match_per_tick_reads_on_the_capture(window: int) -> None:
    edits: list[tuple[float, float, Edit]] = [(10.0, 11.0, damage), (20.0, 21.5, silence),
                                              (30.0, 31.0, damage)]
    ticks = 4000
    a = _play(*_capture_driver(40.0, edits), ticks, None)
    b = _play(*_capture_driver(40.0, edits), ticks, window)
    h = a[1][-1]
    assert h["bad_frames"] >= 10 and h["rejected_bytes"] > 0 and h["timeouts"] == 1
    assert h["reconnects"] == 1 and h["dropped_packets"] >= 3
    assert h["device_errors"] == 2
    assert not any(r[3] for r in a[0])  # the NaN gyro's frame is dropped, not half-read
    assert a[0] == b[0]
    assert a[1] == b[1]
    assert a[2] == b[2]


def test_span_reads_of_the_undamaged_capture_read_nearly_everything() -> None:
    drv, port, clock = _capture_driver(20.0, [])
    reader = MtiSpanReader(drv, port, PERIOD)
    dev = SyncDevice("mti", drv, port, lambda r: None, clock)
    k = stepped = 0
    while k < 2000:
        got = reader.read(k, k + 500)
        if got is not None:
            k += got.ticks
            continue
        clock.t = k * PERIOD
        dev.step(k * PERIOD)
        k, stepped = k + 1, stepped + 1
    assert stepped < 20  # the handshake's ticks
    assert drv.health.messages > 1900


def _synthetic(precision: str, extended: bool = False,
               extras: tuple[str, ...] = EXTRA_OUTPUTS,
               ) -> tuple[MtiSerialDriver, MemorySerial, StepClock]:
    """A measuring MTi with Euler angles and quaternion in one packet (and ``extras``),
    its stream made by the emulator (two chunks per frame, sometimes two frames per
    chunk; ``extended``: every frame with the extended length header, which the parser
    accepts too)."""
    clock = StepClock()
    drv = MtiSerialDriver(name="mti", orientation="euler+quaternion", precision=precision,
                          extra_outputs=extras, baudrate=921600, clock=clock,
                          timeout_clock=clock)
    emu = MtiEmulator(lambda t: (5 * math.sin(t), 30 * math.cos(t / 3), (70 * t) % 360 - 180),
                      outputs=tuple(drv.requested_outputs()))
    try:
        frames = b"".join(encode_frame(MID.MTDATA2, emu.packet(k), extended=extended)
                          for k in range(1500))
    finally:
        shutil.rmtree(emu.link.parent, ignore_errors=True)
    data = damage(bytearray(frames), _frames(frames)[400:500], _layout_of(frames, extended))
    stream, pos, k = [], 0, 0
    for f in [*_frames(data), len(data)]:
        if f > pos:
            t = 0.0042 + k * PERIOD + (0.006 if k % 7 == 3 else 0.0)
            cut = pos + 1 if k % 5 else f
            stream += [(t, bytes(data[pos:cut])), (t + 1e-4, bytes(data[cut:f]))]
            pos, k = f, k + 1
    port = MemorySerial([c for c in stream if c[1]], lambda b: None, "synthetic")
    drv._ser, drv.health.connected = port, True
    drv.health.extra["output_rate_hz"] = 100
    return drv, port, clock


def _layout_of(frames: bytes, extended: bool = False) -> FrameLayout:
    fs = _frames(frames)
    return FrameLayout(np.frombuffer(frames[fs[0]:fs[1]], np.uint8), 6 if extended else 4)


@pytest.mark.parametrize(("precision", "extended", "extras"), [
    ("float32", False, EXTRA_OUTPUTS), ("fp1632", False, EXTRA_OUTPUTS),
    ("fp1220", False, EXTRA_OUTPUTS), ("float64", False, EXTRA_OUTPUTS),
    ("float32", True, EXTRA_OUTPUTS), ("float32", False, ()), ("fp1632", True, ())])
def test_span_reads_match_per_tick_reads_with_the_quaternion(
        precision: str, extended: bool, extras: tuple[str, ...]) -> None:
    """With the rate of turn, acceleration and status word, and without (the default:
    their damage then has nothing to hit)."""
    a = _play(*_synthetic(precision, extended, extras), 1400, None)
    b = _play(*_synthetic(precision, extended, extras), 1400, 64)
    h = a[1][-1]
    assert h["inconsistent_frames"] >= 2 and h["bad_frames"] >= 6
    if not extras:  # no rate of turn in any reading (VALUE_KEYS[3] is gyr_x)
        assert all(r[2][3] == "-" for r in a[0])
    assert len(a[0]) > 1300
    assert a[0] == b[0]
    assert a[1] == b[1]
    assert a[2] == b[2]


def test_columns_decode_as_the_driver_decodes() -> None:
    drv, port, _ = _synthetic("fp1632")
    data = np.frombuffer(b"".join(c[1] for c in port.stream[:200]), np.uint8)
    run = clean_run(data, 2048, {})
    assert run is not None and len(run.rows) > 50
    assert run.layout.fields[XDI.EULER_ANGLES].precision == PRECISION_BY_NAME["fp1632"]
    cols = {k: FrameLayout.column(run.rows, f) for k, f in run.layout.fields.items()}
    for i, row in enumerate(run.rows):
        r = drv.decode(row[4:-1].tobytes())
        assert r is not None
        assert tuple(cols[XDI.EULER_ANGLES][i]) == (r.values["roll_deg"], r.values["pitch_deg"],
                                                    r.values["yaw_deg"])
        assert cols[XDI.PACKET_COUNTER][i] == r.values["packet_counter"]
        assert tuple(cols[XDI.RATE_OF_TURN][i]) == (r.values["gyr_x"], r.values["gyr_y"],
                                                    r.values["gyr_z"])
    assert FP1632 == run.layout.fields[XDI.QUATERNION].precision


def test_consistency_rule_on_columns_is_the_drivers() -> None:
    """Frame by frame against ``_consistent``, on frames near each of its limits."""
    rng = np.random.default_rng(7)
    n = 6000
    steps = rng.normal(0, 0.5, (n, 3))
    jumps = rng.random(n) < 0.15
    steps[jumps] = rng.uniform(-4, 4, (int(jumps.sum()), 3))
    e = np.cumsum(steps, axis=0) + rng.uniform(-150, 150, 3)
    e[:, [0, 2]] = np.remainder(e[:, [0, 2]] + 180.0, 360.0) - 180.0
    e[:, 1] = np.clip(e[:, 1], -91.0, 91.0)
    g = rng.normal(0, 0.3, (n, 3))
    g[::37, 1] = np.nan
    g[::53, 2] = 40.0
    acc = rng.normal(0, 20, (n, 3))
    acc[::61, 0] = 250.0
    g[::71, 0] = 1e-40  # next to zero
    g[::73, 1] = -3e-25
    acc[::89, 2] = -3e-39
    acc[::97, 1] = 0.0  # zero is not next to zero
    acc[::79, 0] = 2e-20  # (nor is this)
    noise = rng.normal(0, 3e-8, (n, 4))
    noise[::5] *= 1500.0  # about the agreement limit
    q = np.array([_quat(*row) for row in e]) + noise
    pc = np.cumsum(rng.choice([1] * 20 + [2, 60], n)).astype(np.int64) & 0xFFFF
    stf = (np.cumsum(np.diff(pc, prepend=0) * 100 + rng.choice([0] * 30 + [1, 2], n))
           + 2**32 - 5000) & 0xFFFFFFFF
    sw = np.full(n, 3, np.int64)
    sw[::43] |= 1 << 29  # reserved
    sw[::59] |= 1 << 17
    sw[::67] ^= 1  # the self-test bit flips
    sw[::101] |= 0x1800040  # defined bits come and go
    drv = MtiSerialDriver(orientation="euler+quaternion", clock=StepClock())
    drv.health.extra["output_rate_hz"] = 100
    want = [drv._consistent(int(pc[i]), int(stf[i]), tuple(e[i].tolist()),
                            tuple(g[i].tolist()), tuple(acc[i].tolist()), tuple(q[i].tolist()),
                            int(sw[i]))
            for i in range(n)]
    got = consistent(e, g, acc, q, pc, stf, None, 100.0, drv.MAX_GAP, sw)
    assert got.tolist() == want
    assert 0.1 < float(np.mean(want)) < 0.9
    # the default packet: no rate of turn, acceleration or status word to check
    drv._prev_frame = None
    want = [drv._consistent(int(pc[i]), int(stf[i]), tuple(e[i].tolist()), None, None,
                            tuple(q[i].tolist()), None)
            for i in range(n)]
    got = consistent(e, None, None, q, pc, stf, None, 100.0, drv.MAX_GAP, None)
    assert got.tolist() == want
    assert 0.1 < float(np.mean(want)) < 0.95


def _quat(r: float, p: float, y: float) -> tuple[float, ...]:
    from drivers.xsens.orientation import euler_deg_to_quat

    return euler_deg_to_quat(r, p, y)
