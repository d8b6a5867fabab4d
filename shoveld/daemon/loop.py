"""The fixed-rate loop: absolute deadlines (no drift), overrun count, jitter statistics.

Tick ``k`` is due at ``t0 + k / rate``; the loop sleeps until that deadline and
calls ``tick(deadline)``, so errors never accumulate the way ``sleep(period)``
would. A tick that ends past the next deadline is an overrun: the ticks that can
no longer be made on time are skipped (counted), and the loop rejoins its grid
rather than bursting to catch up. Lateness of each wake-up against its deadline is
the jitter; a ring of recent values gives the percentiles on the health topic.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from shoveld.daemon.clock import Clock


class LoopStats:
    """Counters and recent timings of the loop (seconds)."""

    def __init__(self, window: int = 3000, keep_all: bool = False) -> None:
        self.ticks = 0
        self.overruns = 0
        self.skipped = 0
        self.max_late_s = 0.0
        self._late = np.zeros(window)
        self._work = np.zeros(window)
        self._n = 0
        self.keep_all = keep_all
        self.all_late: list[float] = []
        self.all_work: list[float] = []
        self.started_mono = time.monotonic()
        self.last_tick_mono = math.nan

    def record(self, late_s: float, work_s: float) -> None:
        i = self._n % len(self._late)
        self._late[i] = late_s
        self._work[i] = work_s
        self._n += 1
        self.ticks += 1
        if late_s > self.max_late_s:
            self.max_late_s = late_s
        if self.keep_all:
            self.all_late.append(late_s)
            self.all_work.append(work_s)
        self.last_tick_mono = time.monotonic()

    def recent(self) -> tuple[np.ndarray, np.ndarray]:
        n = min(self._n, len(self._late))
        return self._late[:n], self._work[:n]

    def as_dict(self, rate_hz: float, simulated: bool = False) -> dict[str, Any]:
        late, work = self.recent()
        elapsed = time.monotonic() - self.started_mono
        d: dict[str, Any] = {
            "rate_hz": rate_hz,
            "ticks": self.ticks, "overruns": self.overruns, "skipped_ticks": self.skipped,
            "actual_rate_hz": round(self.ticks / elapsed, 2) if elapsed > 0 else None,
        }
        if len(late) and not simulated:
            p50, p99 = np.percentile(late, [50, 99])
            d["jitter_ms"] = {"p50": round(1e3 * p50, 3), "p99": round(1e3 * p99, 3),
                              "max": round(1e3 * float(late.max()), 3),
                              "max_since_start": round(1e3 * self.max_late_s, 3)}
        if len(work):
            w50, w99 = np.percentile(work, [50, 99])
            d["tick_work_ms"] = {"p50": round(1e3 * w50, 3), "p99": round(1e3 * w99, 3),
                                 "max": round(1e3 * float(work.max()), 3)}
        return d


class FixedRateLoop:
    """Calls ``tick(t)`` at ``rate_hz`` on ``clock`` until stopped or ``done()``."""

    def __init__(self, clock: Clock, rate_hz: float, tick: Callable[[float], None],
                 stats: LoopStats | None = None) -> None:
        if not rate_hz > 0:
            raise ValueError("rate_hz must be > 0")
        self.clock = clock
        self.rate_hz = rate_hz
        self.period = 1.0 / rate_hz
        self.tick = tick
        self.stats = stats or LoopStats()
        self.behind_s = 0.0
        """How far the current tick started after its deadline (watchdog health)."""

    def run(self, stop: threading.Event, done: Callable[[], bool] | None = None,
            start: float | None = None, max_ticks: int | None = None) -> None:
        clock, period, stats = self.clock, self.period, self.stats
        t0 = clock.now() if start is None else start
        k = 0
        while not stop.is_set():
            deadline = t0 + k * period
            if not clock.sleep_until(deadline, stop):
                break
            woke = clock.now()
            late = woke - deadline
            self.behind_s = late
            self.tick(deadline)
            end = clock.now()
            stats.record(late, end - woke)
            k += 1
            if max_ticks is not None and k >= max_ticks:
                break
            if done is not None and done():
                break
            next_deadline = t0 + k * period
            if end > next_deadline:
                stats.overruns += 1
                missed = int((end - next_deadline) / period)
                if missed:
                    stats.skipped += missed
                    k += missed
