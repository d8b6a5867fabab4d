"""Phase lock of the loop to the master sensor (``[loop] sync``), on simulated clocks."""

from __future__ import annotations

import bisect
import random
import threading
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest

from shoveld.daemon.clock import SimClock
from shoveld.daemon.config import ConfigError, DaemonConfig, parse_config
from shoveld.daemon.loop import FixedRateLoop, PhaseLock
from shoveld.model.params import ModelParams
from shoveld.replay.table import table_service
from shoveld.signals.table import SignalsTable

from .conftest import ROOT, make_cfg

P = 0.01  # 100 Hz


class Master:
    """Arrival times of a master stream; ``ref()`` is the newest one the clock has reached."""

    def __init__(self, clock: SimClock, arrivals: list[float]) -> None:
        self.clock = clock
        self.arrivals = arrivals

    def ref(self) -> float | None:
        i = bisect.bisect_right(self.arrivals, self.clock.now())
        return self.arrivals[i - 1] if i else None

    def history(self, t: float) -> list[float]:
        """Arrivals after ``t`` that the clock has reached (the store's recent readings)."""
        i, j = bisect.bisect_right(self.arrivals, t), bisect.bisect_right(self.arrivals,
                                                                           self.clock.now())
        return self.arrivals[max(i, j - 8):j]

    def before(self, t: float) -> float | None:
        i = bisect.bisect_right(self.arrivals, t)
        return self.arrivals[i - 1] if i else None


def stream(first: float, n: int, period: float = P, delays: Callable[[int], float] | None = None
           ) -> list[float]:
    """Arrivals of a device with its own clock (``period``) seen through host delays."""
    return sorted(first + k * period + (delays(k) if delays else 0.0) for k in range(n))


def run_loop(clock: SimClock, master: Master, ticks: int, delay_s: float = 0.001,
             work_s: float = 0.0002, start: float = 0.0, lost_after_s: float | None = None
             ) -> tuple[list[float], PhaseLock]:
    pll = PhaseLock(P, master.ref, history=master.history, delay_s=delay_s,
                    lost_after_s=lost_after_s)
    seen: list[float] = []

    def tick(t: float) -> None:
        seen.append(t)
        clock._t += work_s  # the tick's own work takes time

    loop = FixedRateLoop(clock, 1.0 / P, tick, phase_lock=pll)
    loop.run(threading.Event(), start=start, max_ticks=ticks)
    return seen, pll


def waits(ticks: list[float], master: Master) -> list[float]:
    """For each tick: how long the newest master reading had been there (its wait)."""
    out = []
    for t in ticks:
        a = master.before(t)
        if a is not None:
            out.append(t - a)
    return out


