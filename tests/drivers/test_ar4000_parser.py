"""Property tests: garbage into the AR4000 line parser never crashes and never yields
a distance from a malformed line."""

from __future__ import annotations

import random
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.acuity.ar4000 import Ar4000Config, Ar4000Driver, LineSplitter, parse_line
from drivers.base import TARGETS_TAKEN, Reading

WELL_FORMED = re.compile(rb"^ *-?\d{1,7}(\.\d{1,4})? *$")


@given(st.binary(max_size=64))
def test_parse_line_never_crashes_and_only_accepts_well_formed(line: bytes) -> None:
    v = parse_line(line, 0.001)
    if WELL_FORMED.match(line) is None:
        assert v is None
    else:
        assert v is not None


@given(st.integers(0, 99999), st.integers(0, 99))
def test_well_formed_inch_lines_round_trip(whole: int, frac: int) -> None:
    line = f"{whole}.{frac:02d}".encode()
    v = parse_line(line, 0.0254)
    assert v is not None
    assert abs(v - (whole + frac / 100) * 0.0254) < 1e-9


@given(st.binary(max_size=40).filter(lambda b: any(c not in b" -.0123456789" for c in b)))
def test_any_foreign_byte_makes_a_line_malformed(line: bytes) -> None:
    assert parse_line(line, 0.001) is None


@given(st.lists(st.binary(max_size=50), max_size=30))
def test_splitter_never_keeps_more_than_max_line(chunks: list[bytes]) -> None:
    s = LineSplitter(max_line=32)
    for c in chunks:
        for line in s.feed(c):
            assert b"\n" not in line
        assert len(s._buf) <= 32


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=80), max_size=20))
def test_driver_parse_of_garbage_emits_only_good_distances(chunks: list[bytes]) -> None:
    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/null"))
    out: list[Reading] = []
    for c in chunks:
        drv._parse(c, out.append, 0.0)
    for r in out:
        if r.invalid:
            assert r.values == {}
        else:
            (d,) = r.values.values()
            assert 0.0 < d <= drv.config.max_plausible_m
    # every byte of a malformed line is accounted for
    assert drv.health.rejected_bytes >= drv.health.bad_frames


@given(st.lists(st.sampled_from([b"12.34\r\n", b"0\r\n", b"#\x00junk\r\n", b"\xff\xfe",
                                 b"5", b".", b"\r\n", b"1234567\r\n"]), max_size=40))
def test_stream_splitting_is_independent_of_chunking(parts: list[bytes]) -> None:
    stream = b"".join(parts)
    whole = LineSplitter(1024).feed(stream)
    s = LineSplitter(1024)
    pieces: list[bytes] = []
    for i in range(0, len(stream), 3):
        pieces += s.feed(stream[i:i + 3])
    assert pieces == whole


def test_the_tail_of_an_overlong_line_is_not_a_distance() -> None:
    from drivers.acuity.ar4000 import LineSplitter, parse_line

    s = LineSplitter(max_line=32)
    lines = s.feed(b"9" * 40) + s.feed(b"45\r\n01234.5\r\n") + s.feed(b"7" * 50 + b"\r\n")
    got = [parse_line(x, 0.001) for x in lines]
    assert got.count(None) == 3 and got[-2] == pytest.approx(1.2345)
    assert s.overflow_bytes == 40 + len(b"45\r\n") + len(b"7" * 50 + b"\n")


