"""Readings -> one :class:`Sample` at the tick time, through the installation survey.

Each device kind contributes known signals: an MTi its pitch (handle angle) and yaw
(swing against the configured zero, unwrapped so a swing through +-180 deg stays
continuous), the AR4000 its distance (crowd through the installation's affine map),
and each ADC module its channels, whose names are signals-table columns. A signal is
put in ``Sample.invalid`` (and left NaN) when its device is disconnected, silent
for longer than its ``max_age_s``, reported the quantity invalid, or gave a value
outside the column's plausible range; the engine then makes no payload update from
it, and the daemon says ``valid: false`` instead of publishing a number. The tick
where a laser's count of targets taken (``TARGETS_TAKEN``) first grows carries
:data:`~shoveld.sample.CROWD_TARGET_CHANGED`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from drivers.base import TARGETS_TAKEN, DriverHealth
from shoveld.daemon.config import LASER_KINDS, MTI_KINDS, DeviceConfig
from shoveld.daemon.store import ReadingStore, Stored
from shoveld.installation import Installation, unwrap_deg, wrap_deg
from shoveld.sample import CROWD_TARGET_CHANGED, SIGNAL_FIELDS, Sample
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


_MTI, _LASER, _ADC = 0, 1, 2
_EMPTY: frozenset[str] = frozenset()
_COL = {name: i for i, name in enumerate(SIGNAL_FIELDS)}
"""Position of each signal in a Sample's positional arguments (time_s is 0)."""
_NAN_ROW = [math.nan] * len(SIGNAL_FIELDS)


