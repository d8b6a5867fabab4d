"""Readings made from a signals table, for tests and benches of everything after the drivers.

:class:`TableFeed` turns each table row into the readings the four devices of a
shovel would have sent (MTi pitch/yaw through the installation's inverse, AR4000
distance, two ADC modules with signals-table channel names) and puts them into the
daemon's store as the loop reaches their times. Faults can be injected per device
(silence, invalid quantities, a disconnected driver) to check what the daemon says.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drivers.base import DriverHealth, Reading
from shoveld.daemon.clock import Clock, SimClock
from shoveld.daemon.config import DaemonConfig, DeviceConfig
from shoveld.daemon.service import Service
from shoveld.installation import Installation
from shoveld.model.params import ModelParams
from shoveld.signals.table import SignalsTable

MOTORS = ("hoist1_a", "hoist2_a", "hoist_field_a", "crowd_a", "crowd_field_a", "swing_a",
          "swing_field_a")
INCLINOMETERS = ("boom_deg", "roll_deg", "pitch_deg")


def table_devices(max_age_s: float = 0.25) -> dict[str, DeviceConfig]:
    """The standard four devices (no driver tables: nothing is opened)."""
    return {
        "mti": DeviceConfig("mti", "mti_serial", {}, max_age_s, ("handle_deg", "swing_deg")),
        "laser": DeviceConfig("laser", "ar4000", {}, max_age_s, ("crowd_m",)),
        "adc_motors": DeviceConfig("adc_motors", "modbus_tcp", {}, max_age_s, MOTORS),
        "adc_incl": DeviceConfig("adc_incl", "modbus_tcp", {}, max_age_s, INCLINOMETERS),
    }


@dataclass
class Fault:
    """A device fault over capture-time interval [start, end)."""

    device: str
    start: float
    end: float
    kind: str = "silent"
    """``silent`` (no readings), ``invalid`` (readings with every quantity invalid) or
    ``disconnected`` (no readings and the driver's health says disconnected)."""


@dataclass
class TableFeed:
    """Feeds the store from a table; call :meth:`step` with each tick time."""

    table: SignalsTable
    installation: Installation = field(default_factory=Installation)
    faults: list[Fault] = field(default_factory=list)
    health: dict[str, DriverHealth] = field(default_factory=dict)
    _i: int = 0

    def __post_init__(self) -> None:
        self.t0 = float(self.table.time[0])
        self.cols = {k: v.tolist() for k, v in self.table.columns.items()}
        self.times = [float(t) - self.t0 for t in self.table.time]
        for name in table_devices():
            self.health.setdefault(name, DriverHealth(connected=True))

    @property
    def end_t(self) -> float:
        return self.times[-1]

    @property
    def finished(self) -> bool:
        return self._i >= len(self.times)

    def _fault(self, device: str, t: float) -> str | None:
        for f in self.faults:
            if f.device == device and f.start <= t < f.end:
                return f.kind
        return None

    def step(self, t: float, put: Callable[[str, Reading], None]) -> None:
        """Emit the readings of every row with time <= t."""
        c, inst = self.cols, self.installation
        while self._i < len(self.times) and self.times[self._i] <= t:
            i, tr = self._i, self.times[self._i]
            self._i += 1
            rows = {
                "mti": {"pitch_deg": inst.mti_pitch_deg(c["handle_deg"][i]),
                        "yaw_deg": inst.mti_yaw_deg(c["swing_deg"][i]), "roll_deg": 0.0},
                "laser": {"distance_m": inst.laser_m(c["crowd_m"][i])},
                "adc_motors": {k: c[k][i] for k in MOTORS},
                "adc_incl": {k: c[k][i] for k in INCLINOMETERS},
            }
            for dev, values in rows.items():
                fault = self._fault(dev, tr)
                h = self.health[dev]
                h.connected = fault != "disconnected"
                if fault in ("silent", "disconnected"):
                    continue
                if fault == "invalid":
                    put(dev, Reading(dev, tr, {}, frozenset(values)))
                else:
                    put(dev, Reading(dev, tr, values))
                h.messages += 1
                h.last_reading_t = tr


class FakeDriver:
    """Stands in for a driver in the service (health only; the feed does the reading)."""

    def __init__(self, name: str, health: DriverHealth) -> None:
        self.name = name
        self.health = health


def table_service(table: SignalsTable, cfg: DaemonConfig, params: ModelParams, *,
                  clock: Clock | None = None, faults: list[Fault] | None = None,
                  **kw: Any) -> tuple[Service, TableFeed]:
    """A service fed from ``table`` on a simulated clock (no drivers, no hardware)."""
    devices = table_devices(cfg.loop.max_age_s)
    cfg = dataclasses.replace(cfg, devices=devices)
    feed = TableFeed(table, cfg.installation, list(faults or []))
    drivers: dict[str, Any] = {n: FakeDriver(n, feed.health[n]) for n in devices}
    svc = Service(cfg, params, clock=clock or SimClock(0.0), drivers=drivers,
                  driver_threads=False, **kw)
    svc.before_tick = lambda t: feed.step(t, svc.store.put)
    return svc, feed
