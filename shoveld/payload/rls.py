"""Recursive least squares for the payload, as a Kalman filter over one state.

With the model's parameters known, both equations of motion are linear in the
payload m: a * m = b per sample. A Kalman filter whose state is m, with a random
walk (process noise) as fading memory, is recursive least squares with
forgetting; filterpy does the arithmetic. The reported standard deviation is the
filter's, scaled by the innovations actually seen: their normalised size (the
model's noise may be wrong) and their lag-1 correlation (samples at 50-100 Hz
are not independent), so the confidence is earned from the data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter


@dataclass(frozen=True)
class RlsConfig:
    prior_kg: float = 15000.0
    prior_std_kg: float = 40000.0
    forgetting_std_kg_per_s: float = 0.0
    """Random walk of the payload per second (0: plain least squares over the pass)."""


class PayloadRls:
    """The payload estimate of one pass."""

    def __init__(self, noise: tuple[float, float], dt: float, cfg: RlsConfig | None = None
                 ) -> None:
        self.cfg = cfg or RlsConfig()
        kf = KalmanFilter(dim_x=1, dim_z=2)
        kf.F = np.eye(1)
        kf.Q = np.array([[(self.cfg.forgetting_std_kg_per_s**2) * dt]])
        kf.R = np.diag(np.square(noise))
        kf.x = np.array([[self.cfg.prior_kg]])
        kf.P = np.array([[self.cfg.prior_std_kg**2]])
        self.kf = kf
        self._h = np.zeros((2, 1))
        self._z = np.zeros((2, 1))
        self.n = 0
        self._nis_sum = 0.0
        self._prev_nu: np.ndarray | None = None
        self._corr_num = 0.0
        self._corr_den = 0.0
        self._s_aa = 0.0
        self._s_adb: np.ndarray | None = None

    def update(self, a: tuple[float, float], b: tuple[float, float],
               db_dp: np.ndarray | None = None) -> None:
        """One sample: a * m = b for the handle and crowd equations.

        ``db_dp`` (2, P), the sensitivity of the equations to the model parameters,
        lets :meth:`param_std_kg` carry the calibration's uncertainty into the pass.
        """
        if db_dp is not None:
            r_inv = 1.0 / np.diag(self.kf.R)
            wa = np.asarray(a) * r_inv
            self._s_aa += float(wa @ np.asarray(a))
            self._s_adb = self._s_adb + wa @ db_dp if self._s_adb is not None else wa @ db_dp
        h, z = self._h, self._z
        h[0, 0], h[1, 0] = a
        z[0, 0], z[1, 0] = b
        kf = self.kf
        kf.predict()
        kf.update(z, H=h)
        nu = kf.y[:, 0] / np.sqrt(np.diag(kf.R))
        self._nis_sum += float((kf.y.T @ kf.SI @ kf.y)[0, 0])
        if self._prev_nu is not None:
            self._corr_num += float(nu @ self._prev_nu)
            self._corr_den += float(nu @ nu)
        self._prev_nu = nu
        self.n += 1

    @property
    def payload_kg(self) -> float:
        return float(self.kf.x[0, 0]) if self.n else math.nan

    def param_std_kg(self, cov: np.ndarray) -> float:
        """Payload std due to the parameters' uncertainty (m = sum a b / sum a a is linear
        in b, and b in the parameters)."""
        if self._s_adb is None or self._s_aa <= 0:
            return 0.0
        g = self._s_adb / self._s_aa
        return math.sqrt(max(0.0, float(g @ cov @ g)))

    @property
    def std_kg(self) -> float:
        """Filter standard deviation, inflated by the innovations' size and correlation."""
        if not self.n:
            return math.nan
        scale = max(1.0, self._nis_sum / (2.0 * self.n))
        rho = self._corr_num / self._corr_den if self._corr_den > 0 else 0.0
        rho = min(max(rho, 0.0), 0.98)
        return math.sqrt(float(self.kf.P[0, 0]) * scale * (1 + rho) / (1 - rho))
