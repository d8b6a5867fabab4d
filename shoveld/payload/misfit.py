"""A pass's misfit, as the daemon records it and the tools show it.

The misfit is the mean square of a pass's residuals in units of the size the
calibration's noise model gives them (``PayloadRls.misfit``): about 1 when the model
holds, 16 for residuals four times that size. No import beyond the standard library:
``shoveld passes`` and ``report`` show it. The calibration's own check of its verified
passes against its trials lives here too, as the daemon's health reads it.
"""

from __future__ import annotations

import math

MISFIT_WARN = 3.0
"""Above this, a pass's currents are not what the model of this machine says: the model
lacks something the machine does, or a sensor measures something else. The pass is
still weighed (unless the crowd's laser lost the handle before it, and the pass fits far
worse than the machine's usual: ``shoveld.engine.loop.CrowdDoubt``); the daemon logs a
warning and the shift report names the pass. Measured
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


PASSES_TO_TRIALS_WARN = 1.5
"""The RMS of the verified passes' residuals over the trials' in one calibration
(``calibrate --verified`` records it as ``fit.passes_to_trials_rms``), above which the
model lacks something operation excites: 1.02-1.18 on 54 realistic simulated machines
(hoist; the crowd 0.99-1.04); 2.05-3.17 with a swing the model lacks (2.2-2.7 crowd;
eight machines); a 7° slope 2.05 (crowd) on one of two machines; every other simulated
effect at either end of its range at most 1.47 (a friction growing with the load,
crowd), and a sensor out of step below 1 (its trials fit worse; the empty dipper sees
it). The misfit the daemon marks passes by is read against this calibration's noise,
which then takes the missing term in: a swing that marked 48 of 48 passes with the
trials' noise marked 13-14 of 48 with this one (``bench/pass_misfit.py --effects
--extend``), so ``calibrate``, ``check-config`` and the daemon's health say it from the
recorded ratio instead."""


def passes_to_trials_above(ratio: object, warn: float = PASSES_TO_TRIALS_WARN
                           ) -> dict[str, float]:
    """The channels of a calibration's recorded passes-to-trials ratio (``fit.
    passes_to_trials_rms``: a table of channel -> ratio, or absent) above ``warn``."""
    if not isinstance(ratio, dict):
        return {}
    return {str(ch): float(r) for ch, r in ratio.items()
            if isinstance(r, int | float) and r > warn}


def calibration_note(fit: dict[str, object]) -> str:
    """What a params file's fit record (``ModelParams.fit``) says of its calibration, for
    ``calibrate`` and ``check-config`` ("" when nothing)."""
    return passes_to_trials_note(passes_to_trials_above(fit.get("passes_to_trials_rms")))


def passes_to_trials_note(above: dict[str, float], warn: float = PASSES_TO_TRIALS_WARN) -> str:
    """What ``calibrate``, ``check-config`` and the daemon's health say of a calibration
    whose verified passes fit worse than its trials ("" when none is above ``warn``)."""
    if not above:
        return ""
    times = ", ".join(f"{ch} {r:.1f}" for ch, r in above.items())
    return (f"the calibration's passes fit worse than its trials ({times} times): above "
            f"{warn:g}, the model lacks something this machine does in operation (a swing, a "
            "slope), which the misfit will not mark; shoveld diagnose names it")
