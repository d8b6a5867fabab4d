"""A pass's misfit, as the daemon records it and the tools show it.

The misfit is the mean square of a pass's residuals in units of the size the
calibration's noise model gives them (``PayloadRls.misfit``): about 1 when the model
holds, 16 for residuals four times that size. No import beyond the standard library:
``shoveld passes`` and ``report`` show it.
"""

from __future__ import annotations

import math

MISFIT_WARN = 3.0
"""Above this, a pass's currents are not what the model of this machine says: the model
lacks something the machine does, or a sensor measures something else. The pass is
still weighed; the daemon logs a warning and the shift report names the pass. Measured
(``bench/pass_misfit.py``): 1,080 passes of 18 realistic simulated machines at most
1.04 (median 0.76), the committed capture's 0.64-0.84; a swing the model leaves out
4.6-123; something lodged on the handle, in the laser's beam, 62-578."""


MISFIT_RECENT = 10
"""The last passes the daemon's health counts the high misfits of."""
MISFIT_PERSISTENT = 5
"""A machine with at least this many of the last ``MISFIT_RECENT`` passes above the level
has a problem health names (the cab's strip, the office's card), not a stray pass: the
passes of 18 realistic machines as calibrated were never above it (0 of 1,080), a swing
the model lacks puts every pass above it (48 of 48, ``bench/pass_misfit.py --effects
--extend``), something on the handle one or two."""


def round_misfit(m: float | None) -> float | None:
    """A misfit as recorded and published: two decimals, None when there is none (a pass
    without a valid sample)."""
    return None if m is None or not math.isfinite(m) else round(m, 2)


def misfit_high(m: float | None, warn: float = MISFIT_WARN) -> bool:
    """Whether a recorded misfit (None: none) is above the warning level."""
    return m is not None and m > warn


def misfit_note(m: float | None, warn: float = MISFIT_WARN) -> str:
    """What a pass's line adds for a high misfit ("" otherwise): the tools that print
    passes line by line (``estimate``, ``replay``, ``passes``) say it the same way."""
    if m is None or not m > warn:
        return ""
    return f"  misfit {m:.1f}: the model does not fit this pass"
