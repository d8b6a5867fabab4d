"""Joint rates and accelerations: zero-phase offline, Kalman-filtered live.

The smoothing below is shared by identification and the payload equations, and
recorded in the params file: both must differentiate the angles the same way, or
the inertia terms identified from one disagree with the accelerations of the other.
"""

DEFAULT_WINDOW_S = 0.82
"""Savitzky-Golay window of the zero-phase joint rates, s."""
DEFAULT_POLYORDER = 5
"""Its polynomial order. A cubic over 0.5 s (the default until 2026-11-25) has the same
noise gain on the acceleration but keeps only 84 % of it at 1 Hz (this fit 95 %): it
flattened the fast strokes' peaks and biased the arm inertia J by +5 standard errors
(3 %) and the payload by about +10 kg (docs/engine.md, "Smoothing")."""
LEGACY_WINDOW_S, LEGACY_POLYORDER = 0.5, 3
"""What params files that do not record their smoothing were identified with."""


def window_samples(window_s: float, dt: float, polyorder: int) -> int:
    """The odd number of samples of a ``window_s`` window at step ``dt``: one rule for the
    offline fit and the live fixed-lag one, at least two more than the order."""
    return max(polyorder + 2, round(window_s / dt)) | 1
