"""Checks of a signals table's values against what the machine can do.

The daemon's laser driver drops a distance the handle cannot have moved to (see
``docs/drivers-ar4000.md``). A table from another logger has had no such driver: these
checks let the commands that read tables say where its crowd extension does what no
handle does, so the field engineer knows before trusting the numbers.
"""

from __future__ import annotations

import numpy as np

from shoveld.installation import CROWD_SPEED_MAX_MPS, LASER_STEP_NOISE_M
from shoveld.signals.table import SignalsTable


def crowd_jumps(table: SignalsTable, max_speed_mps: float = CROWD_SPEED_MAX_MPS,
                noise_m: float = LASER_STEP_NOISE_M) -> np.ndarray:
    """Row indices where ``crowd_m`` changes by more than the handle moves since its
    last change (a table may hold each laser sample over several rows; at least one row's
    interval, so a repeated time stamp is no jump), plus the noise. Blank (NaN) cells are
    skipped."""
    t, x = table.time, table["crowd_m"]
    ok = np.flatnonzero(np.isfinite(x) & np.isfinite(t))
    if len(ok) < 2:
        return np.zeros(0, dtype=np.int64)
    xs, ts = x[ok], t[ok]
    moved = np.flatnonzero(np.diff(xs) != 0.0) + 1  # rows (in ok) where the value changes
    if len(moved) == 0:
        return np.zeros(0, dtype=np.int64)
    # each change against the value before it, over the time since the change before
    last = np.concatenate([[0], moved[:-1]])
    dt = np.maximum(ts[moved] - ts[last], float(np.median(np.diff(ts))))
    step = np.abs(xs[moved] - xs[moved - 1])
    return ok[moved[step > max_speed_mps * dt + noise_m]]
