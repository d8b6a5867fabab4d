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
    l_sd: np.ndarray = field(init=False)
    sin_a3: np.ndarray = field(init=False)
    cos_a3: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.l_sd, self.sin_a3, self.cos_a3 = rope_geometry(self.th, self.d, self.boom)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def take(self, idx: np.ndarray) -> Kinematics:
        """The context restricted to ``idx`` (a mask or an index array)."""
        names = ("t", "th", "thd", "thdd", "d", "dd", "ddd", "boom", "i_h", "i_c", "i_hf",
                 "swing", "swing_rate", "swing_acc", "roll", "pitch")
        return Kinematics(**{n: getattr(self, n)[idx] for n in names})