def test_a_distance_is_used_only_if_the_handle_could_have_moved_there() -> None:
    """The protocol has no checksum: a corrupted digit is stopped by the crowd's speed
    (3 m/s, + 10 mm; 70 mm in one 20 ms sample), measured from the last distance used;
    something else in the beam stays refused for ``other_target_s`` (here 2 s)."""
    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/null", sample_interval_us=20000,
                                             other_target_s=2.0))
    used: list[float | None] = []
    counts: list[float | None] = []

    def line(mm: int, t: float) -> None:
        out: list[Reading] = []
        drv._parse(f"{mm}\r\n".encode(), out.append, t)
        (r,) = out
        used.append(r.values.get("distance_m"))
        counts.append(r.values.get(TARGETS_TAKEN))

    line(4910, 0.00)  # nothing to follow from yet
    line(4912, 0.02)
    line(4980, 0.04)  # 68 mm in 20 ms: 3.4 m/s, within the noise
    line(5980, 0.06)  # a thousands digit corrupted
    line(5980, 0.08)  # twice: the lines agree, but not with the last distance used
    line(4990, 0.10)  # 10 mm from 4980 in 60 ms
    line(5100, 0.12)  # 110 mm in 20 ms
    assert used == [None, 4.912, 4.98, None, None, 4.99, None]
    assert drv.health.extra["jumps"] == 3
    line(0, 0.14)  # no target for a sample: the handle went on moving meanwhile
    line(5030, 0.16)
    line(5990, 0.18)
    assert used[-2:] == [5.03, None] and drv.health.extra["jumps"] == 4
    for i in range(6):  # no target for 6 samples (0.12 s): the handle moves 0.5 m at most
        line(0, 0.20 + 0.02 * i)
    line(7000, 0.32)  # 2 m away: something else in the beam, refused
    line(7010, 0.34)  # and so is what follows it, though the handle's reach grows
    assert used[-2:] == [None, None] and drv.health.extra["jumps"] == 6
    for i in range(50):  # no target for a second: the handle may be anywhere by 3 m
        line(0, 0.36 + 0.02 * i)
    line(7000, 1.36)  # within reach, but the last distance used is old: confirmed by the
    line(7010, 1.38)  # next line (nothing to follow from: no jump)
    line(7030, 1.40)
    assert used[-3:] == [None, 7.01, 7.03] and drv.health.extra["jumps"] == 6
    assert drv.health.extra["other_target"] == 0
    for i in range(60):  # something else in the beam for 1.2 s (a rope, dust)
        line(2000 + i % 3, 1.42 + 0.02 * i)
    assert used[-60:] == [None] * 60 and drv.health.extra["jumps"] == 66
    line(7080, 2.62)  # the handle again, 1.2 s after the last distance used: within
    line(7085, 2.64)  # reach, confirmed by the next line
    assert used[-2:] == [None, 7.085] and drv.health.extra["jumps"] == 67
    assert drv.health.extra["other_target"] == 0
    for i in range(101):  # something else that stays: taken as the target after 2 s
        line(2000 + i % 3, 2.66 + 0.02 * i)
    assert used[-101:-1] == [None] * 100 and used[-1] == pytest.approx(2.001, abs=1e-12)
    assert drv.health.extra["other_target"] == 1 and drv.health.extra["jumps"] == 167
    # the distances from then on say so (the loop marks the tick: the pass is not weighed)
    assert counts[-1] == 1.0 and counts[:-1] == [None] * (len(counts) - 1)
    line(7080, 4.68)  # ... and the handle is then what is out of reach, for a while
    assert used[-1] is None and drv.health.extra["jumps"] == 168


def test_something_in_the_beam_stays_refused_when_its_lines_come_in_bursts() -> None:
    """A busy host reads the port late: ten lines at a time, 0.2 s apart, each stamped
    with its chunk's time. The rule times each line by when it was sent (the chunk's
    time, less a sample interval for each line after it), so something else in the beam
    stays refused across the chunks until it has held for ``other_target_s``, and is
    then counted as taken. (Until the twenty-eighth session the rule timed lines by
    their chunk: each chunk's first line looked 0.2 s after the line before, the thing
    was forgotten, and taken uncounted once the handle's reach had grown to it.)"""
    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/null", sample_interval_us=20000,
                                             other_target_s=2.0))
    used: list[float | None] = []

    def chunk(mms: list[int], t: float) -> None:
        out: list[Reading] = []
        drv._parse(b"".join(f"{mm}\r\n".encode() for mm in mms), out.append, t)
        assert len(out) == len(mms)
        used.extend(r.values.get("distance_m") for r in out)

    for k in range(10):  # the handle, line by line
        chunk([4900 + k], 0.02 * k)
    assert used[1:] == [pytest.approx(4.901 + 0.001 * k) for k in range(9)]
    for k in range(12):  # something 1.9 m short of it, in chunks 0.2 s apart: its
        chunk([3000 + i % 3 for i in range(10)], 0.4 + 0.2 * k)  # lines sent from 0.22 s
    # refused for the 2 s after its first line was sent (100 lines), then taken, counted
    assert used[10:110] == [None] * 100
    assert used[111:] == [pytest.approx(3.0 + 0.001 * (j % 10 % 3)) for j in range(101, 120)]
    assert drv.health.extra["other_target"] == 1


@pytest.mark.parametrize(("step_mm", "catch_up"), [(50, (4, 7)), (58, (33, 37))])
def test_a_corrupted_distance_used_does_not_lock_out_a_fast_handle(
        step_mm: int, catch_up: tuple[int, int]) -> None:
    """A corrupted line just inside the bound becomes the last distance used, 24 mm
    from the one before and 74-82 mm behind the handle, which crowds away at 2.5 or 2.9
    m/s: the handle's lines are out of reach at first (by 54 or 70 mm), but never
    something else in the beam (they are within two samples' reach of it), and are used
    again once the reach, growing 10 or 2 mm a sample faster than the handle moves, has
    caught up with them."""
    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/null", sample_interval_us=20000))
    used: list[float | None] = []

    def line(mm: float, t: float) -> None:
        out: list[Reading] = []
        drv._parse(f"{round(mm)}\r\n".encode(), out.append, t)
        used.append(out[0].values.get("distance_m"))
        assert drv._other is None

    line(4000, 0.00)
    line(4000, 0.02)
    line(4000 + step_mm, 0.04)
    line(4000 + step_mm - 24, 0.06)  # a corrupted line; the handle is 2 steps on
    for k in range(1, 60):
        line(4000 + step_mm * (2 + k), 0.06 + 0.02 * k)
    assert used[3] == pytest.approx((4000 + step_mm - 24) / 1000)
    first = next(i for i in range(4, len(used)) if used[i] is not None)
    assert catch_up[0] <= first - 4 <= catch_up[1] and all(u is not None for u in used[first:])
    assert drv.health.extra["other_target"] == 0