def test_ticks_lock_shortly_after_the_master_readings() -> None:
    clock = SimClock(0.0)
    rng = random.Random(4)
    # arrivals 3.7 ms into the loop's period, host delays 0-0.4 ms
    master = Master(clock, stream(0.0037, 3000, delays=lambda k: rng.uniform(0, 0.0004)))
    ticks, pll = run_loop(clock, master, 3000)
    w = waits(ticks[200:], master)
    # unlocked, a reading waits 0-10 ms; locked, the 1 ms delay and the jitter
    assert sorted(w)[len(w) // 2] == pytest.approx(0.0012, abs=0.0003)
    assert max(w) < 0.0017
    assert pll.state == "locked" and pll.corrections > 2900
    assert pll.as_dict()["late_pct"] == 0.0  # none since the lock settled
    assert pll.delay == 0.001  # the jitter is well inside the minimum delay
    # bounded correction: every period is 10 ms within the maximum step
    gaps = [b - a for a, b in zip(ticks, ticks[1:], strict=False)]
    assert max(abs(g - P) for g in gaps) <= pll.max_step + 1e-12
    assert pll.max_step == pytest.approx(P / 50)


def test_the_delay_widens_to_cover_late_readings() -> None:
    """2 % of the readings come 3 ms late (a busy host): a 1 ms delay would make them
    miss their tick and wait a whole period; the lock widens the delay over them."""
    clock = SimClock(0.0)
    rng = random.Random(5)
    master = Master(clock, stream(0.0037, 4000, delays=lambda k: rng.uniform(0, 0.0004)
                                  + (0.003 if rng.random() < 0.02 else 0.0)))
    ticks, pll = run_loop(clock, master, 4000)
    assert 0.0033 < pll.delay < 0.0040
    # after the first adaptation, (almost) every reading makes the next tick
    late = [a for a in master.arrivals[1500:3900]
            if master.before(ticks[bisect.bisect_left(ticks, a)] - 1e-12) != a]
    assert len(late) <= 0.005 * 2400
    w = sorted(waits(ticks[1500:], master))
    assert w[int(0.99 * len(w))] < 0.0045  # p99 of the wait, outliers included
    d = pll.as_dict()
    assert d["delay_ms"] == pytest.approx(1e3 * pll.delay, abs=1e-3) and d["min_delay_ms"] == 1.0


def test_lock_follows_a_master_clock_that_runs_fast() -> None:
    """A master 200 ppm fast drifts a whole period in 50 s; the lock keeps up."""
    clock = SimClock(0.0)
    master = Master(clock, stream(0.006, 6000, period=P * (1 - 200e-6)))
    ticks, pll = run_loop(clock, master, 6000)
    w = waits(ticks[300:], master)
    assert max(w) < 0.0015 and min(w) > 0.0009
    assert pll.state == "locked"
    assert pll.shift_s < -0.9 * 6000 * P * 200e-6  # the grid moved with the master


def test_free_runs_when_the_master_stops_and_relocks_when_it_returns() -> None:
    clock = SimClock(0.0)
    first = stream(0.0042, 500)  # 0 .. 5 s
    later = stream(8.0071, 500)  # after a 3 s gap, at a different phase
    master = Master(clock, first + later)
    ticks, pll = run_loop(clock, master, 1300, lost_after_s=0.1)
    gap = [t for t in ticks if 5.2 < t < 7.9]
    assert len(gap) > 250
    # free-running: exactly periodic on the loop's own grid, never waiting for the device
    assert all(b - a == pytest.approx(P, abs=1e-9) for a, b in zip(gap, gap[1:], strict=False))
    assert pll.lost_count == 1
    w = waits([t for t in ticks if t > 9.0], master)
    assert w and all(0.0008 < x < 0.0014 for x in w)
    assert pll.state == "locked"


def test_a_master_at_half_the_loop_rate_locks_every_other_tick() -> None:
    clock = SimClock(0.0)
    master = Master(clock, stream(0.0133, 1000, period=2 * P))
    ticks, _ = run_loop(clock, master, 2000)
    after = [t - b for t in ticks[300:] if (b := master.before(t)) is not None]
    # half of the ticks come ~1 ms after a reading, the others one period later
    near = [x for x in after if x < 0.005]
    assert len(near) == pytest.approx(len(after) / 2, abs=2)
    assert all(0.0009 < x < 0.0013 for x in near)


def test_without_readings_the_loop_never_waits() -> None:
    clock = SimClock(0.0)
    ticks, pll = run_loop(clock, Master(clock, []), 100, work_s=0.0)
    assert ticks == [k * P for k in range(100)]
    assert pll.corrections == 0 and pll.state == "free_running" and pll.lost_count == 0


def test_phase_lock_rejects_bad_settings() -> None:
    with pytest.raises(ValueError):
        PhaseLock(P, lambda: None, delay_s=0.02)
    with pytest.raises(ValueError):
        PhaseLock(P, lambda: None, gain=0.0)


# -- configuration and the service ----------------------------------------------------------

def _cfg(tmp_path: Path, loop: dict[str, object]) -> DaemonConfig:
    """The example configuration with ``loop`` merged into its [loop] table."""
    doc = tomllib.loads((ROOT / "examples" / "shoveld.toml").read_text())
    doc["loop"] = {k: v for k, v in {**doc["loop"], **loop}.items() if v is not None}
    doc["shovel"]["state_dir"] = str(tmp_path)
    return parse_config(doc)


def test_config_sync(tmp_path: Path) -> None:
    assert _cfg(tmp_path, {"sync": None}).loop.sync == "none"  # the default
    assert _cfg(tmp_path, {}).loop.sync == "mti"  # the example locks to its MTi
    cfg = _cfg(tmp_path, {"sync": "mti", "sync_delay_s": 0.002})
    assert cfg.loop.sync == "mti" and cfg.loop.sync_delay_s == 0.002
    with pytest.raises(ConfigError, match="loop.sync.*device name"):
        _cfg(tmp_path, {"sync": "gps"})
    with pytest.raises(ConfigError, match="loop.sync_delay_s"):
        _cfg(tmp_path, {"sync": "mti", "sync_delay_s": 0.006})
    # the laser streams at 50 Hz: fine for a 100 Hz loop, not for a 75 Hz one
    _cfg(tmp_path, {"sync": "laser"})
    with pytest.raises(ConfigError, match="whole multiple"):
        _cfg(tmp_path, {"sync": "laser", "rate_hz": 75.0})
    with pytest.raises(ConfigError, match="whole multiple"):  # MTi at 100 Hz, loop 50 Hz
        _cfg(tmp_path, {"sync": "mti", "rate_hz": 50.0})


class SteppingLiveClock(SimClock):
    """Jumps like SimClock but claims to be live, so the service uses its phase lock."""

    simulated = False


def test_service_locks_its_ticks_to_the_mti(tmp_path: Path, e2e_table: SignalsTable,
                                            params: ModelParams) -> None:
    """The whole service on a deterministic clock: the table's MTi readings come every
    20 ms (phase 0); after the lock, every other tick comes 1 ms after one."""
    cfg = make_cfg(tmp_path, loop={"sync": "mti"})
    svc, feed = table_service(e2e_table, cfg, params, clock=SteppingLiveClock(0.0037))
    assert svc.phase_lock is not None
    ticks: list[float] = []
    step = svc.before_tick
    assert step is not None

    def before(t: float) -> None:
        ticks.append(t)
        step(t)

    svc.before_tick = before
    svc.start(zenoh_wait_s=5.0)
    try:
        svc.run(threading.Event(), max_ticks=400)
        h = svc.health_msg
    finally:
        svc.close()
    phases = [round((t - 0.001) % 0.01, 9) for t in ticks[200:]]
    assert all(x < 2e-5 or x > 0.01 - 2e-5 for x in phases), phases[:10]
    assert h is not None and h["loop"]["sync"]["device"] == "mti"
    assert h["loop"]["sync"]["state"] == "locked"


def test_replay_clock_never_phase_locks(tmp_path: Path, e2e_table: SignalsTable,
                                        params: ModelParams) -> None:
    cfg = make_cfg(tmp_path, loop={"sync": "mti"})
    svc, _ = table_service(e2e_table, cfg, params)  # SimClock: readings at the tick times
    assert svc.phase_lock is None
