"""Modbus polls timed by the consumer's tick grid (``align_to_ticks``), on simulated time.

The module is a fake pymodbus client whose answer takes a chosen round trip on a
simulated clock, so every poll time is exact and the tests are deterministic.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

import pytest
from pymodbus.exceptions import ModbusIOException

from drivers.base import Reading
from drivers.modbus_adc import ChannelMap, ModbusAdcConfig, ModbusAdcDriver
from drivers.modbus_adc.driver import PollAligner

CHANNELS = ChannelMap.from_config([{"name": "hoist1_a", "register": 0, "scale": 400.0},
                                   {"name": "crowd_a", "register": 1, "scale": 400.0}])
TICK = 0.01
GRID0 = 0.0031
"""The consumer's ticks are at GRID0 + k * TICK."""
M = PollAligner().margin
"""The lead is a high percentile of the round trips plus this margin."""
W = PollAligner().window


class SimTime:
    """A driver clock that jumps when waited on (``clock_wait_until`` uses ``wait_until``)."""

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def wait_until(self, t: float, max_real_s: float) -> bool:
        self.t = max(self.t, t)
        return True


class _Answer:
    def __init__(self, count: int) -> None:
        self.registers = [100] * count

    def isError(self) -> bool:  # noqa: N802 - pymodbus' name
        return False


class FakeClient:
    """Answers after ``rtt()`` seconds of simulated time; ``starts`` logs request times."""

    def __init__(self, clock: SimTime, rtt: Callable[[], float | None]) -> None:
        self.clock = clock
        self.rtt = rtt
        self.connected = True
        self.starts: list[float] = []

    def connect(self) -> bool:
        return True

    def close(self) -> None:
        pass

    def read_input_registers(self, address: int, count: int, device_id: int) -> _Answer:
        self.starts.append(self.clock.t)
        dt = self.rtt()
        if dt is None:  # no answer: the client gives up after its timeout
            self.clock.t += 0.1
            raise ModbusIOException("no response")
        self.clock.t += dt
        return _Answer(count)


def make(rtt: Callable[[], float | None], poll_hz: float = 50.0, t0: float = 0.0
         ) -> tuple[ModbusAdcDriver, SimTime, FakeClient, list[Reading]]:
    clock = SimTime(t0)
    client = FakeClient(clock, rtt)
    cfg = ModbusAdcConfig.from_config({"kind": "modbus_tcp", "host": "h", "poll_hz": poll_hz,
                                       "reconnect_after": 1000,
                                       "channels": CHANNELS.to_config()})
    drv = ModbusAdcDriver("adc", cfg, clock=clock, client_factory=lambda c: client)
    drv.open()
    out: list[Reading] = []
    return drv, clock, client, out


def run(drv: ModbusAdcDriver, out: list[Reading], n: int) -> None:
    """Call ``read`` until ``n`` more readings came (as ``Driver.run`` would)."""
    goal = len(out) + n
    for _ in range(20 * n):
        drv.read(out.append)
        if len(out) >= goal:
            return
    raise AssertionError("the driver stopped polling")


def grid(base: float = GRID0) -> Callable[[], tuple[float, float]]:
    return lambda: (base, TICK)


def before_tick(t: float, base: float = GRID0) -> float:
    """How long before the next tick of the grid ``t`` is (0 < x <= TICK)."""
    return TICK - (t - base) % TICK or TICK


# --------------------------------------------------------------------------- no hint


def test_without_a_hint_polls_keep_their_own_schedule() -> None:
    drv, _clock, client, out = make(lambda: 0.0008, t0=0.0123)
    run(drv, out, 30)
    assert client.starts == pytest.approx([0.0123 + 0.02 * k for k in range(30)], abs=1e-12)
    assert [r.t_host for r in out] == pytest.approx([0.0131 + 0.02 * k for k in range(30)],
                                                    abs=1e-12)
    assert "align" not in drv.health.extra
    assert drv.aligner.polls == 0


