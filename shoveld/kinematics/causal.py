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
        # filterpy's piecewise model takes the variance of the acceleration change per step.
        kf.Q = Q_discrete_white_noise(dim=3, dt=dt, var=(cfg.jerk_std * dt) ** 2)
        self.kf = kf
        self._last_t: float | None = None
        self._coast = 0.0
        self._steady: tuple[float, float, float] | None = None
        self._qva = [0.0, 0.0, 0.0]
        """The state while steady (``kf.x`` is stale then; see :meth:`_leave_steady`)."""
        self._prev_p = 0.0

    def reset(self, z: float) -> None:
        self._leave_steady()
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
        if self._steady is not None:
            if z == z:  # not NaN
                return self._steady_update(z)
            self._leave_steady()
        self.kf.predict()
        if math.isnan(z):
            self._coast += self.dt
            if self._coast > self.cfg.max_coast_s:
                self._last_t = None
                return math.nan, math.nan, math.nan
        else:
            self._coast = 0.0
            self.kf.update(z)
            p00 = float(self.kf.P[0, 0])
            if abs(p00 - self._prev_p) < 1e-9 * p00:
                # Converged: the gain is constant from here on (steady-state Kalman filter),
                # so the update needs no matrix algebra until a gap disturbs it.
                k = self.kf.K
                self._steady = (float(k[0, 0]), float(k[1, 0]), float(k[2, 0]))
                x = self.kf.x
                self._qva = [float(x[0, 0]), float(x[1, 0]), float(x[2, 0])]
            self._prev_p = p00
        x = self.kf.x
        return float(x[0, 0]), float(x[1, 0]), float(x[2, 0])

    def _steady_update(self, z: float) -> tuple[float, float, float]:
        """Steady-state update on the state held as Python floats (the same double
        arithmetic as on ``kf.x``, without a numpy element access per term); ``kf.x``
        is written back when the steady state ends (:meth:`state`)."""
        qva = self._qva
        q, v, a = qva
        dt = self.dt
        q, v = q + v * dt + 0.5 * a * dt * dt, v + a * dt
        k0, k1, k2 = self._steady  # type: ignore[misc]
        e = z - q
        qva[0] = q = q + k0 * e
        qva[1] = v = v + k1 * e
        qva[2] = a = a + k2 * e
        return q, v, a

    def _leave_steady(self) -> None:
        """Back to filterpy's full update: put the float state into ``kf.x``."""
        if self._steady is not None:
            x = self.kf.x
            x[0, 0], x[1, 0], x[2, 0] = self._qva
            self._steady = None

    def state(self) -> tuple[float, float, float]:
        """The current (q, q', q'') estimate."""
        if self._steady is not None:
            q, v, a = self._qva
            return q, v, a
        x = self.kf.x
        return float(x[0, 0]), float(x[1, 0]), float(x[2, 0])
