"""A pass's misfit, recorded with the pass: a machine doing something the model lacks shows
there, a machine the model describes does not.

The effect is hidden in the simulated machine's physics (the swing's centrifugal pull on
the dipper and its load, ``shoveld.sim.effects``, in the tests' form), on realistic
machines (offsets, gain errors, 12-bit currents, field weakening), and the base model is
calibrated on the machine's own trials, as a field engineer would.
"""

from __future__ import annotations

import logging
import math

import pytest

from shoveld.engine.offline import estimate_table
from shoveld.identify.calibrate import Calibrator
from shoveld.model.params import ModelParams
from shoveld.payload.misfit import MISFIT_WARN, misfit_note, round_misfit
from shoveld.sim.effects import SIM_EFFECTS, SimEffect, make_effects
from shoveld.sim.machine import Machine
from shoveld.sim.scenario import SimResult, simulate_calibration, simulate_cycles

PASSES = 12


def calibrated_session(spec: dict[str, float], seed: int, passes: int = PASSES
                       ) -> tuple[ModelParams, SimResult]:
    """A realistic machine with the effects of ``spec`` (fresh for each table, in the
    tests' form): the base model calibrated on its two trials, and ``passes`` passes of
    3-35 t on it."""
    machine = Machine.draw(seed)

    def fx() -> list[SimEffect]:
        return make_effects(dict(spec), form="test")

    trials = [simulate_calibration(kg, seed + k, effects=fx(), machine=machine).table
              for k, kg in ((1, 0.0), (2, 8420.0))]
    ops = simulate_cycles(passes, seed + 3, payload_range=(3000.0, 35000.0),
                          truck_target_kg=None, effects=fx(), machine=machine)
    params = Calibrator(method="output").fit(trials).params_
    assert params is not None
    return params, ops


def misfits(spec: dict[str, float], seed: int,
            caplog: pytest.LogCaptureFixture) -> tuple[list[float], list[str]]:
    """Each pass's misfit on a realistic machine with the effects of ``spec``, and the
    engine's warnings, the base model calibrated on that machine's two trials."""
    params, ops = calibrated_session(spec, seed)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="shoveld.engine.loop"):
        est = estimate_table(ops.table, params)
    assert len(est.passes) >= PASSES - 1
    warned = [r.getMessage() for r in caplog.records if "misfit" in r.getMessage()]
    return [p.misfit for p in est.passes], warned


@pytest.mark.parametrize("seed", [1000, 2000])
def test_the_model_that_describes_the_machine_fits_every_pass(
        seed: int, caplog: pytest.LogCaptureFixture) -> None:
    ms, warned = misfits({}, seed, caplog)
    assert all(math.isfinite(m) and 0.0 < m <= MISFIT_WARN for m in ms), ms
    assert warned == []


@pytest.mark.parametrize("seed", [1000, 2000])
def test_a_swing_the_model_lacks_shows_in_the_misfit_of_most_passes(
        seed: int, caplog: pytest.LogCaptureFixture) -> None:
    # the bottom of the effect's typical range: the hardest case to see
    size = SIM_EFFECTS["swing_centrifugal"].typical_range[0]
    ms, warned = misfits({"swing_centrifugal": size}, seed, caplog)
    high = [m for m in ms if m > MISFIT_WARN]
    assert len(high) >= 0.75 * len(ms), ms
    # warned at the first such pass (and the tenth), not at every one
    assert 1 <= len(warned) <= 2 and "(1 such pass so far)" in warned[0]
    assert "shoveld diagnose" in warned[0]


def test_a_misfit_is_recorded_with_two_decimals_and_named_only_when_high() -> None:
    assert round_misfit(0.8349) == 0.83 and round_misfit(math.nan) is None
    assert round_misfit(None) is None
    assert misfit_note(0.83) == "" and misfit_note(None) == ""
    assert misfit_note(18.25) == "  misfit 18.2: the model does not fit this pass"
    assert misfit_note(2.5, warn=2.0) != ""  # the daemon's own level where it is set
