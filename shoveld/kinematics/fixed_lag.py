"""Fixed-lag zero-phase joint rates for the payload equations of the live loop.

The causal Kalman filter's acceleration lags by ~0.15 s, and because a lift
starts and ends with the acceleration changing, that lag does not average out
over a pass: it biased payloads by -0.5 % to +0.4 % of the load depending on the
window (bench/kinematics_tradeoff.py). Evaluating the equations of motion half a
window late, with the same Savitzky-Golay fit as identification and the currents
of that same instant, removes the bias at the price of a delay of half a window (0.41 s),
which the operator never sees (the pass is final at the dump, seconds later).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Generic, TypeVar

import numpy as np

from shoveld.kinematics import window_samples
from shoveld.kinematics.savgol import savgol_coeffs

T = TypeVar("T")


class FixedLagSavgol(Generic[T]):
    """Push samples in; get (tag, derivatives) for the sample half a window ago."""

    def __init__(self, window_s: float, dt: float, n_signals: int, polyorder: int = 3) -> None:
        self.window = window_samples(window_s, dt, polyorder)
        self.half = self.window // 2
        # Coefficients for the centre point: value, first and second derivative.
        self.coeffs = np.stack([savgol_coeffs(self.window, polyorder, deriv=k, delta=dt, use="dot")
                                for k in range(3)])
        # A doubled ring: every sample is written twice, so the window is always one
        # contiguous slice and the fit is a single small matrix product.
        self._ring = np.zeros((2 * self.window, n_signals))
        self._pos = 0
        self._count = 0
        self.tags: deque[T] = deque(maxlen=self.window)
        self.n = n_signals
        self.dt = dt
        self._last_t = math.nan

    def push(self, t: float, values: tuple[float, ...], tag: T
             ) -> tuple[T, np.ndarray] | None:
        """Add a sample; once the window is full, return the centre sample's tag and a
        (3, n_signals) array of value, rate and acceleration. NaN or a time gap restarts."""
        tag_c = self.push_tag(t, values, tag)
        if self._count < self.window:  # (not full, or restarted by a NaN)
            return None
        return tag_c, self.derivatives()  # type: ignore[return-value]

    def push_tag(self, t: float, values: tuple[float, ...], tag: T) -> T | None:
        """:meth:`push` without the fit: the centre sample's tag once the window is full
        (else None); :meth:`derivatives` then gives its fit. The live loop needs the fit
        for about one sample in five (settled lift and swing), so it asks only then."""
        missing = False
        for v in values:
            if v != v:  # NaN
                missing = True
        if missing or (not math.isnan(self._last_t) and t - self._last_t > 1.5 * self.dt):
            self._count = 0
            self.tags.clear()
        self._last_t = t
        if missing:
            return None
        w, pos = self.window, self._pos
        ring = self._ring
        ring[pos] = values
        ring[pos + w] = values
        self._pos = (pos + 1) % w
        self._count += 1
        self.tags.append(tag)
        if self._count < w:
            return None
        return self.tags[self.half]

    def derivatives(self) -> np.ndarray:
        """(3, n_signals) value, rate and acceleration at the centre of the current window
        (valid after :meth:`push_tag` returned a tag)."""
        pos = self._pos
        return self.coeffs @ self._ring[pos:pos + self.window]
