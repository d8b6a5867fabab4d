"""Planar arm geometry in the swing plane (model-notes, "Geometry").

Pivot O is the saddle-block shaft, x outward, y up. The bail is at P = d u with
u = (cos th, sin th); the boom-point sheave at B = L_BS (cos b, sin b). The hoist
rope runs from P to B. Signed forms are used instead of the interior angle a3 so
a rope that passes over the handle cannot silently flip a sign.
"""

from __future__ import annotations

import numpy as np

G = 9.81
"""Gravitational acceleration, m/s^2."""
L_BS = 9.21
"""Saddle-block shaft to boom-point sheave, m (P&H 2100, model-notes)."""


def rope_geometry(th: np.ndarray, d: np.ndarray, boom: np.ndarray, l_bs: float = L_BS
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rope length l_SD, sin(a3) and cos(a3) for handle angle ``th`` (rad), crowd ``d`` (m)
    and boom angle ``boom`` (rad).

    A rope tension F gives the torque ``d * F * sin_a3`` about O and the force
    ``-F * cos_a3`` along +u.
    """
    cth, sth = np.cos(th), np.sin(th)
    rx = l_bs * np.cos(boom) - d * cth
    ry = l_bs * np.sin(boom) - d * sth
    l_sd = np.hypot(rx, ry)
    sin_a3 = (cth * ry - sth * rx) / l_sd
    cos_a3 = -(cth * rx + sth * ry) / l_sd
    return l_sd, sin_a3, cos_a3
