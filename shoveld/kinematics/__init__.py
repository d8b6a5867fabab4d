"""Joint rates and accelerations: zero-phase offline, Kalman-filtered live."""
