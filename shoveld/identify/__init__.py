"""Offline identification of the model parameters."""

ANGLE_DRIFT_DEG = 0.1
"""Default size (1 sigma) of the handle-angle sensor's slow drift within a calibration
file, counted in the standard errors: "inertial sensors drift slowly (tenths of a
degree)". Here, not in ``output_error``, so that ``shoveld --help`` need not import numpy."""
