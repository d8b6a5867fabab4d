"""The fixed-rate loop: absolute deadlines (no drift), overrun count, jitter statistics,
and an optional phase lock to a master sensor's stream.

Tick ``k`` is due at ``base + k / rate``; the loop sleeps until that deadline and
calls ``tick(deadline)``, so errors never accumulate the way ``sleep(period)``
would. A tick that ends past the next deadline is an overrun: the ticks that can
no longer be made on time are skipped (counted), and the loop rejoins its grid
rather than bursting to catch up. Lateness of each wake-up against its deadline is
the jitter; a ring of recent values gives the percentiles on the health topic.

With a :class:`PhaseLock` (``[loop] sync = "<device>"``), ``base`` is nudged after
each tick so that ticks fall ``delay_s`` after the master device's readings arrive
(a first-order software PLL with a bounded correction per tick): a reading of the
master then waits about ``delay_s`` for its tick instead of up to a whole period.
The loop still sleeps only until its own deadlines; if the master stops, the grid
simply stays where it is (free-running) until readings come back.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from shoveld.daemon.clock import Clock


def percentiles(values: list[float], ps: tuple[float, ...] = (50.0, 99.0)
                ) -> tuple[list[float], float]:
    """(percentiles ``ps`` with linear interpolation, as numpy's default; maximum) of a
    non-empty list of numbers (no NaN).

    Only the order statistics the interpolation reads are put in place: a short list
    is sorted, a long one is copied into an array and partitioned at them (the health
    message's eight rings of 3,000-4,000 floats, once a second in the live daemon's
    loop thread: 90 against 200 us a ring, the same floats and the same arithmetic)."""
    n = len(values)
    pos = [p / 100.0 * (n - 1) for p in ps]
    if n < 64:
        s: Any = sorted(values)
    else:
        a = np.array(values, dtype=float)
        ks = sorted({k for q in pos for k in (int(q), min(int(q) + 1, n - 1))} | {n - 1})
        a.partition(ks)
        s = dict(zip(ks, a[ks].tolist(), strict=True))  # Python floats, as the list held
        s[-1] = s[n - 1]
    out = []
    for q in pos:
        i = int(q)
        frac = q - i
        out.append(s[i] + (s[i + 1] - s[i]) * frac if frac and i + 1 < n else s[i])
    return out, s[-1]


class LoopStats:
    """Counters and recent timings of the loop (seconds)."""

    def __init__(self, window: int = 3000, keep_all: bool = False) -> None:
        self.ticks = 0
        self.overruns = 0
        self.skipped = 0
        self.max_late_s = 0.0
        self._window = window
        self._late = [0.0] * window
        self._work = [0.0] * window
        self._i = 0
        self._n = 0
        self._work_at = 0
        """``_n`` at the last tick with work other than zero: a simulated clock does not
        move during a tick, so there all of it is zero and the health message's
        percentiles need no sort (half its cost in a replay)."""
        self.keep_all = keep_all
        self.all_late: list[float] = []
        self.all_work: list[float] = []
        self.started_mono = time.monotonic()

    def record(self, late_s: float, work_s: float) -> None:
        """One tick's lateness and work (called at every tick: kept to plain stores)."""
        i = self._i
        self._late[i] = late_s
        self._work[i] = work_s
        i += 1
        self._i = 0 if i == self._window else i
        self._n += 1
        if work_s:
            self._work_at = self._n
        self.ticks += 1
        if late_s > self.max_late_s:
            self.max_late_s = late_s
        if self.keep_all:
            self.all_late.append(late_s)
            self.all_work.append(work_s)

    def recent(self) -> tuple[list[float], list[float]]:
        n = min(self._n, self._window)
        return self._late[:n], self._work[:n]

    def as_dict(self, rate_hz: float, simulated: bool = False) -> dict[str, Any]:
        n = min(self._n, self._window)
        full = n == self._window
        # the rings themselves once full (percentiles sorts its own copy), and the
        # lateness only where it is shown: a replay's health message copied 3,000
        # floats twice more than it used
        work = self._work if full else self._work[:n]
        elapsed = time.monotonic() - self.started_mono
        d: dict[str, Any] = {
            "rate_hz": rate_hz,
            "ticks": self.ticks, "overruns": self.overruns, "skipped_ticks": self.skipped,
            "actual_rate_hz": round(self.ticks / elapsed, 2) if elapsed > 0 else None,
        }
        if n and not simulated:
            (p50, p99), vmax = percentiles(self._late if full else self._late[:n])
            d["jitter_ms"] = {"p50": round(1e3 * p50, 3), "p99": round(1e3 * p99, 3),
                              "max": round(1e3 * vmax, 3),
                              "max_since_start": round(1e3 * self.max_late_s, 3)}
        if work:
            (w50, w99), wmax = (((0.0, 0.0), 0.0) if self._work_at <= self._n - n
                                else percentiles(work))  # (all zero: what it would give)
            d["tick_work_ms"] = {"p50": round(1e3 * w50, 3), "p99": round(1e3 * w99, 3),
                                 "max": round(1e3 * wmax, 3)}
        return d


class PhaseLock:
    """A first-order software PLL: keeps the loop's ticks a short delay after the
    master's readings arrive.

    ``ref()`` returns the arrival time (loop clock) of the master's newest reading, or
    None; ``history(t)``, if given, the arrival times of the readings after ``t`` (so
    that a late reading superseded before any tick saw it still counts in the jitter).
    After each tick, a new master reading gives the phase error
    ``e = wrap(deadline - arrival - delay_s)`` modulo the loop period (positive: the
    ticks come later than wanted); the loop's grid moves by ``-gain * e``, clipped to
    ``max_step_s`` per tick. Clipping makes the lock robust: a reading delayed by the
    host (a busy CPU, a late thread) moves the grid by at most ``max_step_s``, so the
    lock settles on the typical arrival phase, not the outliers. A master that streams
    at the loop rate or an integer fraction of it has one arrival phase modulo the
    period; the loop's rate itself never changes, so a master clock that runs a few
    ppm fast or slow leaves a constant phase offset of (drift per tick) / ``gain``
    (0.5 us per tick at 50 ppm and 100 Hz: 5 us).

    The delay is ``delay_s`` at least. A reading that arrives later than the delay
    misses its tick and waits a whole period, so while locked the delay is widened to
    cover the arrival jitter the lock measures: every 100 readings it becomes the
    spread between the median arrival and the latest 0.5 % of the last ``window``
    arrivals, plus ``margin_s``, between ``delay_s`` and half a period.

    States: ``free_running`` (no master reading yet, or none for ``lost_after_s``: no
    corrections, the loop keeps its last phase), ``acquiring`` (readings, error still
    large), ``locked`` (mean absolute error under a tenth of a period).
    """

    TAIL = 0.005
    """Share of the master's readings the adaptive delay lets miss their tick."""

    def __init__(self, period_s: float, ref: Callable[[], float | None], *,
                 history: Callable[[float], Sequence[float]] | None = None,
                 delay_s: float = 0.001, gain: float = 0.1, max_step_s: float | None = None,
                 lost_after_s: float | None = None, window: int = 1000,
                 adaptive: bool = True, margin_s: float = 0.0003) -> None:
        if not 0 <= delay_s < period_s:
            raise ValueError("delay_s must be in [0, period)")
        if not 0 < gain <= 1:
            raise ValueError("gain must be in (0, 1]")
        self.period = period_s
        self.ref = ref
        self.history = history
        self.min_delay = delay_s
        self.delay = delay_s
        """The delay in use (``delay_s`` or wider, see the class)."""
        self.adaptive = adaptive
        self.margin = margin_s
        self.gain = gain
        self.max_step = period_s / 50.0 if max_step_s is None else max_step_s
        self.lost_after = 10.0 * period_s if lost_after_s is None else lost_after_s
        self.state = "free_running"
        self.corrections = 0
        self.shift_s = 0.0
        """Total movement of the grid since start (seconds, + = later)."""
        self.last_error_s = math.nan
        self.lost_count = 0
        self.late = 0
        """Master readings that arrived after the tick locked to them (they wait a period)."""
        self._mean_abs = period_s / 4.0
        self._last_ref: float | None = None
        self._last_new = -math.inf
        self._window = window
        self._err = [0.0] * window
        self._phase = [0.0] * window
        """How long before its tick each recent reading arrived (negative: after it)."""
        self._i = 0
        self._n = 0
        self._pn = 0
        self._center = delay_s
        """Typical time from a reading to its tick (the median of the recent ones)."""

    def correction(self, deadline: float, now: float) -> float:
        """How far to move the grid after the tick due at ``deadline`` (seconds)."""
        a = self.ref()
        last = self._last_ref
        if a is None or a == last:
            if self.state != "free_running" and now - self._last_new > self.lost_after:
                self.state = "free_running"
                self.lost_count += 1
                self._mean_abs = 0.25 * self.period  # settle again before "locked"
                self._pn = 0  # and measure the jitter afresh
                self._center = self.delay
            return 0.0
        self._last_ref = a
        self._last_new = now
        if now - a > self.lost_after:  # an old reading (before a gap): nothing to lock on
            return 0.0
        period = self.period
        half = 0.5 * period
        locked = self.state == "locked"
        new = (self.history(last) if self.history is not None and last is not None
               else None) or (a,)
        c = self._center
        for x in new:  # how long before the tick each new reading came (< 0: after it),
            # within half a period of the typical arrival (further is ambiguous)
            before = (deadline - x - c + half) % period - half + c
            if before < 0.0:
                self.late += 1  # missed the tick it was meant for: waited a period
            if locked:  # the arrival jitter, once the lock has settled
                self._phase[self._pn % self._window] = before
                self._pn += 1
                if self.adaptive and self._pn % 100 == 0:
                    self._adapt_delay()
        e = (deadline - a - self.delay + half) % period - half
        self.last_error_s = e
        i = self._i
        self._err[i] = e
        self._i = 0 if i + 1 == self._window else i + 1
        self._n += 1
        self._mean_abs += 0.05 * (abs(e) - self._mean_abs)
        self.state = "locked" if self._mean_abs < 0.1 * period else "acquiring"
        step = self.gain * e
        ms = self.max_step
        if step > ms:
            step = ms
        elif step < -ms:
            step = -ms
        self.corrections += 1
        self.shift_s -= step
        return -step

    def _adapt_delay(self) -> None:
        n = min(self._pn, self._window)
        if n < 200:
            return
        ph = sorted(self._phase[:n])
        self._center = med = ph[n // 2]
        tail = med - ph[int(self.TAIL * (n - 1))]  # how much later the late ones come
        self.delay = min(max(self.min_delay, tail + self.margin), 0.5 * self.period)

    def as_dict(self) -> dict[str, Any]:
        n = min(self._n, self._window)
        d: dict[str, Any] = {"state": self.state, "delay_ms": round(1e3 * self.delay, 3),
                             "min_delay_ms": round(1e3 * self.min_delay, 3),
                             "corrections": self.corrections,
                             "shift_ms": round(1e3 * self.shift_s, 3),
                             "lost": self.lost_count, "late": self.late}
        if n:
            (p50, p99), _ = percentiles([abs(e) for e in self._err[:n]])
            d["phase_error_ms"] = {"p50": round(1e3 * p50, 3), "p99": round(1e3 * p99, 3)}
        pn = min(self._pn, self._window)
        if pn:
            d["late_pct"] = round(100.0 * sum(1 for x in self._phase[:pn] if x < 0.0) / pn, 2)
        return d


class FixedRateLoop:
    """Calls ``tick(t)`` at ``rate_hz`` on ``clock`` until stopped or ``done()``."""

    def __init__(self, clock: Clock, rate_hz: float, tick: Callable[[float], None],
                 stats: LoopStats | None = None, phase_lock: PhaseLock | None = None) -> None:
        if not rate_hz > 0:
            raise ValueError("rate_hz must be > 0")
        self.clock = clock
        self.rate_hz = rate_hz
        self.period = 1.0 / rate_hz
        self.tick = tick
        self.stats = stats or LoopStats()
        self.phase_lock = phase_lock
        self.behind_s = 0.0
        """How far the current tick started after its deadline (watchdog health)."""
        self.base: float | None = None
        """Tick ``k`` is due at ``base + k * period`` while running (None otherwise)."""

    def tick_hint(self) -> tuple[float, float] | None:
        """(a tick deadline, the period) of the running grid, for drivers that time their
        polls to land just before ticks (:class:`drivers.base.TickHint`); any thread."""
        base = self.base
        return None if base is None else (base, self.period)

    def run(self, stop: threading.Event, done: Callable[[], bool] | None = None,
            start: float | None = None, max_ticks: int | None = None) -> None:
        base = self.clock.now() if start is None else start
        self.base = base
        try:
            self._run(stop, done, max_ticks, base)
        finally:
            self.base = None

    def _run(self, stop: threading.Event, done: Callable[[], bool] | None,
             max_ticks: int | None, base: float) -> None:
        clock, period, stats = self.clock, self.period, self.stats
        pll = self.phase_lock
        # bound once, not looked up at every tick (a replay runs this loop thousands of
        # times a second, where the lookups were a tenth of a microsecond a tick)
        stopped, sleep_until, now = stop.is_set, clock.sleep_until, clock.now
        tick, record = self.tick, stats.record
        k = 0
        while not stopped():
            deadline = base + k * period
            if not sleep_until(deadline, stop):
                break
            woke = now()
            late = woke - deadline
            self.behind_s = late
            tick(deadline)
            end = now()
            record(late, end - woke)
            k += 1
            if max_ticks is not None and k >= max_ticks:
                break
            if done is not None and done():
                break
            if pll is not None:
                base += pll.correction(deadline, end)
                self.base = base
            next_deadline = base + k * period
            if end > next_deadline:
                stats.overruns += 1
                missed = int((end - next_deadline) / period)
                if missed:
                    stats.skipped += missed
                    k += missed
