"""Causal joint-rate estimation for the live loop: a Kalman filter per joint.

Each joint is a constant-acceleration (white-jerk) process observed in position,
with a three-state Kalman filter written out on numpy (:class:`Kalman3`): filterpy's
``KalmanFilter`` gives the same numbers (``tests/engine/test_filters.py``) but its
import pulls in scipy.stats, 0.6-2 s of every daemon start, for a filter whose whole
algebra is a dozen lines (``bench/filters.py``). The jerk intensity sets the lag/noise
trade-off (``bench/kinematics_tradeoff.py`` measures it); the default was chosen
there. The filter coasts through missing samples and skipped ticks (predict only)
and resets after a long gap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class JointFilterConfig:
    """Measurement noise and jerk intensity of one joint (SI units)."""

    meas_std: float
    jerk_std: float
    max_coast_s: float = 0.5


HANDLE = JointFilterConfig(meas_std=math.radians(0.03), jerk_std=1.0)
CROWD = JointFilterConfig(meas_std=0.002, jerk_std=4.0)
SWING = JointFilterConfig(meas_std=math.radians(0.1), jerk_std=1.0)


def white_jerk_q(dt: float, var: float) -> np.ndarray:
    """Process noise of a constant-acceleration model whose acceleration changes by a
    piecewise-constant white step of variance ``var`` per sample (filterpy's
    ``Q_discrete_white_noise(dim=3)``)."""
    g = np.array([0.5 * dt * dt, dt, 1.0])
    return var * np.outer(g, g)


class Kalman3:
    """A linear Kalman filter with a scalar measurement of the first state; the
    covariance update in Joseph form (stable with the tiny variances of a settled
    filter), as filterpy's ``KalmanFilter`` does it."""

    def __init__(self, F: np.ndarray, Q: np.ndarray, r: float) -> None:
        self.F = F
        self.Q = Q
        self.r = r
        n = F.shape[0]
        self.x = np.zeros(n)
        self.P = np.eye(n)
        self.K = np.zeros(n)
        self._eye = np.eye(n)

    def predict(self) -> None:
        self.x = self.F @ self.x
        self.P = self.F @ self.P @ self.F.T + self.Q

    def update(self, z: float) -> None:
        P = self.P
        s = P[0, 0] + self.r
        k = P[:, 0] / s
        self.x = self.x + k * (z - self.x[0])
        ikh = self._eye.copy()
        ikh[:, 0] -= k
        # k k' as a broadcast product: np.outer's own arithmetic, without its wrapper
        self.P = ikh @ P @ ikh.T + self.r * (k[:, None] * k)
        self.K = k


