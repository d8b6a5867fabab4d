"""The fixed-rate loop: absolute deadlines, no drift, overruns counted, grid kept."""

from __future__ import annotations

import math
import threading
import time

import pytest

from shoveld.daemon.clock import MonotonicClock, SimClock
from shoveld.daemon.loop import FixedRateLoop


def test_ticks_on_absolute_deadlines_without_drift() -> None:
    clock = SimClock(5.0)
    ticks: list[float] = []
    loop = FixedRateLoop(clock, 100.0, ticks.append)
    loop.run(threading.Event(), max_ticks=100_000)
    assert len(ticks) == 100_000
    # tick k is exactly t0 + k / rate (no accumulated rounding of a period sum)
    assert ticks[-1] == pytest.approx(5.0 + 99_999 / 100.0, abs=1e-9)
    assert ticks[12345] == 5.0 + 12345 * 0.01
    assert loop.stats.overruns == 0 and loop.stats.skipped == 0


def test_overruns_are_counted_and_the_grid_is_kept() -> None:
    work = {3: 0.025, 7: 0.0105}  # tick 3 overruns two periods, tick 7 just one
    clock = SimClock(0.0)
    ticks: list[float] = []

    def tick(t: float) -> None:
        ticks.append(t)
        clock._t += work.get(len(ticks) - 1, 0.001)

    loop = FixedRateLoop(clock, 100.0, tick)
    loop.run(threading.Event(), max_ticks=12)
    assert loop.stats.overruns == 2
    assert loop.stats.skipped == 1  # after tick 3 (ends 0.056) the 0.04 and 0.05 are late
    # every tick stays on the 10 ms grid
    assert all(abs(t * 100 - round(t * 100)) < 1e-9 for t in ticks)
    assert 0.05 in [round(t, 6) for t in ticks] and 0.04 not in [round(t, 6) for t in ticks]


def test_done_and_stop_end_the_loop() -> None:
    clock = SimClock(0.0)
    n = []
    loop = FixedRateLoop(clock, 50.0, lambda t: n.append(t))
    loop.run(threading.Event(), done=lambda: len(n) >= 7)
    assert len(n) == 7
    stop = threading.Event()
    stop.set()
    loop.run(stop)
    assert len(n) == 7


def test_live_clock_keeps_its_rate() -> None:
    """Half a second at 100 Hz on the host clock: about 50 ticks, small lateness."""
    clock = MonotonicClock()
    ticks: list[float] = []
    loop = FixedRateLoop(clock, 100.0, ticks.append)
    stop = threading.Event()
    t0 = time.monotonic()
    threading.Timer(0.5, stop.set).start()
    loop.run(stop)
    elapsed = time.monotonic() - t0
    assert abs(len(ticks) - 100 * elapsed) <= 3
    d = loop.stats.as_dict(100.0)
    assert d["jitter_ms"]["p50"] < 2.0  # generous: the machine is shared with other tests
    assert clock.wall(clock.now()) == pytest.approx(time.time(), abs=0.01)


def test_stop_wakes_a_sleeping_live_loop() -> None:
    clock = MonotonicClock()
    loop = FixedRateLoop(clock, 0.2, lambda t: None)  # a 5 s period
    stop = threading.Event()
    th = threading.Thread(target=loop.run, args=(stop,))
    th.start()
    time.sleep(0.1)
    t0 = time.monotonic()
    stop.set()
    th.join(2)
    assert not th.is_alive() and time.monotonic() - t0 < 0.5


def test_tick_work_percentiles_with_the_all_zero_shortcut() -> None:
    """The health message's tick work is what sorting the ring gives, whether the ring
    holds only zeros (a simulated clock: the shortcut) or a tick with work, inside the
    ring or just leaving it."""
    import random

    from shoveld.daemon.loop import LoopStats, percentiles

    rng = random.Random(3)
    for window in (1, 5, 50):
        for pattern in range(40):
            st = LoopStats(window=window)
            works: list[float] = []
            for _ in range(rng.randrange(1, 3 * window + 3)):
                w = rng.choice([0.0, 0.0, 0.0, rng.random() * 1e-3])
                works.append(w)
                st.record(0.0, w)
                recent = works[-window:]
                (w50, w99), wmax = percentiles(recent)
                want = {"p50": round(1e3 * w50, 3), "p99": round(1e3 * w99, 3),
                        "max": round(1e3 * wmax, 3)}
                got = st.as_dict(100.0, simulated=True)["tick_work_ms"]
                assert got == want and [repr(x) for x in got.values()] == \
                    [repr(x) for x in want.values()], (window, pattern, works)


def _percentiles_by_sorting(values: list[float], ps: tuple[float, ...]
                            ) -> tuple[list[float], float]:
    s = sorted(values)
    n = len(s)
    out = []
    for p in ps:
        pos = p / 100.0 * (n - 1)
        i = int(pos)
        frac = pos - i
        out.append(s[i] + (s[i + 1] - s[i]) * frac if frac and i + 1 < n else s[i])
    return out, s[-1]


@pytest.mark.parametrize("n", [1, 2, 3, 63, 64, 65, 100, 101, 3000, 4000, 4001])
def test_percentiles_are_those_of_the_sorted_list_bit_for_bit(n: int) -> None:
    """The partition (long lists) reads the same order statistics as a full sort: the
    same floats, whatever the ties, signs and percentiles asked."""
    import random

    from shoveld.daemon.loop import percentiles

    rng = random.Random(n)
    cases = [[rng.random() * 1e-3 for _ in range(n)],
             [float(rng.randrange(5)) for _ in range(n)],  # many ties
             [rng.gauss(0.0, 1.0) for _ in range(n)],
             [0.25] * n]
    for values in cases:
        for ps in ((50.0, 99.0), (0.0, 100.0), (12.5, 50.0, 90.0, 99.9)):
            got = percentiles(list(values), ps)
            assert got == _percentiles_by_sorting(values, ps)
            assert [math.copysign(1, x) for x in got[0]] == [
                math.copysign(1, x) for x in _percentiles_by_sorting(values, ps)[0]]
