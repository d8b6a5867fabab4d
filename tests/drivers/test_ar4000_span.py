"""The AR4000 driver's span reads do what its per-tick reads do, reading for reading and
health after every tick: on the committed capture, and with what a laser and its line
do wrong (garbage, empty and overlong lines, a line that never ends, no target,
implausible and negative distances, digits lost or gained, a babbling stretch, a
silence)."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.acuity.ar4000 import DISTANCE, Ar4000Driver, parse_line
from drivers.acuity.span import Ar4000SpanReader, digit_lines
from drivers.base import TARGETS_TAKEN, Reading
from drivers.capture.format import read_capture
from shoveld.daemon.config import DeviceConfig, device_signals
from shoveld.replay.sync import MemorySerial, StepClock, SyncDevice, SyncReplay

from .span_play import play

CAPTURE = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e"
PERIOD = 0.01
BAD_LINES = {
    3: b"garbage\r\n", 5: b"\r\n", 7: b"1" * 40 + b"\r\n", 9: b"0.00\r\n", 11: b"25000\r\n",
    13: b"-120\r\n", 15: b"12a4\r\n", 17: b"7" * 40, 19: b"0\r\n", 23: b"1722\r\n",
    27: b"7\r\n", 31: b"72\r\n", **{n: b"1500\r\n" for n in range(35, 43)},
}
"""Line index (in a damaged stretch) -> what the laser sent instead: a digit gained or
lost is a jump; eight lines of something else in the beam are jumps (out of the
handle's reach when they start, and refused for ``other_target_s`` even when the reach
grows to them), and the handle's first line after them waits for the next to confirm
it (the last distance used is by then too old to measure from alone)."""


def _replace(stream: list[tuple[float, bytes]], t0: float, t1: float,
             new: Callable[[int], bytes | None]) -> list[tuple[float, bytes]]:
    """The n-th line ending in [t0, t1) (from 1) replaced by ``new(n)``, where not None."""
    out: list[tuple[float, bytes]] = []
    n = 0
    for t, data in stream:
        if t0 <= t < t1 and data.endswith(b"\n"):
            n += 1
            line = new(n)
            if line is not None:
                data = line
                if out and not out[-1][1].endswith(b"\n"):  # the line's first bytes
                    out[-1] = (out[-1][0], b"")
        out.append((t, data))
    return out


def _damage(stream: list[tuple[float, bytes]], t0: float, t1: float, babble: bool
            ) -> list[tuple[float, bytes]]:
    return _replace(stream, t0, t1,
                    lambda n: b"#!\r\n" if babble and n % 2 else BAD_LINES.get(n))


def _block(stream: list[tuple[float, bytes]], t0: float, t1: float, mm: int
           ) -> list[tuple[float, bytes]]:
    """Every line in [t0, t1) replaced by ``mm``: something that stays in the beam."""
    return _replace(stream, t0, t1, lambda n: f"{mm}\r\n".encode())


def _setup(edits: list[tuple[float, float, bool]], gap: tuple[float, float] | None = None,
           blocks: tuple[tuple[float, float, int], ...] = (), **laser: Any
           ) -> tuple[Ar4000Driver, MemorySerial, StepClock]:
    cap = read_capture(CAPTURE)
    d = dict(cap.devices["laser"].settings["config"])
    d["kind"] = "ar4000"
    d.update(laser)
    sync = SyncReplay(cap, {"laser": DeviceConfig("laser", "ar4000", d, 0.5,
                                                  device_signals("ar4000", d))})
    port: MemorySerial = sync.transports["laser"]
    stream = list(port.stream)
    for t0, t1, babble in edits:
        stream = _damage(stream, t0, t1, babble)
    for block in blocks:
        stream = _block(stream, *block)
    if gap is not None:
        stream = [c for c in stream if not gap[0] <= c[0] < gap[1]]
    port.stream[:] = stream
    port._times[:] = [c[0] for c in stream]
    port._chunks[:] = [c[1] for c in stream]
    return sync.drivers["laser"], port, sync.clock  # type: ignore[return-value]


def _play(driver: Ar4000Driver, port: MemorySerial, clock: StepClock, ticks: int,
          window: int | None) -> tuple[list[tuple[Any, ...]], list[dict[str, Any]]]:
    """Readings and health after every tick; span reads of up to ``window`` ticks
    wherever they can start (None: the per-tick reads only)."""
    readings: list[tuple[Any, ...]] = []
    at = [0]

    def sink(r: Reading) -> None:
        v = r.values.get(DISTANCE, math.nan)
        readings.append((at[0], r.t_host, "nan" if math.isnan(v) else v,
                         tuple(sorted(r.invalid)), r.values.get(TARGETS_TAKEN)))

    def span_rows(got: Any) -> None:
        taken = got.values.get(TARGETS_TAKEN)
        for i, tick in enumerate(got.reading_ticks.tolist()):
            v = float(got.values[DISTANCE][i])
            readings.append((tick, tick * PERIOD, "nan" if math.isnan(v) else v,
                             (DISTANCE,) if math.isnan(v) else (),
                             None if taken is None else float(taken[i])))

    dev = SyncDevice("laser", driver, port, sink, clock)
    reader = Ar4000SpanReader(driver, port, PERIOD) if window else None
    return readings, play(dev, reader, clock, ticks, window, PERIOD, span_rows, at)


@pytest.mark.parametrize("window", [1000, 41])
def test_span_reads_match_per_tick_reads(window: int) -> None:
    a = _play(*_setup([]), 3000, None)
    b = _play(*_setup([]), 3000, window)
    assert len(a[0]) > 1400
    assert a == b


@pytest.mark.parametrize("window", [1000, 41])
def test_span_reads_match_per_tick_reads_on_a_damaged_line(window: int) -> None:
    edits = [(5.0, 6.0, False), (8.0, 9.0, True), (15.0, 16.0, False)]
    a = _play(*_setup(edits, gap=(20.0, 21.5)), 3000, None)
    b = _play(*_setup(edits, gap=(20.0, 21.5)), 3000, window)
    h = a[1][-1]
    assert h["bad_frames"] > 20 and h["no_target"] >= 4 and h["implausible"] >= 4
    # per clean stretch 12: 1722, 7 and 72; the eight 1500s, none taken; the handle's
    # first line after them
    assert h["jumps"] >= 2 * 12
    assert not any(r[2] == 1.5 for r in a[0])
    assert h["timeouts"] == 1 and h["reconnects"] == 1
    assert any(x["babbling"] for x in a[1])
    assert a == b


@pytest.mark.parametrize("window", [1000, 41])
def test_span_reads_carry_the_count_of_targets_taken(window: int) -> None:
    """Something stays in the beam for 0.6 s twice, taken after 0.2 s each time, and
    the handle after it: four targets taken. The distances after each carry the count,
    from the span reads as from the per-tick reads."""
    blocks = ((5.0, 5.6, 1500), (12.0, 12.6, 9000))
    a = _play(*_setup([], blocks=blocks, other_target_s=0.2), 3000, None)
    b = _play(*_setup([], blocks=blocks, other_target_s=0.2), 3000, window)
    assert a[1][-1]["other_target"] == 4
    assert [r[4] for r in a[0] if r[1] > 20.0][-1] == 4.0
    assert a == b


def test_digit_lines_are_valued_as_parse_line_values_them() -> None:
    """Lines of 1 to 7 digits by numpy, the others left to parse_line: the same values."""
    rng = np.random.default_rng(5)
    lines = [b"0", b"0000000", b"7", b"1234567", b"12345678", b"", b"\r", b"12\r\r",
             b" 12", b"-12", b"1.5", b"12a", b"\x0012"]
    for _ in range(3000):
        n = int(rng.integers(1, 9))
        lines.append("".join(map(str, rng.integers(0, 10, n))).encode()
                     + (b"\r" if rng.random() < 0.7 else b""))
    data = b"".join(x + b"\n" for x in lines)
    arr = np.frombuffer(data, np.uint8)
    lf = np.flatnonzero(arr == 0x0A)
    starts = np.concatenate([[0], lf[:-1] + 1])
    for unit in (0.001, 0.0254):
        plain, vals = digit_lines(arr, starts, lf, unit)
        for x, p, v in zip(lines, plain.tolist(), vals.tolist(), strict=True):
            text = x[:-1] if x.endswith(b"\r") else x
            assert p == (text.isdigit() and 1 <= len(text) <= 7 and text.isascii())
            if p:
                assert v == parse_line(text, unit)
