"""The model in current units: measured minus predicted motor current, per channel.

The measured currents are the noisiest signals of the machine. Left inside the
regressor (the thesis's form), their noise biases least squares towards zero
(errors in variables), the crowd worst. Here each equation is solved for its own
motor's current instead, so the currents are the *output* and the regressor holds
kinematics only (output-error form; Janot, Vandanjon & Gautier's IDIM-IV and DIDIM
do the same job):

* hoist channel: the handle equation divided by how much it moves per ampere of
  hoist current (``-K_H(i_f) d sin a3``): measured minus predicted hoist current;
* crowd channel: the crowd equation with the rope force taken from the handle
  equation, not from the measured hoist current (so its noise stays in its own
  channel), divided by its change per ampere of crowd current (``-K_C``).

The current sensors' offsets are subtracted on this side. Identification minimises
these residuals weighted by each channel's noise; the payload filter uses the same
equations, which are linear in the payload: ``residual = a m - b``.
"""

from __future__ import annotations

import functools

import numpy as np

from shoveld.model.kin import Kinematics
from shoveld.model.model import Model
from shoveld.model.terms import pair

CHANNELS: tuple[str, str] = ("hoist", "crowd")


class CurrentEquations:
    """The model's current residuals on fixed kinematics (regressor evaluated once)."""

    def __init__(self, model: Model, k: Kinematics) -> None:
        self.model = model
        w, phi, psi = model.regressor(k)
        d = model.current_derivatives(k)
        # per equation, contiguous (the regressor lays W and Psi out so: views, not
        # copies); the fits evaluate these hundreds of times
        self.w0, self.w1 = np.ascontiguousarray(w[:, 0, :]), np.ascontiguousarray(w[:, 1, :])
        self.phi0, self.phi1 = np.ascontiguousarray(phi[:, 0]), np.ascontiguousarray(phi[:, 1])
        self.has_psi = bool(np.any(psi))
        self.psi0 = np.ascontiguousarray(psi[:, 0, :])
        self.psi1 = np.ascontiguousarray(psi[:, 1, :])
        # only the columns that move with a measured current: the drives'
        self.h_cols, self.c_cols = d.hoist, d.crowd
        self.dh0 = np.ascontiguousarray(d.d_hoist[:, 0, :])
        self.dh1 = np.ascontiguousarray(d.d_hoist[:, 1, :])
        self.dc1 = np.ascontiguousarray(d.d_crowd[:, 1, :])
        self.offsets = model.offset_index
        self.i_h = k.i_h
        self.i_c = k.i_c
        self.acc = pair(k.thdd, k.ddd)
        self.spread_idx, spread = model.column_spread(k)
        self.spread0 = np.ascontiguousarray(spread[:, 0, :])
        self.spread1 = np.ascontiguousarray(spread[:, 1, :])
        self._gain_cache: tuple[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None

    def __len__(self) -> int:
        return int(self.w0.shape[0])

    def gains(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N,) each: d e_handle / d i_H; the multiple of the handle equation that removes
        i_H from the crowd equation; d e_crowd / d i_C."""
        key = p.tobytes()
        if self._gain_cache is not None and self._gain_cache[0] == key:
            return self._gain_cache[1]
        p_h = p[self.h_cols]
        g_h = self.dh0 @ p_h
        c = -(self.dh1 @ p_h) / g_h
        g_c = self.dc1 @ p[self.c_cols]
        self._gain_cache = (key, (g_h, c, g_c))
        return g_h, c, g_c

    def _offsets(self, p: np.ndarray) -> tuple[float, float]:
        if self.offsets is None:
            return 0.0, 0.0
        return float(p[self.offsets[0]]), float(p[self.offsets[1]])

    def payload_equations(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(a, b), each (N, 2) in amps: the residual of a payload m is ``a m - b``."""
        g_h, c, g_c = self.gains(p)
        ew0, ew1 = self.w0 @ p, self.w1 @ p
        em0, em1 = self.phi0, self.phi1
        if self.has_psi:
            em0, em1 = em0 + self.psi0 @ p, em1 + self.psi1 @ p
        o_h, o_c = self._offsets(p)
        a = pair(em0 / g_h, (em1 + c * em0) / g_c)
        b = -pair(ew0 / g_h - o_h, (ew1 + c * ew0) / g_c - o_c)
        return a, b

    def residual(self, p: np.ndarray, m: np.ndarray | float) -> np.ndarray:
        """(N, 2): measured minus predicted hoist and crowd current, A."""
        a, b = self.payload_equations(p)
        m = np.broadcast_to(np.asarray(m, dtype=float), (len(self),))
        return a * m[:, None] - b

    def jacobian(self, p: np.ndarray, m: np.ndarray | float) -> np.ndarray:
        """(N, 2, P): d residual / d p (exact, the model being linear in p per equation)."""
        if type(m) is float:  # the live engine's one payload: the same values as
            mv = np.empty(len(self))  # broadcast_to's view, at a tenth of its cost
            mv.fill(m)
            m = mv
        else:
            m = np.broadcast_to(np.asarray(m, dtype=float), (len(self),))
        if self.has_psi:
            a0 = self.w0 + m[:, None] * self.psi0
            a1 = self.w1 + m[:, None] * self.psi1
        else:
            a0, a1 = self.w0, self.w1
        e0 = a0 @ p + m * self.phi0
        e1 = a1 @ p + m * self.phi1
        h, cc = self.h_cols, self.c_cols
        g_h, c, g_c = self.gains(p)
        gh, gc = g_h[:, None], g_c[:, None]
        # d r / d p = (d e / d p - r d g / d p) / g per channel, the crowd channel's e
        # being e1 + c e0; the gains move only with the drives' columns (h, cc), the
        # other columns are the equations' own over their gains. Equation-major in
        # memory (each channel's rows contiguous, as these operations run), (N, 2, P)
        # in shape.
        by_eq = np.empty((2, len(m), len(p)))
        j0, j1 = by_eq
        jac = by_eq.transpose(1, 0, 2)
        r_h = e0 / g_h
        np.divide(a0, gh, out=j0)
        j0[:, h] = (a0[:, h] - r_h[:, None] * self.dh0) / gh
        np.multiply(c[:, None], a0, out=j1)
        j1 += a1
        # d c / d p (zero but for rounding while the hoist current acts through one rope
        # on both equations, as in every model so far: kept for one where it does not)
        dc_dp = -(self.dh1 * gh + (c * g_h)[:, None] * self.dh0) / (g_h**2)[:, None]
        j1[:, h] += e0[:, None] * dc_dp
        n = e1 + c * e0
        j1[:, cc] -= (n / g_c)[:, None] * self.dc1
        j1 /= gc
        if self.offsets is not None:
            jac[:, 0, self.offsets[0]] -= 1.0
            jac[:, 1, self.offsets[1]] -= 1.0
        return jac

    def model_variance(self, p: np.ndarray) -> np.ndarray:
        """(N, 2) A^2: the variance of each channel's predicted current that comes from
        the model's own uncertain columns (``Model.column_spread``: the friction's sign
        near standstill), taken as independent between columns."""
        if not len(self.spread_idx):
            return np.zeros((len(self), 2))
        g_h, c, g_c = self.gains(p)
        ps = p[self.spread_idx]
        s0 = self.spread0 * ps
        s1 = self.spread1 * ps + c[:, None] * s0
        return pair(np.sum(s0 * s0, axis=1) / g_h**2, np.sum(s1 * s1, axis=1) / g_c**2)

    def currents(self) -> np.ndarray:
        """(N, 2) the measured hoist (sum) and crowd currents these equations explain."""
        return pair(self.i_h, self.i_c)


NOISE_KEYS = ("floor_a", "rel", "handle_acc_a", "crowd_acc_a", "tau")
"""Per channel: a floor (A), a part of the reading, parts per unit of the handle's
(rad/s^2) and the crowd's (m/s^2) acceleration (where the estimated rates are least
exact), and the residuals' integrated autocorrelation time (samples)."""


def noise_regressors(i: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """(N, 2, 4): what each channel's noise variance is linear in: 1, i^2, th''^2, d''^2."""
    out = np.empty((len(i), 2, 4))
    out[:, :, 0] = 1.0
    out[:, :, 1] = i ** 2
    out[:, :, 2] = (acc[:, 0] ** 2)[:, None]
    out[:, :, 3] = (acc[:, 1] ** 2)[:, None]
    return out


@functools.lru_cache(maxsize=64)
def _noise_coef(floor_a: float, rel: float, handle_acc_a: float, crowd_acc_a: float
                ) -> np.ndarray:
    """One channel's noise coefficients, squared: the same for every block of a pass."""
    out = np.array([floor_a, rel, handle_acc_a, crowd_acc_a], dtype=float) ** 2
    out.flags.writeable = False
    return out


def noise_sigma(noise: dict[str, dict[str, float]] | None, i: np.ndarray, acc: np.ndarray
                ) -> np.ndarray:
    """(N, 2) noise std per channel for measured currents ``i`` (N, 2) and the joints'
    accelerations ``acc`` (N, 2: handle, crowd), from the calibration's noise model."""
    if not noise:
        raise ValueError("the params file has no current noise model ([current_noise]); "
                         "calibrate again with this version")
    reg = noise_regressors(i, acc)
    out = np.empty_like(i, dtype=float)
    for j, ch in enumerate(CHANNELS):
        n = noise[ch]
        coef = _noise_coef(n["floor_a"], n["rel"], n["handle_acc_a"], n["crowd_acc_a"])
        out[:, j] = np.sqrt(reg[:, j] @ coef)
    return out


def current_sigma(noise: dict[str, dict[str, float]] | None, ce: CurrentEquations,
                  p: np.ndarray) -> np.ndarray:
    """(N, 2) each sample's std per channel: the calibration's noise model and what the
    model itself does not know there (``CurrentEquations.model_variance``)."""
    sig = noise_sigma(noise, ce.currents(), ce.acc)
    return np.sqrt(sig * sig + ce.model_variance(p))
