"""``[loop] align_polls``: the loop's tick hint, its configuration, and the service's wiring."""

from __future__ import annotations

import threading
import time
import tomllib
from pathlib import Path

import pytest

from drivers.base import Reading
from drivers.modbus_adc import ModbusAdcDriver
from hil_fixtures.modbus_adc import ModbusAdcEmulator
from hil_fixtures.virtual_shovel import MOTOR_CHANNELS
from shoveld.daemon.clock import SimClock
from shoveld.daemon.config import ConfigError, DaemonConfig, parse_config
from shoveld.daemon.loop import FixedRateLoop, PhaseLock
from shoveld.daemon.service import Service
from shoveld.model.params import ModelParams

ROOT = Path(__file__).resolve().parents[2]


class SteppingLiveClock(SimClock):
    """Jumps like SimClock but claims to be live (as in test_sync)."""

    simulated = False


def _cfg(tmp_path: Path, loop: dict[str, object], adc_poll_hz: float | None = None
         ) -> DaemonConfig:
    """The example configuration with ``loop`` merged into its [loop] table."""
    doc = tomllib.loads((ROOT / "examples" / "shoveld.toml").read_text())
    doc["loop"] = {k: v for k, v in {**doc["loop"], **loop}.items() if v is not None}
    doc["shovel"]["state_dir"] = str(tmp_path)
    if adc_poll_hz is not None:
        doc["devices"]["adc_incl"]["poll_hz"] = adc_poll_hz
    return parse_config(doc)


# --------------------------------------------------------------------------- the loop's hint


def test_tick_hint_gives_the_running_grid_and_follows_the_lock() -> None:
    clock = SimClock(0.5)
    seen: list[tuple[float, tuple[float, float] | None]] = []
    arrivals = [0.5 + 0.0042 + 0.01 * k for k in range(400)]

    def ref() -> float | None:
        t = clock.now()
        past = [a for a in arrivals if a <= t]
        return past[-1] if past else None

    pll = PhaseLock(0.01, ref, delay_s=0.001)
    loop: FixedRateLoop

    def tick(t: float) -> None:
        seen.append((t, loop.tick_hint()))

    loop = FixedRateLoop(clock, 100.0, tick, phase_lock=pll)
    assert loop.tick_hint() is None  # not running: no grid
    loop.run(threading.Event(), max_ticks=300)
    assert loop.tick_hint() is None
    for t, hint in seen:
        assert hint is not None and hint[1] == 0.01
        k = (t - hint[0]) / 0.01
        assert k == pytest.approx(round(k), abs=1e-6)  # each deadline is on the hinted grid
    # the lock moved the grid (ticks now 1 ms after the readings), and the hint with it
    assert (seen[-1][0] - 0.5 - 0.0042 - 0.001) % 0.01 == pytest.approx(0.0, abs=2e-5)
    assert seen[-1][1] != seen[0][1]


# --------------------------------------------------------------------------- configuration


def test_align_polls_defaults_to_on_with_sync(tmp_path: Path) -> None:
    assert _cfg(tmp_path, {}).loop.align_polls  # the example locks to its MTi
    assert not _cfg(tmp_path, {"sync": "none"}).loop.align_polls
    assert _cfg(tmp_path, {"sync": "none", "align_polls": True}).loop.align_polls
    assert not _cfg(tmp_path, {"align_polls": False}).loop.align_polls


def test_align_polls_errors_name_the_key(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="key 'loop.align_polls' must be true or false"):
        _cfg(tmp_path, {"align_polls": "yes"})
    with pytest.raises(ConfigError, match="key 'loop.align_polls': device 'adc_incl' polls "
                                          "at 200 Hz"):
        _cfg(tmp_path, {"align_polls": True}, adc_poll_hz=200.0)
    # by default such a device just keeps its own schedule, so the file is fine
    assert _cfg(tmp_path, {}, adc_poll_hz=200.0).loop.align_polls
    _cfg(tmp_path, {"align_polls": False}, adc_poll_hz=200.0)


# --------------------------------------------------------------------------- the service


def test_service_gives_the_hint_to_host_polled_drivers(tmp_path: Path,
                                                       params: ModelParams) -> None:
    svc = Service(_cfg(tmp_path, {}), params, clock=SteppingLiveClock(0.0))
    assert sorted(svc.aligned_drivers) == ["adc_incl", "adc_motors"]
    slots = set()
    for name in ("adc_incl", "adc_motors"):
        drv = svc.drivers[name]
        assert isinstance(drv, ModbusAdcDriver) and drv.tick_hint == svc.loop.tick_hint
        slots.add(drv._slot)
    assert slots == {0, 1}  # staggered
    assert getattr(svc.drivers["mti"], "tick_hint", None) is None  # streams: nothing to time


@pytest.mark.parametrize("loop, clock", [({"align_polls": False}, SteppingLiveClock(0.0)),
                                         ({"sync": "none"}, SteppingLiveClock(0.0)),
                                         ({}, SimClock(0.0))])
def test_service_without_alignment_leaves_the_polls_alone(
        tmp_path: Path, params: ModelParams, loop: dict[str, object], clock: SimClock) -> None:
    """Off, or on a simulated clock (replay, tests: the capture's schedule must stay)."""
    svc = Service(_cfg(tmp_path, loop), params, clock=clock)
    assert svc.aligned_drivers == []
    assert all(getattr(d, "tick_hint", None) is None for d in svc.drivers.values())


# --------------------------------------------------------------------------- a real module


def test_aligned_polls_against_a_pymodbus_server() -> None:
    """The driver's aligned path through pymodbus' TCP client and a real server: polls at
    the configured rate, round trips measured, health reports the lead. (How early the
    answers land is host timing: bench/daemon_live.py measures it.)"""
    values = {"hoist1_a": 1000.0, "hoist2_a": 900.0, "hoist_field_a": 30.0,
              "crowd_a": -200.0, "crowd_field_a": 25.0, "swing_a": 50.0,
              "swing_field_a": 20.0}
    base = time.monotonic()
    with ModbusAdcEmulator(lambda t: values, MOTOR_CHANNELS) as emu:
        drv = ModbusAdcDriver.from_config("adc", emu.driver_config(poll_hz=50))
        assert drv.align_to_ticks(lambda: (base, 0.01))
        out: list[Reading] = []
        drv.open()
        try:
            while len(out) < 60:
                drv.read(out.append)
        finally:
            drv.close()
    assert out[-1].values["hoist1_a"] == pytest.approx(1000.0, abs=0.2)
    a = drv.health.extra["align"]
    assert a["state"] == "aligned" and a["polls"] >= 50
    assert 0.0 < a["lead_ms"] <= 5.0 and a["rtt_ms"]["p50"] > 0.0
