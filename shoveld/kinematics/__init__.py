"""Joint rates and accelerations: zero-phase offline, Kalman-filtered live.

Two smoothings, both recorded in the params file. Identification's must follow the
calibration trials' fast strokes, where the inertia terms and the field knots are
seen, so it is a high-order fit over a short window. The payload equations' runs
over lift and swing, slower motions where a longer, lower-order fit leaves less
noise on the acceleration than it adds bias (docs/engine.md, "The payload's own
smoothing").
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
PAYLOAD_WINDOW_S = 1.5
"""Savitzky-Golay window of the payload equations' rates (live and offline), s."""
PAYLOAD_POLYORDER = 5
"""Its order. Chosen on 18 simulated machines among 16 windows and orders (RMS/CRB
1.58 with identification's 1.0 s 7th-order fit, 1.51 with this one) and checked on 36
others it was not chosen on (docs/engine.md, "The payload's own smoothing")."""
LEGACY_WINDOW_S, LEGACY_POLYORDER = 0.5, 3
"""What params files that do not record their smoothing were identified with."""


def window_samples(window_s: float, dt: float, polyorder: int) -> int:
    """The odd number of samples of a ``window_s`` window at step ``dt``: one rule for the
    offline fit and the live fixed-lag one, at least two more than the order."""
    return max(polyorder + 2, round(window_s / dt)) | 1
