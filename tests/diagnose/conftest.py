"""Simulated sessions with hidden effects for the diagnosis tests."""

from __future__ import annotations

import zlib
from typing import Any

import numpy as np

from shoveld.signals.table import SignalsTable
from shoveld.sim.effects import SIM_EFFECTS, make_effects
from shoveld.sim.machine import Machine
from shoveld.sim.scenario import simulate_calibration, simulate_cycles

PASSES = 24


def draw(name: str) -> tuple[float, int]:
    """A magnitude from the effect's typical range and a seed, drawn per effect name."""
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    lo, hi = SIM_EFFECTS[name].typical_range
    return float(rng.uniform(lo, hi)), int(rng.integers(1, 100_000))


def session(spec: dict[str, float], seed: int, passes: int = PASSES, *,
            machine: Machine | None = None, form: str = "test"
            ) -> tuple[list[SignalsTable], list[SignalsTable], Any]:
    """Empty and 8,420 kg calibration trials and a session of cycles (3-35 t, about half
    scale-verified), all with the effects in ``spec`` (in their ``form``) and the default
    sensor noise; on ``machine`` (a realistic one from ``Machine.draw``) if given."""

    def fx() -> list[Any]:
        return make_effects(dict(spec), form=form)

    c0 = simulate_calibration(0.0, seed + 1, effects=fx(), machine=machine)
    c1 = simulate_calibration(8420.0, seed + 2, effects=fx(), machine=machine)
    ops = simulate_cycles(passes, seed + 3, payload_range=(3000.0, 35000.0),
                          truck_target_kg=None, verified_fraction=0.5, effects=fx(),
                          machine=machine)
    return [c0.table, c1.table], [ops.table], ops
