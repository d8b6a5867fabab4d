"""Dig-cycle phase recognition from joint motion.

A small state machine over the causal joint estimates. The payload filter runs
only in LIFT and SWING, where the dipper hangs free and the model holds; DIG
(bank forces), DUMP (mass leaving) and RETURN (lowering on the weak hoist field)
are excluded. Thresholds are per-site settings, not constants of nature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

PHASES: tuple[str, ...] = ("idle", "dig", "lift", "swing", "dump", "return")
IDLE, DIG, LIFT, SWING, DUMP, RETURN = range(6)
ESTIMATING = frozenset({LIFT, SWING})


@dataclass(frozen=True)
class PhaseConfig:
    """Thresholds of the phase machine (degrees, degrees per second, seconds)."""

    tuck_deg: float = -25.0
    """Below this handle angle a rising dipper starts a dig."""
    dig_exit_deg: float = -4.0
    """The dipper has left the bank when the handle rises above this angle."""
    rise_deg_s: float = 1.5
    """Handle rate that counts as rising."""
    swing_on_deg_s: float = 4.0
    swing_off_deg_s: float = 1.5
    stop_hold_s: float = 0.3
    """The swing must stay below ``swing_off`` this long to count as stopped."""
    idle_rate_deg_s: float = 1.5
    """Handle slower than this, swing slower than ``idle_swing_deg_s`` and crowd slower than
    ``idle_crowd_m_s`` (each above its filter's largest noise at rest) for ``idle_hold_s``
    means the machine is idle."""
    idle_swing_deg_s: float = 3.0
    idle_crowd_m_s: float = 0.08
    idle_hold_s: float = 10.0
    min_dig_s: float = 2.0

    RANGES: ClassVar[dict[str, dict[str, float | bool]]] = {
        **{k: {"positive": True} for k in (
            "rise_deg_s", "swing_on_deg_s", "swing_off_deg_s", "idle_rate_deg_s",
            "idle_swing_deg_s", "idle_crowd_m_s", "idle_hold_s")},
        "stop_hold_s": {"lo": 0.0}, "min_dig_s": {"lo": 0.0},
        "tuck_deg": {"lo": -90.0, "hi": 90.0}, "dig_exit_deg": {"lo": -90.0, "hi": 90.0}}
    """What the configuration may set each threshold to (``shoveld.daemon.config``):
    rates and holds above zero, handle angles within a quarter turn."""


class PhaseMachine:
    """Feed one sample at a time; ``phase`` is the current phase index."""

    def __init__(self, cfg: PhaseConfig | None = None) -> None:
        self.cfg = cfg or PhaseConfig()
        self.phase = IDLE
        self.since = -math.inf
        self._slow_since: float | None = None
        self._still_since: float | None = None
        self._swing_dir = 0.0

    def _enter(self, phase: int, t: float) -> None:
        self.phase = phase
        self.since = t
        self._slow_since = None

    def update(self, t: float, th_deg: float, thd_deg_s: float, swing_rate_deg_s: float,
               crowd_rate_m_s: float = 0.0) -> int:
        """Advance with the current handle angle and rates; return the phase."""
        c = self.cfg
        if th_deg != th_deg or thd_deg_s != thd_deg_s or swing_rate_deg_s != swing_rate_deg_s:
            return self.phase  # NaN: a joint is unknown, hold the phase
        # |x| > k written as x > k or x < -k (and |x| < k as x < k and x > -k): the same
        # truth for every x, NaN included, without a call at every tick
        sw = swing_rate_deg_s
        k = c.idle_rate_deg_s
        if thd_deg_s > k or thd_deg_s < -k:
            moving = True
        else:
            k = c.idle_swing_deg_s
            moving = sw > k or sw < -k
            if not moving:
                k = c.idle_crowd_m_s
                moving = crowd_rate_m_s > k or crowd_rate_m_s < -k
        if moving:
            self._still_since = None
        elif self._still_since is None:
            self._still_since = t
        p = self.phase
        if p == IDLE or p == RETURN:
            if th_deg < c.tuck_deg and thd_deg_s > c.rise_deg_s and sw < c.swing_on_deg_s \
                    and sw > -c.swing_on_deg_s:  # rising from the tuck, inline
                self._enter(DIG, t)
            elif p == RETURN and self._still_since is not None \
                    and t - self._still_since > c.idle_hold_s:
                self._enter(IDLE, t)
        elif p == DIG:
            if t - self.since >= c.min_dig_s:
                k = c.swing_on_deg_s
                if th_deg > c.dig_exit_deg or sw > k or sw < -k:
                    self._enter(LIFT, t)
        elif p == LIFT:
            k = c.swing_on_deg_s
            if sw > k or sw < -k:
                self._swing_dir = math.copysign(1.0, sw)
                self._enter(SWING, t)
        elif p == SWING:
            k = c.swing_off_deg_s
            if sw < k and sw > -k:
                if self._slow_since is None:
                    self._slow_since = t
                elif t - self._slow_since >= c.stop_hold_s:
                    self._enter(DUMP, t)
            else:
                self._slow_since = None
        elif p == DUMP:
            if sw * self._swing_dir < -c.swing_on_deg_s \
                    or self._rising_from_tuck(th_deg, thd_deg_s, sw) \
                    or thd_deg_s < -4 * c.rise_deg_s:
                self._enter(RETURN, t)
        if p != IDLE and p != DIG and self._still_since is not None \
                and t - self._still_since > c.idle_hold_s:
            self._enter(IDLE, t)
        return self.phase

    def _rising_from_tuck(self, th_deg: float, thd_deg_s: float, sw: float) -> bool:
        """The dipper rises from the tuck (a dig starts), asked only where it matters."""
        c = self.cfg
        return th_deg < c.tuck_deg and thd_deg_s > c.rise_deg_s \
            and sw < c.swing_on_deg_s and sw > -c.swing_on_deg_s
