"""Recursive least squares for the payload, as a Kalman filter over one state.

With the model's parameters known, both equations of motion are linear in the
payload m: a * m = b per sample. A Kalman filter whose state is m, with a random
walk (process noise) as fading memory, is recursive least squares with
forgetting. With one state, a block of N samples is a closed-form information update
(O(N)); filterpy's ``KalmanFilter`` gives the same numbers
(``tests/engine/test_filters.py``) but inverts the 2N x 2N innovation covariance and
imports scipy.stats at start (``bench/filters.py`` measures both). The reported
standard deviation is the filter's, scaled by the innovations actually seen: their
normalised size (the model's noise may be wrong) and their lag-1 correlation (samples
at 50-100 Hz are not independent), so the confidence is earned from the data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RlsConfig:
    prior_kg: float = 15000.0
    prior_std_kg: float = 40000.0
    forgetting_std_kg_per_s: float = 0.0
    """Random walk of the payload per second (0: plain least squares over the pass)."""


class PayloadRls:
    """The payload estimate of one pass."""

    def __init__(self, noise: tuple[float, float], dt: float, cfg: RlsConfig | None = None,
                 tau: tuple[float, float] | None = None) -> None:
        self.cfg = cfg or RlsConfig()
        self.tau = tau
        """Per channel, the residuals' integrated autocorrelation time (samples) measured
        at calibration; None: estimate a lag-1 correlation from this pass's innovations."""
        self._info = np.zeros(2)
        self.dt = dt
        self.r_diag = np.square(np.asarray(noise, dtype=float))
        self.x = self.cfg.prior_kg
        self.p = self.cfg.prior_std_kg**2
        """The filter's state (the payload) and its variance."""
        self.n = 0
        self._nis_sum = 0.0
        self._nis_dof = 0
        self._prev_nu: np.ndarray | None = None
        self._corr_num = 0.0
        self._corr_den = 0.0
        self._s_aa = 0.0
        self._s_adb: np.ndarray | None = None

    def update(self, a: np.ndarray, b: np.ndarray, db_dp: np.ndarray | None = None,
               sigma: np.ndarray | None = None) -> None:
        """A block of samples: ``a[k] * m = b[k]`` for the two equations (channels).

        ``a``, ``b`` are (N, 2). One update with the stacked measurement is the same as
        N sequential updates when there is no forgetting, and cheaper.
        ``sigma`` (N, 2) is each row's noise std (default: the constant per-equation
        noise given at construction). ``db_dp`` (N, 2, P), the sensitivity of ``b`` to
        the model parameters, lets :meth:`param_std_kg` carry the calibration's
        uncertainty into the pass.
        """
        a = np.asarray(a, dtype=float).reshape(-1, 2)
        b = np.asarray(b, dtype=float).reshape(-1, 2)
        n = len(a)
        if n == 0:
            return
        var = (np.tile(self.r_diag, (n, 1)) if sigma is None
               else np.square(np.asarray(sigma, dtype=float).reshape(-1, 2)))
        # Predict: a random walk of the payload over the block.
        p = self.p + (self.cfg.forgetting_std_kg_per_s**2) * self.dt * n
        # Update in information form: S = a a' p + R, so by Woodbury
        # y' S^-1 y = y' R^-1 y - (a' R^-1 y)^2 / (1/p + a' R^-1 a).
        y = b - a * self.x
        wa = a / var
        info = float(np.sum(wa * a))
        ay = float(np.sum(wa * y))
        prec = 1.0 / p + info
        self.p = 1.0 / prec
        self.x += ay / prec
        self._nis_sum += float(np.sum(y * y / var)) - ay * ay / prec
        self._nis_dof += 2 * n
        nu = y / np.sqrt(var)
        last = nu[-1]
        if self._prev_nu is not None:
            nu_prev = np.vstack([self._prev_nu[None, :], nu[:-1]])
        else:
            nu_prev = nu[:-1]
            nu = nu[1:] if n > 1 else nu[:0]
        self._corr_num += float(np.sum(nu * nu_prev))
        self._corr_den += float(np.sum(nu * nu))
        self._prev_nu = last
        self._info += np.sum(a * a / var, axis=0)
        if db_dp is not None:
            self._s_aa += float(np.sum(wa * a))
            s = np.einsum("ke,kep->p", wa, np.asarray(db_dp))
            self._s_adb = s if self._s_adb is None else self._s_adb + s
        self.n += n

    @property
    def payload_kg(self) -> float:
        return float(self.x) if self.n else math.nan

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
        scale = max(1.0, self._nis_sum / max(1, self._nis_dof))
        if self.tau is not None and self._info.sum() > 0:
            # each channel's information counts 1/tau of a white sample's
            infl = float(self._info @ np.asarray(self.tau)) / float(self._info.sum())
            return math.sqrt(float(self.p) * scale * max(1.0, infl))
        rho = self._corr_num / self._corr_den if self._corr_den > 0 else 0.0
        rho = min(max(rho, 0.0), 0.98)
        return math.sqrt(float(self.p) * scale * (1 + rho) / (1 - rho))
