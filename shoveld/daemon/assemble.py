"""Readings -> one :class:`Sample` at the tick time, through the installation survey.

Each device kind contributes known signals: an MTi its pitch (handle angle) and yaw
(swing against the configured zero, unwrapped so a swing through +-180 deg stays
continuous), the AR4000 its distance (crowd through the installation's affine map),
and each ADC module its channels, whose names are signals-table columns. A signal is
put in ``Sample.invalid`` (and left NaN) when its device is disconnected, silent
for longer than its ``max_age_s``, reported the quantity invalid, or gave a value
outside the column's plausible range; the engine then makes no payload update from
it, and the daemon says ``valid: false`` instead of publishing a number.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from drivers.base import DriverHealth
from shoveld.daemon.config import ADC_KINDS, LASER_KINDS, MTI_KINDS, DeviceConfig
from shoveld.daemon.store import ReadingStore, Stored
from shoveld.installation import Installation, unwrap_deg, wrap_deg
from shoveld.sample import Sample
from shoveld.signals.columns import BY_NAME

ANGLE_KEYS = frozenset({"yaw_deg"})
"""Quantities that wrap at +-180 deg: interpolated the short way round."""

_RANGE = {c: (BY_NAME[c].lo, BY_NAME[c].hi) for c in BY_NAME}
"""Plausible range per signals-table column (values outside are invalid)."""


@dataclass
class DeviceState:
    """What the loop last saw of one device (published on the health topic)."""

    state: str = "no_data"
    """ok / stale / disconnected / no_data / invalid."""
    age_s: float | None = None
    invalid: list[str] = field(default_factory=list)
    last_seq: int = 0
    """Sequence number of the newest reading used; a larger one is new data."""


def _interp(key: str, b: Stored, a: Stored | None, t: float) -> float:
    """Value of ``key`` at ``t``: linear between the bracketing readings, else held."""
    vb = b.reading.values.get(key, math.nan)
    if a is None or key in a.reading.invalid or key not in a.reading.values:
        return vb
    tb, ta = b.reading.t_host, a.reading.t_host
    if ta <= tb:
        return vb
    va = a.reading.values[key]
    w = (t - tb) / (ta - tb)
    if key in ANGLE_KEYS:
        return wrap_deg(vb + w * wrap_deg(va - vb))
    return vb + w * (va - vb)


class Assembler:
    """Builds the engine's sample at each tick from the store."""

    def __init__(self, devices: Mapping[str, DeviceConfig], installation: Installation,
                 store: ReadingStore,
                 health_of: Callable[[str], DriverHealth | None] = lambda name: None) -> None:
        self.devices = dict(devices)
        self.inst = installation
        self.store = store
        self.health_of = health_of
        self.state: dict[str, DeviceState] = {n: DeviceState() for n in self.devices}
        self._swing_prev = math.nan
        self.new_arrivals: list[float] = []
        """Store-arrival times (host monotonic) of readings first used by the last tick."""

    def sample(self, t: float) -> Sample:
        values: dict[str, float] = {}
        invalid: set[str] = set()
        self.new_arrivals = []
        for name, dev in self.devices.items():
            self._device(t, name, dev, values, invalid)
        for k in invalid:
            values[k] = math.nan
        return Sample(time_s=t, **values, invalid=frozenset(invalid))

    @staticmethod
    def _set(signal: str, v: float, values: dict[str, float], invalid: set[str]) -> None:
        """Record a value, or mark it invalid when it is outside the column's range
        (a unit or scaling mistake, a broken transducer)."""
        lo, hi = _RANGE[signal]
        if lo <= v <= hi:  # False for NaN too
            values[signal] = v
        else:
            invalid.add(signal)

    # -- per device -----------------------------------------------------------------------
    def _device(self, t: float, name: str, dev: DeviceConfig, values: dict[str, float],
                invalid: set[str]) -> None:
        st = self.state[name]
        health = self.health_of(name)
        b, a = self.store.bracket(name, t)
        if b is None and a is not None and a.reading.t_host - t <= dev.max_age_s:
            b, a = a, None  # only a reading just after the tick: use it as is
        if b is None:
            st.state, st.age_s = ("disconnected" if health is not None and not health.connected
                                  else "no_data"), None
            invalid.update(dev.signals)
            return
        age = max(0.0, t - b.reading.t_host) if a is None else 0.0
        st.age_s = age
        if b.seq > st.last_seq:
            self.new_arrivals.append(b.arrived)
            st.last_seq = b.seq
        if health is not None and not health.connected:
            st.state = "disconnected"
            invalid.update(dev.signals)
            return
        if age > dev.max_age_s:
            st.state = "stale"
            invalid.update(dev.signals)
            return
        bad_before = len(invalid)
        if dev.kind in MTI_KINDS:
            self._mti(t, b, a, values, invalid)
        elif dev.kind in LASER_KINDS:
            self._one(t, b, a, "distance_m", "crowd_m", self.inst.crowd_m, values, invalid)
        elif dev.kind in ADC_KINDS:
            r = b.reading
            vals, bad = r.values, r.invalid
            for s in dev.signals:
                if a is None:  # the common case: hold the latest reading
                    v = vals.get(s, math.nan) if s not in bad else math.nan
                else:
                    v = self._raw(t, b, a, s)
                self._set(s, v, values, invalid)
        st.invalid = sorted(s for s in dev.signals if s in invalid)
        st.state = "invalid" if len(invalid) > bad_before else "ok"

    @staticmethod
    def _raw(t: float, b: Stored, a: Stored | None, key: str) -> float:
        r = b.reading
        if key in r.invalid or key not in r.values:
            return math.nan
        return _interp(key, b, a, t)

    def _one(self, t: float, b: Stored, a: Stored | None, key: str, signal: str,
             fn: Callable[[float], float] | None, values: dict[str, float],
             invalid: set[str]) -> None:
        v = self._raw(t, b, a, key)
        self._set(signal, fn(v) if fn is not None and not math.isnan(v) else v, values, invalid)

    def _mti(self, t: float, b: Stored, a: Stored | None, values: dict[str, float],
             invalid: set[str]) -> None:
        pitch = self._raw(t, b, a, "pitch_deg")
        self._set("handle_deg", self.inst.handle_deg(pitch), values, invalid)
        yaw = self._raw(t, b, a, "yaw_deg")
        if math.isnan(yaw):
            invalid.add("swing_deg")
        else:
            sw = unwrap_deg(self._swing_prev, self.inst.swing_deg(yaw))
            self._swing_prev = sw
            values["swing_deg"] = sw  # unwrapped: a count of turns, not range-checked
