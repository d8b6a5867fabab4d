"""Zero-phase joint rates and accelerations for offline identification.

Savitzky-Golay differentiation (a local polynomial fit) is zero-phase, so currents
need no matching delay, and it has a sharper noise/bandwidth trade-off than the
thesis's differentiate-then-Butterworth. Gaps (blank cells) split the data into
segments; samples within half a window of a gap are marked invalid.
The window and order are :mod:`shoveld.kinematics`'s defaults.
"""

from __future__ import annotations

import math

import numpy as np

from shoveld.kinematics import DEFAULT_POLYORDER, DEFAULT_WINDOW_S, window_samples
from shoveld.kinematics.savgol import savgol_coeffs, savgol_filter
from shoveld.model.kin import Kinematics
from shoveld.signals.table import SignalsTable

POSITION_COLUMNS = ("handle_deg", "crowd_m", "swing_deg", "boom_deg")


def _segments(valid: np.ndarray) -> list[tuple[int, int]]:
    edges = np.flatnonzero(np.diff(np.r_[0, valid.astype(np.int8), 0]))
    return list(zip(edges[::2], edges[1::2], strict=True))


def savgol_derivatives(y: np.ndarray, dt: float, window: int, valid: np.ndarray,
                       polyorder: int = DEFAULT_POLYORDER
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed value, first and second derivative; plus the mask where they are valid."""
    out = [np.full_like(y, np.nan) for _ in range(3)]
    ok = np.zeros(len(y), dtype=bool)
    for a, b in _segments(valid):
        if b - a < window:
            continue
        seg = y[a:b]
        for k in range(3):
            out[k][a:b] = savgol_filter(seg, window, polyorder, deriv=k, delta=dt)
        half = window // 2
        ok[a + half:b - half] = True
    return out[0], out[1], out[2], ok


def difference_noise(x: np.ndarray, order: int) -> float:
    """A sensor's white noise (1 sigma) from the ``order``-th differences of its readings.

    Where the true signal is smooth against the sample step, its ``order``-th difference
    is noise alone, of variance C(2 order, order) sigma^2; the median (scaled to a
    standard deviation) ignores the few samples where the signal itself turns sharply.
    """
    dk = np.diff(np.asarray(x, dtype=float), order)
    dk = dk[np.isfinite(dk)]
    if len(dk) < 10:
        return 0.0
    return float(1.4826 * np.median(np.abs(dk)) / math.sqrt(math.comb(2 * order, order)))


def smoothed_noise_sd(sigma: float, dt: float, window: int,
                      polyorder: int = DEFAULT_POLYORDER) -> tuple[float, float, float]:
    """Standard deviations of the smoothed value, rate and acceleration that white noise
    ``sigma`` on a reading leaves after :func:`savgol_derivatives` (away from edges).

    The rate's weights are odd and the value's and acceleration's even, so the rate's
    error is independent of the other two."""
    v, r, a = (sigma * float(np.linalg.norm(savgol_coeffs(window, polyorder, deriv=k,
                                                          delta=dt))) for k in range(3))
    return v, r, a


def offline_kinematics(cols: dict[str, np.ndarray] | SignalsTable,
                       window_s: float = DEFAULT_WINDOW_S,
                       polyorder: int = DEFAULT_POLYORDER) -> tuple[Kinematics, np.ndarray]:
    """Kinematics from a whole table, and the mask of samples where every input is valid."""
    if isinstance(cols, SignalsTable):
        cols = cols.columns
    t = cols["time_s"]
    dt = float(np.median(np.diff(t)))
    window = window_samples(window_s, dt, polyorder)
    i_h = cols["hoist1_a"] + cols["hoist2_a"]
    valid = np.isfinite(i_h) & np.isfinite(cols["crowd_a"]) & np.isfinite(cols["hoist_field_a"])
    for c in POSITION_COLUMNS:
        valid &= np.isfinite(cols[c])
    # A gap in time (dropped samples) also breaks the smoothing window.
    gap = np.r_[False, np.diff(t) > 1.5 * dt]
    seg_valid = valid.copy()
    seg_valid[gap] = False
    th, thd, thdd, ok_th = savgol_derivatives(np.radians(cols["handle_deg"]), dt, window,
                                              seg_valid, polyorder)
    d, dd, ddd, _ = savgol_derivatives(cols["crowd_m"], dt, window, seg_valid, polyorder)
    sw, swd, swdd, _ = savgol_derivatives(np.radians(cols["swing_deg"]), dt, window, seg_valid,
                                      polyorder)
    boom = np.radians(np.where(np.isfinite(cols["boom_deg"]), cols["boom_deg"], 45.0))
    roll = np.radians(np.nan_to_num(cols["roll_deg"]))
    pitch = np.radians(np.nan_to_num(cols["pitch_deg"]))
    fill = np.where(ok_th, 1.0, np.nan)
    k = Kinematics(t=t, th=th, thd=thd, thdd=thdd, d=d, dd=dd, ddd=ddd, boom=boom,
                   i_h=i_h * fill, i_c=cols["crowd_a"] * fill, i_hf=cols["hoist_field_a"],
                   swing=sw, swing_rate=swd, swing_acc=swdd, roll=roll, pitch=pitch)
    return k, ok_th & valid
