"""Savitzky-Golay smoothing and differentiation on numpy alone.

The method is a local polynomial least-squares fit; its coefficients are the
minimum-norm solution of a small Vandermonde system. ``scipy.signal`` does the same
(and is the oracle of ``tests/engine/test_filters.py``), but importing it costs
0.6-2 s, which every daemon start and every replay paid for a few dozen numbers
(``bench/startup.py``). The results agree with scipy's to rounding.
"""

from __future__ import annotations

import math

import numpy as np

from shoveld.words import n_of


def savgol_coeffs(window: int, polyorder: int, deriv: int = 0, delta: float = 1.0,
                  pos: int | None = None, use: str = "conv",
                  keep: np.ndarray | None = None) -> np.ndarray:
    """Weights that give the ``deriv``-th derivative of the fitted polynomial at ``pos``
    (default: the centre) of a ``window``-sample stretch spaced ``delta`` apart.

    ``use="dot"``: to be applied as ``coeffs @ samples`` in time order; ``"conv"``:
    reversed, for ``np.convolve``. ``keep`` (``"dot"`` only): the samples to fit, when
    some are missing; the weights returned are for those alone.
    """
    if window < 1 or polyorder >= window or deriv > polyorder:
        raise ValueError(f"savgol: window {window}, order {polyorder}, derivative {deriv} "
                         "(need order < window and derivative <= order)")
    if pos is None:
        pos = window // 2
    x = np.arange(-pos, window - pos, dtype=float)
    if use == "conv":
        x = x[::-1]
    elif keep is not None:
        x = x[keep]
        if len(x) <= polyorder:
            raise ValueError(f"savgol: {n_of(len(x), 'sample', 'samples')} kept, need more "
                             f"than order {polyorder}")
    # Powers of x/scale, not of x: x**9 over +-40 samples spans 18 decades, and lstsq's
    # cut-off then drops the high orders (scipy's savgol_coeffs does, and returned a
    # 9th-order fit's value and acceleration wrong by 100 % over 81 samples). The
    # weights are the same least-squares ones, the target rescaled to match.
    scale = max(float(np.max(np.abs(x))), 1.0)
    vander = (x / scale)[None, :] ** np.arange(polyorder + 1)[:, None]
    target = np.zeros(polyorder + 1)
    target[deriv] = math.factorial(deriv) / (delta * scale)**deriv
    coeffs, *_ = np.linalg.lstsq(vander, target, rcond=None)
    return coeffs


def savgol_filter(y: np.ndarray, window: int, polyorder: int, deriv: int = 0,
                  delta: float = 1.0) -> np.ndarray:
    """Smoothed ``y`` (or its derivative) with the edges from a polynomial fitted to the
    first and last ``window`` samples (scipy's ``mode="interp"``)."""
    y = np.asarray(y, dtype=float)
    n = len(y)
    if n < window:
        raise ValueError(f"savgol: {n_of(n, 'sample', 'samples')}, fewer than the window {window}")
    half = window // 2
    out = np.empty(n)
    out[half:n - half] = np.convolve(y, savgol_coeffs(window, polyorder, deriv, delta),
                                     mode="valid")
    x = np.arange(window, dtype=float)
    for lo, hi, sl in ((0, half, slice(0, window)), (window - half, window,
                                                     slice(n - window, n))):
        poly = np.polynomial.Polynomial.fit(x, y[sl], polyorder).convert()
        vals = poly.deriv(deriv)(x[lo:hi]) / delta**deriv if deriv else poly(x[lo:hi])
        if lo == 0:
            out[:half] = vals
        else:
            out[n - half:] = vals
    return out