class Assembler:
    """Builds the engine's sample at each tick from the store.

    A laser's or ADC module's contribution is a pure function of its newest reading,
    so it is computed once per reading and reused while the device sends nothing new
    (the staleness and connection checks still run at every tick). The MTi's is
    recomputed at every tick because the unwrapped swing carries state.
    """

    def __init__(self, devices: Mapping[str, DeviceConfig], installation: Installation,
                 store: ReadingStore,
                 health_of: Callable[[str], DriverHealth | None] = lambda name: None) -> None:
        self.devices = dict(devices)
        self.inst = installation
        self.store = store
        self.health_of = health_of
        self.state: dict[str, DeviceState] = {n: DeviceState() for n in self.devices}
        self._swing_prev = math.nan
        self.new_arrivals: list[tuple[str, float]] = []
        """(device, store-arrival time, host monotonic) of the readings first used by the
        last tick."""
        self._plan: list[tuple[Any, ...]] = []
        for name, dev in self.devices.items():
            kind = (_MTI if dev.kind in MTI_KINDS else _LASER if dev.kind in LASER_KINDS
                    else _ADC)
            ranges = (tuple((sg, _COL[sg], *_RANGE[sg]) for sg in dev.signals)
                      if kind == _ADC else ())
            self._plan.append((name, dev, kind, self.state[name], ranges, dev.max_age_s,
                               tuple(dev.signals), store.recent(name)))
        self._cache: dict[str, tuple[Any, ...]] = {}
        self._taken: dict[str, float] = {}
        """Per laser, the largest count of targets taken seen so far."""
        self._i_handle, self._i_swing, self._i_crowd = (_COL["handle_deg"], _COL["swing_deg"],
                                                        _COL["crowd_m"])

    def sample(self, t: float) -> Sample:
        row = _NAN_ROW.copy()
        row[0] = t
        invalid: list[str] = []
        arrivals: list[tuple[str, float]] = []
        health_of, cache = self.health_of, self._cache
        for plan in self._plan:
            name, _dev, kind, st, _ranges, max_age, signals, recent = plan
            b: Stored | None = recent[-1] if recent else None
            if b is None or b.reading.t_host > t:  # nothing yet, or a reading after the tick
                self._device(t, plan, row, invalid, arrivals)
                continue
            # the usual case, inline: the newest reading is at or before the tick
            health = health_of(name)
            st.age_s = age = t - b.reading.t_host
            if b.seq > st.last_seq:
                arrivals.append((name, b.arrived))
                st.last_seq = b.seq
            if health is not None and not health.connected:
                st.state = "disconnected"
                invalid.extend(signals)
                continue
            if age > max_age:
                st.state = "stale"
                invalid.extend(signals)
                continue
            if kind == _MTI:
                self._mti(t, b, None, row, invalid, st)
                continue
            cached = cache.get(name)
            if cached is not None and cached[0] is b:  # nothing new from this device
                _, pairs, bad, st.invalid, st.state = cached
                for i, v in pairs:
                    row[i] = v
                if bad:
                    invalid.extend(bad)
                continue
            self._contribute(t, plan, b, None, row, invalid)
        self.new_arrivals = arrivals
        # ``row`` holds a value per signal field (a cast would cost a call every tick)
        return Sample(*row,  # type: ignore[misc, arg-type]  # mypy cannot count a list
                      invalid=frozenset(invalid) if invalid else _EMPTY)

    # -- per device -----------------------------------------------------------------------
    def _device(self, t: float, plan: tuple[Any, ...], row: list[float], invalid: list[str],
                arrivals: list[tuple[str, float]]) -> None:
        name, dev, kind, st, ranges, max_age, signals, recent = plan
        health = self.health_of(name)
        b: Stored | None = recent[-1] if recent else None
        a: Stored | None = None
        if b is not None and b.reading.t_host > t:  # something arrived after the tick
            b, a = self.store.bracket(name, t)
            if b is None and a is not None and a.reading.t_host - t <= max_age:
                b, a = a, None  # only a reading just after the tick: use it as is
        if b is None:
            st.state, st.age_s = ("disconnected" if health is not None and not health.connected
                                  else "no_data"), None
            invalid.extend(signals)
            return
        r = b.reading
        age = t - r.t_host if a is None else 0.0
        if age < 0.0:
            age = 0.0
        st.age_s = age
        if b.seq > st.last_seq:
            arrivals.append((name, b.arrived))
            st.last_seq = b.seq
        if health is not None and not health.connected:
            st.state = "disconnected"
            invalid.extend(signals)
            return
        if age > max_age:
            st.state = "stale"
            invalid.extend(signals)
            return
        if kind == _MTI:
            self._mti(t, b, a, row, invalid, st)
            return
        if a is None:
            cached = self._cache.get(name)
            if cached is not None and cached[0] is b:
                _, pairs, bad, st.invalid, st.state = cached
                for i, v in pairs:
                    row[i] = v
                if bad:
                    invalid.extend(bad)
                return
        self._contribute(t, plan, b, a, row, invalid)

    def _contribute(self, t: float, plan: tuple[Any, ...], b: Stored, a: Stored | None,
                    row: list[float], invalid: list[str]) -> None:
        """A laser's or ADC module's signals from its bracketing readings (cached when
        there is no later reading to interpolate with)."""
        name, _dev, kind, st, ranges = plan[:5]
        r = b.reading
        pairs: list[tuple[int, float]] = []
        bad: list[str] = []
        if kind == _LASER:
            v = self._raw(t, b, a, "distance_m")
            if not math.isnan(v):
                v = self.inst.crowd_m(v)
            lo, hi = _RANGE["crowd_m"]
            if lo <= v <= hi:  # False for NaN too
                pairs.append((self._i_crowd, v))
            else:
                bad.append("crowd_m")
            taken = r.values.get(TARGETS_TAKEN)
            if taken is not None and taken > self._taken.get(name, 0.0):
                self._taken[name] = taken  # once: not in the cache, which is reused
                invalid.append(CROWD_TARGET_CHANGED)
        else:
            vals, rbad = r.values, r.invalid
            for sg, i, lo, hi in ranges:
                if a is None:  # the common case: hold the latest reading
                    v = vals.get(sg, math.nan) if sg not in rbad else math.nan
                else:
                    v = self._raw(t, b, a, sg)
                if lo <= v <= hi:  # False for NaN too; out of range: a unit or scaling
                    pairs.append((i, v))  # mistake, a broken transducer
                else:
                    bad.append(sg)
        for i, v in pairs:
            row[i] = v
        if bad:
            invalid.extend(bad)
        st.invalid = sorted(bad)
        st.state = "invalid" if bad else "ok"
        if a is None:
            self._cache[name] = (b, tuple(pairs), tuple(bad), st.invalid, st.state)

    @staticmethod
    def _raw(t: float, b: Stored, a: Stored | None, key: str) -> float:
        r = b.reading
        if key in r.invalid or key not in r.values:
            return math.nan
        return _interp(key, b, a, t)

    def _mti(self, t: float, b: Stored, a: Stored | None, row: list[float],
             invalid: list[str], st: DeviceState) -> None:
        r = b.reading
        vals, rbad = r.values, r.invalid
        if a is None:
            pitch = vals.get("pitch_deg", math.nan) if "pitch_deg" not in rbad else math.nan
            yaw = vals.get("yaw_deg", math.nan) if "yaw_deg" not in rbad else math.nan
        else:
            pitch = self._raw(t, b, a, "pitch_deg")
            yaw = self._raw(t, b, a, "yaw_deg")
        bad: list[str] = []
        handle = self.inst.handle_deg(pitch)
        lo, hi = _RANGE["handle_deg"]
        if lo <= handle <= hi:
            row[self._i_handle] = handle
        else:
            bad.append("handle_deg")
        if math.isnan(yaw):
            bad.append("swing_deg")
        else:
            sw = unwrap_deg(self._swing_prev, self.inst.swing_deg(yaw))
            self._swing_prev = sw
            row[self._i_swing] = sw  # unwrapped: a count of turns, not range-checked
        if bad:
            invalid.extend(bad)
            st.invalid = bad
            st.state = "invalid"
        else:
            st.invalid = []
            st.state = "ok"
