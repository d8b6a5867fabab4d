"""Kinematic context: joint positions, rates, accelerations and currents, as arrays.

Terms of the model read what they need from here; the context is built either by
offline zero-phase smoothing (identification) or sample by sample by the causal
filter of the live loop (one sample = arrays of length 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shoveld.model.geometry import rope_geometry


@dataclass
class Kinematics:
    """Everything a model term may use, SI units, angles in radians."""

    t: np.ndarray
    th: np.ndarray
    thd: np.ndarray
    thdd: np.ndarray
    d: np.ndarray
    dd: np.ndarray
    ddd: np.ndarray
    boom: np.ndarray
    i_h: np.ndarray
    """Total hoist armature current (sum of both motors), A."""
    i_c: np.ndarray
    i_hf: np.ndarray
    """Hoist field current, A."""
    swing: np.ndarray
    swing_rate: np.ndarray
    swing_acc: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    i_h_est: np.ndarray | None = None
    """Hoist current estimated from the neighbouring samples only (default: i_h). Terms
    nonlinear in the current use it: its noise is independent of this sample's, so
    it does not correlate with the current on the other side of the equation."""
    i_c_est: np.ndarray | None = None
    """Likewise for the crowd current."""
    l_sd: np.ndarray = field(init=False)
    sin_a3: np.ndarray = field(init=False)
    cos_a3: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.l_sd, self.sin_a3, self.cos_a3 = rope_geometry(self.th, self.d, self.boom)
        if self.i_h_est is None:
            self.i_h_est = self.i_h
        if self.i_c_est is None:
            self.i_c_est = self.i_c

    def estimate_currents(self, window: int) -> None:
        """Set ``i_h_est``/``i_c_est`` by leave-one-out Savitzky-Golay smoothing.

        The cubic fit over ``window`` samples minus the centre sample's own share: exact
        for currents that are cubic over the window, independent of the centre's noise.
        """
        from shoveld.kinematics.savgol import savgol_coeffs

        window = max(5, window | 1)
        c = savgol_coeffs(window, 3, use="conv")
        w0 = c[window // 2]
        loo = c.copy()
        loo[window // 2] = 0.0
        loo /= 1.0 - w0
        for src, dst in (("i_h", "i_h_est"), ("i_c", "i_c_est")):
            x = getattr(self, src)
            out = x.copy()
            ok = np.isfinite(x)
            edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
            for a, b in zip(edges[::2], edges[1::2], strict=True):
                if b - a >= window:
                    half = window // 2
                    out[a + half:b - half] = np.convolve(x[a:b], loo, mode="valid")
            setattr(self, dst, out)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def take(self, idx: np.ndarray) -> Kinematics:
        """The context restricted to ``idx`` (a mask or an index array)."""
        names = ("t", "th", "thd", "thdd", "d", "dd", "ddd", "boom", "i_h", "i_c", "i_hf",
                 "swing", "swing_rate", "swing_acc", "roll", "pitch", "i_h_est", "i_c_est")
        return Kinematics(**{n: getattr(self, n)[idx] for n in names})