def test_a_hint_without_a_grid_yet_keeps_the_own_schedule() -> None:
    drv, _clock, client, out = make(lambda: 0.0008, t0=0.0123)
    assert drv.align_to_ticks(lambda: None)
    run(drv, out, 10)
    assert client.starts == pytest.approx([0.0123 + 0.02 * k for k in range(10)], abs=1e-12)
    assert drv.health.extra["align"]["state"] == "waiting"
    drv.align_to_ticks(None)
    assert "align" not in drv.health.extra and drv.tick_hint is None


# --------------------------------------------------------------------------- aligned


def test_answers_land_just_before_ticks_by_the_lead() -> None:
    drv, _clock, _client, out = make(lambda: 0.0008, t0=0.0123)
    drv.align_to_ticks(grid())
    run(drv, out, 100)
    after = out[5:]  # the first poll uses the initial lead (2 ms)
    for r in after:  # lead = round trip + margin: each answer the margin before a tick
        assert before_tick(r.t_host) == pytest.approx(M, abs=1e-9)
    gaps = {round(b.t_host - a.t_host, 9) for a, b in zip(after, after[1:], strict=False)}
    assert gaps == {0.02}  # every other tick, at the poll rate
    a = drv.health.extra["align"]
    assert a["state"] == "aligned" and a["lead_ms"] == pytest.approx(1e3 * (0.0008 + M))
    assert drv.aligner.late == 0


def test_jittery_round_trips_land_before_their_ticks_but_a_percent() -> None:
    rng = random.Random(4)
    drv, _clock, _client, out = make(lambda: rng.uniform(0.0004, 0.0016), t0=0.0077)
    drv.align_to_ticks(grid())
    run(drv, out, 2000)
    lead = drv.aligner.lead_for(TICK)
    assert 0.0016 < lead < 0.0016 + M + 1e-9
    landed = [before_tick(r.t_host) for r in out[60:]]
    early = [x for x in landed if x < TICK / 2]  # the rest came just after a tick
    assert len(landed) - len(early) <= 0.01 * len(landed)
    # never earlier than the largest lead (slowest answer + margin) - the fastest answer
    assert max(early) <= 0.0016 + M - 0.0004 + 1e-9
    assert drv.aligner.late == len(landed) - len(early) + sum(
        1 for r in out[:60] if before_tick(r.t_host) > TICK / 2)


def test_lead_follows_the_round_trip_up_to_half_a_tick() -> None:
    rtt = [0.0005]
    drv, _clock, _client, out = make(lambda: rtt[0])
    drv.align_to_ticks(grid())
    run(drv, out, 400)
    assert drv.aligner.lead_for(TICK) == pytest.approx(0.0005 + M)
    rtt[0] = 0.002  # slower: late until the lead has caught up, then on time again
    run(drv, out, 400)
    assert drv.aligner.lead_for(TICK) == pytest.approx(0.002 + M)
    late = drv.aligner.late
    assert 0 < late <= drv.aligner.update_every
    run(drv, out, 400)
    assert drv.aligner.late == late
    assert all(before_tick(r.t_host) == pytest.approx(M) for r in out[-400:])
    rtt[0] = 0.0003  # faster again: the lead comes down once the slow ones leave the window
    run(drv, out, W)
    assert drv.aligner.lead_for(TICK) == pytest.approx(0.0003 + M)
    rtt[0] = 0.008  # slower than half a tick: the lead stops at 5 ms, answers 3 ms late
    run(drv, out, 400)
    assert drv.aligner.lead_for(TICK) == pytest.approx(0.005)
    assert drv.health.extra["align"]["lead_ms"] == pytest.approx(5.0)
    assert (out[-1].t_host - GRID0) % TICK == pytest.approx(0.003)
    assert drv.aligner.late > late + 300


def test_timeouts_are_not_round_trips() -> None:
    n = [0]

    def rtt() -> float | None:
        n[0] += 1
        return None if n[0] % 10 == 0 else 0.0007

    drv, _clock, _client, out = make(rtt)
    drv.align_to_ticks(grid())
    run(drv, out, 500)
    assert drv.aligner.lead_for(TICK) == pytest.approx(0.0007 + M)
    assert drv.aligner.late == 0  # a poll that timed out is not a late answer
    assert drv.health.timeouts >= 45


