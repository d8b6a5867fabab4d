"""Joint rates and accelerations: zero-phase offline, Kalman-filtered live.

The smoothing below is shared by identification and the payload equations, and
recorded in the params file: both must differentiate the angles the same way, or
the inertia terms identified from one disagree with the accelerations of the other.
"""

DEFAULT_WINDOW_S = 1.0
"""Savitzky-Golay window of the zero-phase joint rates, s."""
DEFAULT_POLYORDER = 7
"""Its polynomial order. Every smoothing leaves a bias where the motion turns sharply,
and the identification reads it as physics: a cubic over 0.5 s (the default until
2026-11-25) kept only 84 % of a 1 Hz acceleration and biased the arm inertia J by +5
standard errors; a 5th-order fit over 0.82 s (until 2026-11-26) leaned J and the
field knots the fast strokes sweep by 0.2-0.4 standard errors with noise-free angles.
This fit leaves about two thirds of a 7th-order fit's bias over 1.15 s on those knots
and a third of it on J, for a third more noise on the acceleration (0.0150 against
0.0113 rad/s^2 from the handle's 0.03 deg), which the angles' correction takes out of
the identification (docs/engine.md, "The smoothing's bias on the fast strokes")."""
LEGACY_WINDOW_S, LEGACY_POLYORDER = 0.5, 3
"""What params files that do not record their smoothing were identified with."""


def window_samples(window_s: float, dt: float, polyorder: int) -> int:
    """The odd number of samples of a ``window_s`` window at step ``dt``: one rule for the
    offline fit and the live fixed-lag one, at least two more than the order."""
    return max(polyorder + 2, round(window_s / dt)) | 1