def test_the_jump_keys_are_checked() -> None:
    with pytest.raises(ValueError, match="'max_speed_mps' must be > 0"):
        Ar4000Config.from_config({"port": "/dev/null", "max_speed_mps": 0})
    with pytest.raises(ValueError, match="'jump_noise_m' must be >= 0"):
        Ar4000Config.from_config({"port": "/dev/null", "jump_noise_m": -0.01})
    with pytest.raises(ValueError, match="'max_speed_mps' must be a number"):
        Ar4000Config.from_config({"port": "/dev/null", "max_speed_mps": "fast"})


def test_a_laser_that_keeps_jumping_is_named_on_the_health_topic() -> None:
    from shoveld.daemon.health import problems

    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/null", sample_interval_us=20000))
    for i in range(31):  # after the handle, every other line 2 m nearer (14 of them)
        mm = 2000 if i > 2 and i % 2 == 0 else 4000 + i
        drv._parse(f"{mm}\r\n".encode(), lambda r: None, 0.02 * i)
    assert drv.health.extra["jumping"] and drv.health.extra["jumps"] == 14
    said = problems({"laser": {"state": "ok", **drv.health.extra}}, {}, {"open": True}, {})
    assert said == ["laser: jumping (distances the handle cannot reach: dirty target, "
                    "something in the beam?)"]
    for i in range(31, 81):  # the beam clear again: the window forgets the jumps
        drv._parse(f"{4000 + i}\r\n".encode(), lambda r: None, 0.02 * i)
    assert not drv.health.extra["jumping"]


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1),
       st.lists(st.tuples(st.sampled_from(["stray", "block", "no target", "digit"]),
                          st.integers(1, 200)), max_size=10))
def test_the_handle_is_followed_through_strays_blocks_and_corrupted_digits(
        seed: int, events: list[tuple[str, int]]) -> None:
    """A handle crowding at up to 2.1 m/s (the simulated machines' peak), its laser lines
    disturbed by events at least ten clean lines apart: a stray line 0.25-3 m off, a
    block of up to 4 s of something that stays 0.25-3 m off, up to 5 no-target lines, a
    corrupted digit. Every distance used is the handle's, within what a corrupted line
    just inside the bound can be off (130 mm), and the handle is used again within 20
    lines (0.4 s) of every event's end. A block stays where the handle does not come
    within 0.15 m of it, in the block or the second after it: where the handle lingers
    at the place of something that was in the beam, its lines cannot be told from that
    thing's (they are refused, up to ``other_target_s``), and something else after that
    may then be taken as the handle (docs/drivers-ar4000.md)."""
    rng = random.Random(seed)
    n, dt = 2500, 0.02
    x, v, truth = rng.uniform(1.0, 4.0), 0.0, []
    for _ in range(n):  # a crowd whose speed wanders, kept inside the stroke
        v = max(-2.1, min(2.1, v + rng.uniform(-0.15, 0.15)))
        if not 0.3 <= x + v * dt <= 4.8:
            v = -v
        x += v * dt
        truth.append(x)
    lines = [f"{round(t * 1000) + rng.randint(-2, 2)}" for t in truth]
    ends: list[int] = []
    at = 20
    for kind, k in events:
        if kind == "no target":
            k = 1 + k % 5
        elif kind in ("stray", "digit"):
            k = 1
        if at + k + 10 >= n - 30:
            break
        off = rng.randint(250, 3000) / 1000
        place = truth[at] + (off if truth[at] - off < 0.1 or rng.random() < 0.5 else -off)
        if kind == "block" and any(abs(t - place) < 0.15 for t in truth[at:at + k + 50]):
            continue
        for i in range(at, at + k):
            if kind == "no target":
                lines[i] = "0"
            elif kind == "digit":
                s = list(lines[i])
                j = rng.randrange(len(s))
                s[j] = str((int(s[j]) + rng.randint(1, 9)) % 10)
                lines[i] = "".join(s).lstrip("0") or "0"
            else:
                lines[i] = str(round(place * 1000) + rng.randint(-2, 2))
        ends.append(at + k)
        at += k + 10 + rng.randint(0, 100)
    drv = Ar4000Driver("laser", Ar4000Config(port="/dev/null", sample_interval_us=20000))
    used: list[float | None] = []
    for i, text in enumerate(lines):
        out: list[Reading] = []
        drv._parse(f"{text}\r\n".encode(), out.append, i * dt)
        used.append(out[0].values.get("distance_m"))
    for i, d in enumerate(used):
        assert d is None or abs(d - truth[i]) <= 0.132, (i, d, truth[i])
    for e in ends:
        assert any(d is not None for d in used[e:e + 20]), e
    assert drv.health.extra["other_target"] == 0
