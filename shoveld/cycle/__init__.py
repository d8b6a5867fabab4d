"""Dig-cycle recognition."""

from shoveld.cycle.phases import PHASES, PhaseConfig, PhaseMachine

__all__ = ["PHASES", "PhaseConfig", "PhaseMachine"]
