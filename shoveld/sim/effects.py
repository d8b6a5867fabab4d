"""Physical effects the simulator can switch on, each with a magnitude.

An effect changes the simulated world, never the model: it adds a body, a force,
a friction law, a drive characteristic or a sensor fault through the hook points
of :class:`shoveld.sim.plant.Plant` and :func:`shoveld.sim.scenario.measure`.
The model-side term that tries to explain it lives in ``shoveld.model`` and is
written independently (see ``docs/diagnosis.md``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

SIM_EFFECTS: dict[str, type[SimEffect]] = {}


def register_effect(cls: type[SimEffect]) -> type[SimEffect]:
    if cls.name in SIM_EFFECTS:
        raise ValueError(f"sim effect {cls.name!r} registered twice")
    SIM_EFFECTS[cls.name] = cls
    return cls


class SimEffect:
    """Base class: every hook defaults to "no change"."""

    name: ClassVar[str]
    default_magnitude: ClassVar[float] = 1.0
    magnitude_unit: ClassVar[str] = ""
    description: ClassVar[str] = ""

    def __init__(self, magnitude: float | None = None) -> None:
        self.magnitude = self.default_magnitude if magnitude is None else float(magnitude)

    def before_dynamics(self, ctx: dict[str, Any]) -> None:
        """May set ctx['boom_true'] or ctx['gravity'] ((N,2) or (2,)) before dynamics."""

    def bodies(self, ctx: dict[str, Any]) -> None:
        """May add or replace entries of ctx['bodies']."""

    def extra_forces(self, ctx: dict[str, Any]) -> np.ndarray:
        """(N, 2) generalized forces the actuators must supply in addition."""
        return 0.0  # type: ignore[return-value]

    def friction(self, ctx: dict[str, Any], fric: np.ndarray) -> np.ndarray:
        return fric

    def before_currents(self, ctx: dict[str, Any]) -> None:
        """May change ctx['i_hf'] (hoist field) or the required forces."""

    def currents(self, ctx: dict[str, Any]) -> None:
        """May change ctx['i_h'], ctx['i_c'] (drive characteristics)."""

    def measure(self, cols: dict[str, np.ndarray], ctx: dict[str, Any],
                rng: np.random.Generator) -> None:
        """May change the measured columns (sensor effects), in place."""


def make_effects(spec: dict[str, float | None]) -> list[SimEffect]:
    """Effects from {name: magnitude or None for the default}."""
    unknown = [n for n in spec if n not in SIM_EFFECTS]
    if unknown:
        raise ValueError(f"unknown sim effect(s) {unknown}; known: {sorted(SIM_EFFECTS)}")
    return [SIM_EFFECTS[n](m) for n, m in spec.items()]
