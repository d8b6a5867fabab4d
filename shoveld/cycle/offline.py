"""Phase labels for a whole table, from offline kinematics (used to exclude digging)."""

from __future__ import annotations

import numpy as np

from shoveld.cycle.phases import PhaseConfig, PhaseMachine
from shoveld.model.kin import Kinematics


def label_phases(kin: Kinematics, cfg: PhaseConfig | None = None) -> np.ndarray:
    """Phase index per sample (the same state machine as the live loop)."""
    pm = PhaseMachine(cfg)
    out = np.zeros(len(kin), dtype=np.int8)
    th = np.degrees(kin.th).tolist()
    thd = np.degrees(kin.thd).tolist()
    swr = np.degrees(kin.swing_rate).tolist()
    dd = kin.dd.tolist()
    for j, t in enumerate(kin.t.tolist()):
        out[j] = pm.update(t, th[j], thd[j], swr[j], dd[j])
    return out
