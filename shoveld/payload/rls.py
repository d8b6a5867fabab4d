"""Recursive least squares for the payload, as a Kalman filter over one state.

With the model's parameters known, both equations of motion are linear in the
payload m: a * m = b per sample. A Kalman filter whose state is m, with a random
walk (process noise) as fading memory, is recursive least squares with
forgetting. With one state, a block of N samples is a closed-form information update
(O(N)); filterpy's ``KalmanFilter`` gives the same numbers
(``tests/engine/test_filters.py``) but inverts the 2N x 2N innovation covariance and
imports scipy.stats at start (``bench/filters.py`` measures both).

The reported standard deviation is earned from the pass's own residuals: a
heteroscedasticity and autocorrelation consistent (Newey-West) variance of the
estimate, whose scores are correlated over the angles' smoothing window, never less
than the filter's variance under the calibrated noise model. The calibration's
residual correlation time (``tau``) once inflated every pass instead; it counts
misfit of the calibration's fast strokes that a pass does not have, and the std it
gave covered 76 % of the errors within 1 sigma over 18 realistic machines, where 68 %
is honest (now 66 %; docs/engine.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class RlsConfig:
    prior_kg: float = 15000.0
    prior_std_kg: float = 40000.0
    forgetting_std_kg_per_s: float = 0.0
    """Random walk of the payload per second (0: plain least squares over the pass)."""

    RANGES: ClassVar[dict[str, dict[str, float | bool]]] = {
        "prior_std_kg": {"positive": True}, "forgetting_std_kg_per_s": {"lo": 0.0}}
    """What the configuration may set (``shoveld.daemon.config``): a prior of no spread
    would hold the payload at ``prior_kg`` whatever the pass."""


class PayloadRls:
    """The payload estimate of one pass."""

    def __init__(self, noise: tuple[float, float], dt: float, cfg: RlsConfig | None = None,
                 hac_lag: int = 0) -> None:
        self.cfg = cfg or RlsConfig()
        self.hac_lag = int(hac_lag)
        """Samples over which the scores may be correlated (the smoothing window): the
        Newey-West bandwidth. 0: the filter's variance, scaled by the innovations' size
        and lag-1 correlation."""
        self._info = np.zeros(2)
        # Newey-West sums of the per-sample scores s = u - m c (u = sum a b / var,
        # c = sum a a / var, over the two channels), kept as products of u and c so the
        # final m goes in at the end; the last hac_lag rows carry lags across blocks.
        self._hac = np.zeros(3)
        self._tail = np.zeros((self.hac_lag, 2))
        # kernel of a 'valid' convolution: 0 at lag 0, then lag 1..L's Bartlett weights
        self._weights = np.concatenate(
            [[0.0], 2.0 * (1.0 - np.arange(1, self.hac_lag + 1) / (self.hac_lag + 1))])
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
        # (the arrays' own reductions: the same sums as np.sum, without its dispatch,
        # which on blocks of ten rows cost as much as the arithmetic)
        y = b - a * self.x
        wa = a / var
        waa = wa * a
        info = float(waa.sum())
        ay = float((wa * y).sum())
        prec = 1.0 / p + info
        self.p = 1.0 / prec
        self.x += ay / prec
        self._nis_sum += float((y * y / var).sum()) - ay * ay / prec
        self._nis_dof += 2 * n
        self._info += waa.sum(axis=0)
        if self.hac_lag > 0:
            uc = np.empty((n, 2))
            uc[:, 0] = (wa * b).sum(axis=1)
            uc[:, 1] = waa.sum(axis=1)
            self._hac_add(uc)
        else:
            self._lag1(y / np.sqrt(var))
        if db_dp is not None:
            self._s_aa += info
            s = np.einsum("ke,kep->p", wa, np.asarray(db_dp))
            self._s_adb = s if self._s_adb is None else self._s_adb + s
        self.n += n

    def _lag1(self, nu: np.ndarray) -> None:
        """Add a block's normalised innovations to their lag-1 correlation sums."""
        last = nu[-1]
        if self._prev_nu is not None:
            nu_prev = np.vstack([self._prev_nu[None, :], nu[:-1]])
        else:
            nu_prev = nu[:-1]
            nu = nu[1:]
        self._corr_num += float(np.sum(nu * nu_prev))
        self._corr_den += float(np.sum(nu * nu))
        self._prev_nu = last

    def _hac_add(self, uc: np.ndarray) -> None:
        """Add a block's (u, c) rows to the Newey-West sums: lag 0, and each lag up to
        ``hac_lag`` with its Bartlett weight, pairing every new row with those before
        (the rows before a pass's first are zeros, which add nothing)."""
        rows = np.concatenate((self._tail, uc))
        u, c = uc[:, 0], uc[:, 1]
        # for each new row, the Bartlett-weighted sum of the lag rows before it
        bu = np.convolve(rows[:, 0], self._weights, "valid")
        bc = np.convolve(rows[:, 1], self._weights, "valid")
        self._hac += np.array([u @ u + u @ bu, u @ c + 0.5 * (u @ bc + c @ bu),
                               c @ c + c @ bc])
        self._tail = rows[-self.hac_lag:]

    def hac_std_kg(self) -> float:
        """The Newey-West std of the estimate, from this pass's own scores."""
        uu, uc, cc = self._hac
        m = self.x
        info = float(self._info.sum())
        return math.sqrt(max(uu - 2.0 * m * uc + m * m * cc, 0.0)) / info if info else math.nan

    @property
    def misfit(self) -> float:
        """The pass's mean normalised innovation squared per degree of freedom: about 1
        when the residuals are the noise model's size, far above when the model does not
        hold (``bench/pass_misfit.py`` measures it). The engine records it with the pass
        and warns above ``misfit_warn`` (:mod:`shoveld.payload.misfit`); it weighs the pass
        all the same."""
        return self._nis_sum / self._nis_dof if self._nis_dof else math.nan

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
        """The pass's own (Newey-West) std, never under the filter's; without a
        bandwidth, the filter's std inflated by the innovations' size and correlation."""
        if not self.n:
            return math.nan
        if self.hac_lag > 0:
            return max(math.sqrt(float(self.p)), self.hac_std_kg())
        scale = max(1.0, self._nis_sum / max(1, self._nis_dof))
        rho = self._corr_num / self._corr_den if self._corr_den > 0 else 0.0
        rho = min(max(rho, 0.0), 0.98)
        return math.sqrt(float(self.p) * scale * (1 + rho) / (1 - rho))