class JointFilter:
    """Position, rate and acceleration of one joint from noisy positions, causally."""

    def __init__(self, cfg: JointFilterConfig, dt: float) -> None:
        self.cfg = cfg
        self.dt = dt
        F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        # The piecewise model takes the variance of the acceleration change per step.
        self.kf = Kalman3(F, white_jerk_q(dt, (cfg.jerk_std * dt) ** 2), cfg.meas_std**2)
        self._last_t: float | None = None
        self._late = 1.5 * dt
        """A sample later than this after the last one follows skipped ticks."""
        self._coast = 0.0
        self._steady: tuple[float, float, float] | None = None
        self._qva = [0.0, 0.0, 0.0]
        """The state while steady (``kf.x`` is stale then; see :meth:`_leave_steady`)."""
        self._prev_p = 0.0

    def reset(self, z: float) -> None:
        self._leave_steady()
        self.kf.x = np.array([z, 0.0, 0.0])
        self.kf.P = np.diag([self.cfg.meas_std**2, 1.0, 10.0])

    def update(self, t: float, z: float) -> tuple[float, float, float]:
        """Feed the measurement at time t (NaN: missing); return (q, q', q'')."""
        last = self._last_t
        steady = self._steady
        if steady is not None and z == z and last is not None and not t - last > self._late:
            # The common tick (converged filter, the next sample, a value): the gain is
            # constant, so the update is a few float operations on the state held as
            # Python floats (``kf.x`` is written back when the steady state ends).
            self._last_t = t
            qva = self._qva
            q, v, a = qva
            dt = self.dt
            q, v = q + v * dt + 0.5 * a * dt * dt, v + a * dt
            k0, k1, k2 = steady
            e = z - q
            qva[0] = q = q + k0 * e
            qva[1] = v = v + k1 * e
            qva[2] = a = a + k2 * e
            return q, v, a
        if last is None:
            if math.isnan(z):
                return math.nan, math.nan, math.nan
            self.reset(z)
            self._last_t = t
            return z, 0.0, 0.0
        if t - last > self._late:
            missed = round((t - last) / self.dt) - 1
            # Ticks the loop skipped (a busy host): predict over them as over missing
            # samples, or the whole move since the last sample lands in one step and
            # the rates spike (and the phase machine sees a dig or a swing that is not).
            for k in range(1, missed + 1):
                self.update(last + k * self.dt, math.nan)
                if self._last_t is None:  # coasted too long: restart at this sample
                    return self.update(t, z)
        self._last_t = t
        # (a steady filter gets here only for a missing value or after skipped ticks)
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
                gain = self.kf.K
                self._steady = (float(gain[0]), float(gain[1]), float(gain[2]))
                x = self.kf.x
                self._qva = [float(x[0]), float(x[1]), float(x[2])]
            self._prev_p = p00
        q, v, a = self.kf.x.tolist()
        return q, v, a

    def _leave_steady(self) -> None:
        """Back to the full update: put the float state into ``kf.x``."""
        if self._steady is not None:
            self.kf.x = np.array(self._qva)
            self._steady = None

    def state(self) -> tuple[float, float, float]:
        """The current (q, q', q'') estimate."""
        if self._steady is not None:
            q, v, a = self._qva
            return q, v, a
        x = self.kf.x
        return float(x[0]), float(x[1]), float(x[2])


def update_joints(fa: JointFilter, fb: JointFilter, fc: JointFilter, t: float, za: float,
                  zb: float, zc: float) -> tuple[float, float, float, float, float, float,
                                                 float, float, float]:
    """Three filters fed the same tick: (q, q', q'') of each, in one tuple.

    The live loop's joints at every tick: when all three are steady and get the next
    sample with a value, their steady updates are done here in one call (the float
    operations of :meth:`JointFilter.update`, in its order, so the same bits); anything
    else goes through :meth:`JointFilter.update` one by one.
    """
    sa, sb, sc = fa._steady, fb._steady, fc._steady
    last = fa._last_t
    if (sa is not None and sb is not None and sc is not None and za == za and zb == zb
            and zc == zc and last is not None and last == fb._last_t == fc._last_t
            and not t - last > fa._late and fa.dt == fb.dt == fc.dt):
        fa._last_t = fb._last_t = fc._last_t = t
        dt = fa.dt
        x = fa._qva
        q, v, a = x
        q, v = q + v * dt + 0.5 * a * dt * dt, v + a * dt
        k0, k1, k2 = sa
        e = za - q
        x[0] = qa = q + k0 * e
        x[1] = va = v + k1 * e
        x[2] = aa = a + k2 * e
        x = fb._qva
        q, v, a = x
        q, v = q + v * dt + 0.5 * a * dt * dt, v + a * dt
        k0, k1, k2 = sb
        e = zb - q
        x[0] = qb = q + k0 * e
        x[1] = vb = v + k1 * e
        x[2] = ab = a + k2 * e
        x = fc._qva
        q, v, a = x
        q, v = q + v * dt + 0.5 * a * dt * dt, v + a * dt
        k0, k1, k2 = sc
        e = zc - q
        x[0] = qc = q + k0 * e
        x[1] = vc = v + k1 * e
        x[2] = ac = a + k2 * e
        return qa, va, aa, qb, vb, ab, qc, vc, ac
    return fa.update(t, za) + fb.update(t, zb) + fc.update(t, zc)
