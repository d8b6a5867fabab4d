"""Joint rates and accelerations: zero-phase offline, Kalman-filtered live.

The smoothing below is shared by identification and the payload equations, and
recorded in the params file: both must differentiate the angles the same way, or
the inertia terms identified from one disagree with the accelerations of the other.
"""

DEFAULT_WINDOW_S = 0.5
"""Savitzky-Golay window of the zero-phase joint rates, s."""
DEFAULT_POLYORDER = 3
"""Its polynomial order. A cubic over 0.5 s passes 84 % of the acceleration at 1 Hz: it
flattens the fast strokes' peaks and biases the arm inertia J by +3 % (5 standard
errors). A 5th-order fit over 0.82 s (``calibrate --polyorder 5 --window 0.82``) has the
same noise gain, passes 95 %, and removes that bias and a third of the payload's mean
error, but K_H's error then grows to +0.9 standard errors: the default stays, and
docs/engine.md ("Smoothing") gives both sets of figures."""
LEGACY_WINDOW_S, LEGACY_POLYORDER = 0.5, 3
"""What params files that do not record their smoothing were identified with."""
