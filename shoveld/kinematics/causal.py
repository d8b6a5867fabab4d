"""Causal joint-rate estimation for the live loop: a Kalman filter per joint.

Each joint is a constant-acceleration (white-jerk) process observed in position;
filterpy's ``KalmanFilter`` does the work. The jerk intensity sets the lag/noise
trade-off (``bench/kinematics_tradeoff.py`` measures it); the default was chosen
there. The filter coasts through missing samples (predict only) and resets after
a long gap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter


@dataclass(frozen=True)
class JointFilterConfig:
    """Measurement noise and jerk intensity of one joint (SI units)."""

    meas_std: float
    jerk_std: float
    max_coast_s: float = 0.5


HANDLE = JointFilterConfig(meas_std=math.radians(0.03), jerk_std=1.0)
CROWD = JointFilterConfig(meas_std=0.002, jerk_std=4.0)
SWING = JointFilterConfig(meas_std=math.radians(0.1), jerk_std=1.0)


class JointFilter:
    """Position, rate and acceleration of one joint from noisy positions, causally."""

    def __init__(self, cfg: JointFilterConfig, dt: float) -> None:
        self.cfg = cfg
        self.dt = dt
        kf = KalmanFilter(dim_x=3, dim_z=1)
        kf.F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        kf.H = np.array([[1.0, 0.0, 0.0]])
        kf.R = np.array([[cfg.meas_std**2]])
        kf.Q = Q_discrete_white_noise(dim=3, dt=dt, var=cfg.jerk_std**2)
        self.kf = kf
        self._last_t: float | None = None
        self._coast = 0.0

    def reset(self, z: float) -> None:
        self.kf.x = np.array([[z], [0.0], [0.0]])
        self.kf.P = np.diag([self.cfg.meas_std**2, 1.0, 10.0])

    def update(self, t: float, z: float) -> tuple[float, float, float]:
        """Feed the measurement at time t (NaN: missing); return (q, q', q'')."""
        if self._last_t is None:
            if math.isnan(z):
                return math.nan, math.nan, math.nan
            self.reset(z)
            self._last_t = t
            return z, 0.0, 0.0
        self._last_t = t
        self.kf.predict()
        if math.isnan(z):
            self._coast += self.dt
            if self._coast > self.cfg.max_coast_s:
                self._last_t = None
                return math.nan, math.nan, math.nan
        else:
            self._coast = 0.0
            self.kf.update(z)
        x = self.kf.x
        return float(x[0, 0]), float(x[1, 0]), float(x[2, 0])
