"""The angles' smoothings (identification's, the payload's): recorded with the fitted
parameters, followed by the engine."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from shoveld.engine.loop import Engine, EngineConfig
from shoveld.identify.calibrate import Calibrator
from shoveld.kinematics import (
    DEFAULT_POLYORDER,
    DEFAULT_WINDOW_S,
    LEGACY_POLYORDER,
    LEGACY_WINDOW_S,
    PAYLOAD_POLYORDER,
    PAYLOAD_WINDOW_S,
)
from shoveld.kinematics.fixed_lag import FixedLagSavgol
from shoveld.model.params import ModelParams, load_params, save_params
from shoveld.sim.scenario import SimResult


def test_the_engine_smooths_as_the_params_record(
        calib_trials: tuple[SimResult, SimResult], tmp_path: Path) -> None:
    """The identification's smoothing and the payload equations' own are both recorded;
    the engine takes the payload's."""
    cal = Calibrator(window_s=0.82, polyorder=5, payload_window_s=1.2,
                     payload_polyorder=3).fit([r.table for r in calib_trials])
    assert cal.params_ is not None
    save_params(tmp_path / "p.toml", cal.params_)
    p = load_params(tmp_path / "p.toml")
    assert p.fit["window_s"] == 0.82 and p.fit["polyorder"] == 5
    assert p.fit["payload_window_s"] == 1.2 and p.fit["payload_polyorder"] == 3
    e = Engine(p)
    assert (e.window_s, e.polyorder, e.lagged.window) == (1.2, 3, 61)
    # configured explicitly, the configuration wins
    assert Engine(p, EngineConfig(window_s=0.5, polyorder=3)).lagged.window == 25


def test_the_calibration_records_the_payloads_smoothing_by_default(params: ModelParams
                                                                  ) -> None:
    e = Engine(params)
    assert (e.window_s, e.polyorder) == (PAYLOAD_WINDOW_S, PAYLOAD_POLYORDER)
    assert (params.fit["window_s"], params.fit["polyorder"]) == (DEFAULT_WINDOW_S,
                                                                 DEFAULT_POLYORDER)


def test_params_from_before_the_payloads_own_smoothing_estimate_as_they_did(
        params: ModelParams) -> None:
    """A params file that records only the identification's smoothing (written before
    2026-11-26, seventh session) is estimated with it, as it was."""
    old = dataclasses.replace(params, fit={k: v for k, v in params.fit.items()
                                           if not k.startswith("payload_")}
                              | {"window_s": 0.82, "polyorder": 5})
    e = Engine(old)
    assert (e.window_s, e.polyorder) == (0.82, 5)


def test_params_that_do_not_say_are_read_as_identified_before_it_was_recorded(
        params: ModelParams) -> None:
    old = dataclasses.replace(params, fit={k: v for k, v in params.fit.items()
                                           if k not in ("window_s", "polyorder",
                                                        "payload_window_s",
                                                        "payload_polyorder")})
    e = Engine(old)
    assert (e.window_s, e.polyorder) == (LEGACY_WINDOW_S, LEGACY_POLYORDER)


@pytest.mark.parametrize(("window_s", "order", "low", "high"),
                         [(0.5, 3, 0.80, 0.87), (0.82, 5, 0.93, 0.98)])
def test_how_much_of_a_1_hz_acceleration_each_fit_keeps(window_s: float, order: int,
                                                        low: float, high: float) -> None:
    """Why J is biased with the cubic: it keeps 84 % of a 1 Hz stroke's acceleration."""
    dt = 0.02
    f: FixedLagSavgol[int] = FixedLagSavgol(window_s, dt, 1, order)
    w = 2 * np.pi * 1.0
    got, want = [], []
    for i in range(400):
        out = f.push(i * dt, (float(np.sin(w * i * dt)),), i)
        if out is not None:
            assert out[0] is not None  # every sample pushed has its index as its tag
            got.append(out[1][2, 0])
            want.append(-w * w * np.sin(w * out[0] * dt))
    gain = np.std(got) / np.std(want)
    assert low < gain < high