@pytest.mark.parametrize("slew", [0.005, -0.005])
def test_polls_follow_a_moving_grid(slew: float) -> None:
    """The phase lock moves the loop's grid (here 0.1 ms per poll, faster than it can, in
    either direction): the polls are timed on the hint read before each wait, so they keep
    landing before ticks, off by at most the grid's movement during one poll period."""
    drv, clock, _client, out = make(lambda: 0.001)
    drv.align_to_ticks(lambda: (GRID0 + slew * clock.t, TICK))
    run(drv, out, 500)
    for r in out[10:]:
        x = before_tick(r.t_host, GRID0 + slew * r.t_host)
        assert M - 0.0001 - 1e-5 < x < M + 0.0001 + 1e-5, x
    assert clock.t > 9.0  # the grid moved by more than 4 ticks meanwhile
    assert drv.aligner.late == 0


def test_poll_rate_not_a_whole_number_of_ticks() -> None:
    """30 Hz against 100 Hz ticks: each answer lands before a tick, at 30 polls/s."""
    drv, _clock, _client, out = make(lambda: 0.0008, poll_hz=30.0)
    drv.align_to_ticks(grid())
    run(drv, out, 301)
    for r in out[5:]:
        assert before_tick(r.t_host) == pytest.approx(M, abs=1e-9)
    assert (out[-1].t_host - out[0].t_host) == pytest.approx(10.0, abs=0.011)
    assert {round(b.t_host - a.t_host, 6) for a, b in zip(out[5:], out[6:], strict=False)} \
        <= {0.03, 0.04}


def test_polls_faster_than_the_ticks_keep_their_own_schedule() -> None:
    drv, _clock, client, out = make(lambda: 0.0008, poll_hz=200.0, t0=0.001)
    drv.align_to_ticks(grid())
    run(drv, out, 20)
    assert client.starts == pytest.approx([0.001 + 0.005 * k for k in range(20)], abs=1e-12)
    assert drv.health.extra["align"]["state"] == "off: polls faster than ticks"


def test_after_a_stalled_answer_polls_do_not_burst() -> None:
    """One answer takes 45 ms (two poll periods): the slots it overran are dropped, and
    the next poll is timed for the first tick it can make, not fired to catch up."""
    n = [0]

    def rtt() -> float:
        n[0] += 1
        return 0.045 if n[0] == 150 else 0.0008

    drv, _clock, client, out = make(rtt)
    drv.align_to_ticks(grid())
    run(drv, out, 300)
    gaps = [b - a for a, b in zip(client.starts, client.starts[1:], strict=False)]
    assert gaps[149] > 0.045 and min(gaps[150:]) == pytest.approx(0.02)
    # one slow answer does not move the lead (a high percentile of the recent round trips)
    for r in out[5:149] + out[150:]:
        assert before_tick(r.t_host) == pytest.approx(M, abs=1e-9)
    assert drv.aligner.late == 1


def test_aligner_percentile_ignores_rare_outliers() -> None:
    al = PollAligner()
    for i in range(al.window):
        al.record(0.010 if i % 400 == 7 else 0.001, 0.0, 1.0)  # 3 stalls in 1000
    assert al.lead_for(1.0) == pytest.approx(0.001 + M)
    d: dict[str, Any] = al.as_dict("aligned")
    assert d["rtt_ms"]["p50"] == pytest.approx(1.0) and d["polls"] == al.window


def test_slots_put_two_modules_on_different_ticks() -> None:
    """Two 50 Hz modules against 100 Hz ticks: slot 0 answers before the even ticks of
    the hinted grid, slot 1 before the odd ones, so they do not compete for one tick."""
    ticks: dict[int, set[int]] = {}
    for slot in (0, 1):
        drv, _clock, _client, out = make(lambda: 0.0008, t0=0.0123)
        drv.align_to_ticks(grid(), slot=slot)
        run(drv, out, 50)
        ticks[slot] = {round((r.t_host + M - GRID0) / TICK) % 2 for r in out[5:]}
    assert ticks == {0: {0}, 1: {1}}
