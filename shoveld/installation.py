"""Installation geometry: device readings <-> joint variables of the signals table.

The arm-geometry sensor sits on the saddle block: the MTi pitch is the handle
angle (plus a mounting offset), its yaw the swing angle against a configured
zero, and the laser distance maps affinely to crowd extension. Both directions
live here so the daemon (device -> joints) and the virtual hardware
(joints -> device) use one set of numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    import numpy as np

Value = TypeVar("Value", float, "np.ndarray")
"""A reading or a column of them: the conversions are elementwise (bulk replay)."""

CROWD_SPEED_MAX_MPS = 3.0
"""The fastest the handle moves along the laser's beam: above the 2 m/s the field trial
tested the AR4000 at (the thesis, section 3.4) and the 2.1 m/s the simulated crowd
reaches. A crowd extension further than this from the last one is not the handle (the
laser driver's ``max_speed_mps``; the tables' check, ``shoveld.signals.checks``)."""
LASER_STEP_NOISE_M = 0.01
"""What two laser distances of a handle at rest may differ by (its 3 mm accuracy on
each, its 1 mm step): the driver's ``jump_noise_m``."""


@dataclass(frozen=True)
class Installation:
    """Mounting constants of one shovel, from the installer's survey."""

    handle_pitch_offset_deg: float = 0.0
    """handle_deg = mti_pitch_deg * handle_pitch_sign + offset."""
    handle_pitch_sign: float = 1.0
    swing_yaw_zero_deg: float = 0.0
    """swing_deg = wrap(mti_yaw_deg - zero) * swing_yaw_sign."""
    swing_yaw_sign: float = 1.0
    crowd_offset_m: float = 5.88
    """crowd_m = crowd_offset_m + crowd_gain * laser_m (laser 4.91 m range over the
    6 .. 10.79 m crowd stroke, model-notes)."""
    crowd_gain: float = 1.0

    def handle_deg(self, mti_pitch_deg: Value) -> Value:
        return self.handle_pitch_sign * mti_pitch_deg + self.handle_pitch_offset_deg

    def mti_pitch_deg(self, handle_deg: Value) -> Value:
        return (handle_deg - self.handle_pitch_offset_deg) / self.handle_pitch_sign

    def swing_deg(self, mti_yaw_deg: Value) -> Value:
        return self.swing_yaw_sign * wrap_deg(mti_yaw_deg - self.swing_yaw_zero_deg)

    def mti_yaw_deg(self, swing_deg: Value) -> Value:
        return wrap_deg(swing_deg / self.swing_yaw_sign + self.swing_yaw_zero_deg)

    def crowd_m(self, laser_m: Value) -> Value:
        return self.crowd_offset_m + self.crowd_gain * laser_m

    def laser_m(self, crowd_m: Value) -> Value:
        return (crowd_m - self.crowd_offset_m) / self.crowd_gain


def wrap_deg(a: Value) -> Value:
    """Angle into [-180, 180)."""
    return (a + 180.0) % 360.0 - 180.0


def unwrap_deg(prev: float, a: float) -> float:
    """Continue ``a`` from ``prev`` across the +-180 wrap (swing passes through it)."""
    if math.isnan(prev):
        return a
    return prev + wrap_deg(a - prev)
