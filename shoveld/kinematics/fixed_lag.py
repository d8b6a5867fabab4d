"""Fixed-lag zero-phase joint rates for the payload equations of the live loop.

The causal Kalman filter's acceleration lags by ~0.15 s, and because a lift
starts and ends with the acceleration changing, that lag does not average out
over a pass: it biased payloads by -0.5 % to +0.4 % of the load depending on the
window (bench/kinematics_tradeoff.py). Evaluating the equations of motion half a
window late, with a zero-phase Savitzky-Golay fit (the payload's own, recorded in the
params: 1.5 s by default) and the currents of that same instant, removes the bias at
the price of a delay of half a window (0.75 s), which the operator never sees (the
pass is final at the dump, seconds later).

A short hole in the stream (ticks the loop skipped on a busy host, a sample with an
unknown angle) does not restart the window: the windows over it are fitted to the
samples they have, so a lift keeps its payload equations instead of losing a whole
window (1.5 s) for one late tick. A hole longer than ``max_gap_s`` restarts.
"""

from __future__ import annotations

import math
from collections import deque
from functools import lru_cache
from itertools import islice
from typing import Generic, TypeVar

import numpy as np

from shoveld.kinematics import window_samples
from shoveld.kinematics.savgol import savgol_coeffs

T = TypeVar("T")

SLIDE_WINDOWS = 8
"""The buffer the window's array slides along, in windows: the whole window is
written anew once per this many windows' worth of rows (or after a pause)."""

MAX_GAP_S = 0.1
"""The longest hole in the angle stream the fixed-lag fit bridges (5 ticks at 50 Hz)."""


