"""Shared simulated data for the engine tests (simulated once per session)."""

from __future__ import annotations

import pytest

from shoveld.identify.calibrate import Calibrator
from shoveld.model.params import ModelParams
from shoveld.sim.scenario import SimResult, simulate_calibration, simulate_cycles


@pytest.fixture(scope="session")
def calib_trials() -> tuple[SimResult, SimResult]:
    return simulate_calibration(0.0, seed=101), simulate_calibration(8420.0, seed=102)


@pytest.fixture(scope="session")
def params(calib_trials: tuple[SimResult, SimResult]) -> ModelParams:
    cal = Calibrator().fit([calib_trials[0].table, calib_trials[1].table])
    assert cal.params_ is not None
    return cal.params_


@pytest.fixture(scope="session")
def cycles() -> SimResult:
    return simulate_cycles(10, seed=103, payload_range=(3000.0, 35000.0))