class FixedLagSavgol(Generic[T]):
    """Push samples in; get (tag, derivatives) for the sample half a window ago."""

    def __init__(self, window_s: float, dt: float, n_signals: int, polyorder: int = 3,
                 max_gap_s: float = MAX_GAP_S) -> None:
        self.window = window_samples(window_s, dt, polyorder)
        self.half = self.window // 2
        self.polyorder = polyorder
        # Coefficients for the centre point: value, first and second derivative.
        self.coeffs = np.stack([savgol_coeffs(self.window, polyorder, deriv=k, delta=dt, use="dot")
                                for k in range(3)])
        # The window's rows as Python tuples (None: a hole), and a numpy copy of them
        # written only when a fit is asked for: the live loop asks for about one sample in
        # five, and a row written into an array costs more than the tuple kept here.
        # The copy slides along a buffer of several windows, so the window is always one
        # contiguous slice and the fit a single small matrix product.
        self._rows: deque[tuple[float, ...] | None] = deque(maxlen=self.window)
        self._buf = np.zeros((SLIDE_WINDOWS * self.window, n_signals))
        self._end = 0
        """Where the copy's window ends in ``_buf``."""
        self._unsynced = 0
        """Rows pushed since the copy was last brought up to date."""
        self._zero = (0.0,) * n_signals
        """A hole's row in the copy (its weight is zero)."""
        self._holes = 0
        """Holes (missing samples) in the window."""
        self._count = 0
        self.tags: deque[T | None] = deque(maxlen=self.window)
        self.n = n_signals
        self.dt = dt
        self.max_gap = max(0, round(max_gap_s / dt))
        """The longest run of missing samples bridged (longer restarts)."""
        self.max_holes = (self.window - polyorder - 1) // 4
        """Beyond this many holes in a window its fit is NaN: too few samples left."""
        self._run = 0
        """Missing samples since the last sample with values."""
        self.last_t = math.nan
        """Time of the last tick pushed (NaN: none since a restart)."""
        self.late = 1.5 * dt
        """A sample this long after the last tick follows missed ticks (ask :meth:`gap`)."""

    def push(self, t: float, values: tuple[float, ...], tag: T
             ) -> tuple[T | None, np.ndarray] | None:
        """Add a sample; once the window is full, return the centre sample's tag and a
        (3, n_signals) array of value, rate and acceleration. A long gap restarts; for a
        short one, call :meth:`gap` and :meth:`push_hole` first (or lose those centres)."""
        tag_c = self.push_tag(t, values, tag)
        if self._count < self.window:  # (not full, or restarted)
            return None
        return tag_c, self.derivatives()

    def missed(self, t: float) -> int:
        """How many ticks were missed between the last sample and ``t`` (0 when none
        was pushed since a restart), bridged or not."""
        last = self.last_t
        return 0 if last != last else round((t - last) / self.dt) - 1

    def gap(self, t: float) -> int:
        """How many ticks were missed between the last sample and ``t`` that the filter
        will bridge: push that many holes (:meth:`push_hole`) before the sample at ``t``.
        0 when none were missed, or when the gap is too long (the push then restarts)."""
        n = self.missed(t)
        return n if 0 < n and self._run + n <= self.max_gap else 0

    def push_hole(self, tag: T | None = None) -> T | None:
        """Advance one tick with no sample; the centre sample's tag as :meth:`push_tag`."""
        self.last_t += self.dt
        self._run += 1
        return self._write(None, tag)

    def push_tag(self, t: float, values: tuple[float, ...], tag: T) -> T | None:
        """:meth:`push` without the fit: the centre sample's tag once the window is full
        (else None); :meth:`derivatives` then gives its fit. The live loop needs the fit
        for about one sample in five (settled lift and swing), so it asks only then. A
        sample with a NaN value is a hole, and keeps its tag."""
        missing = False
        for v in values:
            if v != v:  # NaN
                missing = True
        return self.push_known(t, values, tag, missing)

    def push_known(self, t: float, values: tuple[float, ...], tag: T, missing: bool
                   ) -> T | None:
        """:meth:`push_tag` for a caller that has tested its values for NaN already
        (``missing``: one is): the live loop's push at every tick, in one call."""
        last = self.last_t
        if t - last > self.late:  # a gap not bridged: restart (NaN compares false)
            self._restart()
        if missing:
            if self._run >= self.max_gap or last != last:
                self._restart()  # too long a hole (or nothing before it)
                self.last_t = math.nan
                return None
            self._run += 1
            self.last_t = t
            return self._write(None, tag)
        self._run = 0
        self.last_t = t
        # _write, inline for the common sample with values
        rows = self._rows
        if self._holes and len(rows) == self.window and rows[0] is None:
            self._holes -= 1  # a hole leaves the window
        rows.append(values)
        self._unsynced += 1
        self._count = count = self._count + 1
        tags = self.tags
        tags.append(tag)
        if count < self.window:
            return None
        return tags[self.half]

    def _restart(self) -> None:
        """Forget the window: the next samples fill a new one."""
        self._count = 0
        self.tags.clear()
        self._rows.clear()
        self._holes = 0
        self._run = 0

    def _write(self, values: tuple[float, ...] | None, tag: T | None) -> T | None:
        rows = self._rows
        if self._holes and len(rows) == self.window and rows[0] is None:
            self._holes -= 1  # a hole leaves the window
        if values is None:
            self._holes += 1
        rows.append(values)
        self._unsynced += 1
        self._count += 1
        self.tags.append(tag)
        if self._count < self.window:
            return None
        return self.tags[self.half]

    def _window(self) -> np.ndarray:
        """The window as a (window, n_signals) array: the rows pushed since the last fit
        written into the buffer after the ones before them (the whole window anew at the
        buffer's end or after a longer pause)."""
        w, u, end = self.window, self._unsynced, self._end
        if u:
            buf, rows, zero = self._buf, self._rows, self._zero
            if u >= w or end + u > len(buf):
                buf[:w] = [zero if r is None else r for r in rows]
                end = w
            elif u == 1:
                r = rows[-1]
                buf[end] = zero if r is None else r
                end += 1
            else:
                buf[end:end + u] = [zero if r is None else r for r in islice(rows, w - u, w)]
                end += u
            self._end, self._unsynced = end, 0
        return self._buf[end - w:end]

    def derivatives(self) -> np.ndarray:
        """(3, n_signals) value, rate and acceleration at the centre of the current window
        (valid after :meth:`push_tag` returned a tag); fitted to the samples it has when
        there are holes, NaN when too many are missing."""
        window = self._window()
        if not self._holes:
            return self.coeffs @ window
        if self._holes > self.max_holes:
            return np.full((3, self.n), math.nan)
        mask = bytes(r is None for r in self._rows)
        return _masked_coeffs(mask, self.window, self.polyorder, self.dt) @ window


@lru_cache(maxsize=256)
def _masked_coeffs(mask: bytes, window: int, polyorder: int, dt: float) -> np.ndarray:
    """Centre value, rate and acceleration weights of a window with holes (zero weight on
    them): the same local polynomial fit, to the samples there are. A gap makes up to
    ``window`` distinct masks, so the cache keeps a gap's worth and a few more."""
    keep = ~np.frombuffer(mask, dtype=bool)
    out = np.zeros((3, window))
    for k in range(3):
        out[k, keep] = savgol_coeffs(window, polyorder, deriv=k, delta=dt, use="dot",
                                     keep=keep)
    return out
