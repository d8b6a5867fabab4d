"""The Modbus ADC driver's span reads do what its per-tick polls do, reading for reading
and health after every tick: on the committed capture, and with what a module and a
link do wrong (timeouts, exceptions, answers of another length, no answer yet, a run
of timeouts that makes the driver reconnect, values that decode to no number)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.base import Reading
from drivers.capture.format import RegisterRead, read_capture
from drivers.capture.replay import RecordedRegisters
from drivers.modbus_adc.channels import Channel
from drivers.modbus_adc.driver import ModbusAdcDriver
from drivers.modbus_adc.span import ModbusSpanReader
from shoveld.daemon.config import DeviceConfig, device_signals
from shoveld.replay.sync import MemoryModbus, StepClock, SyncDevice, SyncReplay

from .span_play import play

CAPTURE = Path(__file__).resolve().parents[2] / "hil_fixtures" / "captures" / "daemon-e2e"
PERIOD = 0.01


def _setup(name: str, damage: bool) -> tuple[ModbusAdcDriver, MemoryModbus, StepClock]:
    cap = read_capture(CAPTURE)
    d = dict(cap.devices[name].settings["config"])
    d["kind"] = cap.devices[name].kind
    sync = SyncReplay(cap, {name: DeviceConfig(name, d["kind"], d, 0.5,
                                               device_signals(d["kind"], d))})
    port: MemoryModbus = sync.transports[name]
    reads = list(cap.modbus_reads(name))
    if damage:
        reads = _damage(reads)
    port.registers = RecordedRegisters(reads, sync.clock)
    return sync.drivers[name], port, sync.clock  # type: ignore[return-value]


def _damage(reads: list[RegisterRead]) -> list[RegisterRead]:
    """Timeouts, exceptions, short answers, a word that decodes to no number, and a
    stretch of 0.5 s without an answer (the driver reconnects)."""
    out = []
    for i, r in enumerate(reads):
        if 2.0 <= r.t < 2.5 or i % 97 == 5:
            r = dataclasses.replace(r, registers=None, error="timeout")
        elif i % 89 == 7:
            r = dataclasses.replace(r, registers=None, error="exception", exception_code=4)
        elif i % 113 == 9 and r.registers:
            r = dataclasses.replace(r, registers=r.registers[:-1])
        out.append(r)
    return out


def _play(driver: ModbusAdcDriver, port: MemoryModbus, clock: StepClock, ticks: int,
          window: int | None) -> tuple[list[tuple[Any, ...]], list[dict[str, Any]]]:
    """Readings and health after every tick; span reads of up to ``window`` ticks
    wherever they can start (None: the per-tick polls only)."""
    readings: list[tuple[Any, ...]] = []
    names = [ch.name for ch in driver.config.channels]

    def sink(r: Reading) -> None:
        readings.append((round(r.t_host / PERIOD), r.t_host,
                         tuple(r.values.get(k, "-") for k in names), tuple(sorted(r.invalid))))

    def span_rows(got: Any) -> None:
        for i, tick in enumerate(got.reading_ticks.tolist()):
            readings.append((tick, float(got.times[i]),
                             tuple(float(got.values[n][i]) for n in names), ()))

    dev = SyncDevice(driver.name, driver, port, sink, clock)
    reader = ModbusSpanReader(driver, port, port.registers, PERIOD) if window else None
    return readings, play(dev, reader, clock, ticks, window, PERIOD, span_rows)


@pytest.mark.parametrize("name", ["adc_motors", "adc_incl"])
@pytest.mark.parametrize("window", [1000, 29])
def test_span_reads_match_per_tick_polls(name: str, window: int) -> None:
    a = _play(*_setup(name, damage=False), 3000, None)
    b = _play(*_setup(name, damage=False), 3000, window)
    assert len(a[0]) > 1400
    assert a == b


@pytest.mark.parametrize("window", [1000, 29])
def test_span_reads_match_per_tick_polls_when_the_module_fails(window: int) -> None:
    a = _play(*_setup("adc_motors", damage=True), 3000, None)
    b = _play(*_setup("adc_motors", damage=True), 3000, window)
    h = a[1][-1]
    assert h["timeouts"] > 20 and h["exceptions"] > 5 and h["bad_frames"] > 3
    assert h["reconnects"] >= 1
    assert any(r[3] for r in a[0])
    assert a == b


def test_a_value_that_is_no_number_goes_to_the_per_tick_poll(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A channel that decodes one word to NaN: that poll drops the channel's value (it is
    missing, not invalid, in the driver's reading); the span read leaves it to the poll."""
    drv, port, _ = _setup("adc_incl", damage=False)
    address, count, chans, decoders = drv._plan[0]
    word = port.registers.recorded((drv.config.function_code, address, count))[300] \
        .registers[decoders[0][1]]
    target = chans[0].name
    decode_words = Channel.decode_words

    def nan_words(self: Channel, words: np.ndarray) -> np.ndarray:
        out = decode_words(self, words)
        return np.where(words == word, np.nan, out) if self.name == target else out
    monkeypatch.setattr(Channel, "decode_words", nan_words)
    runs = []
    for window in (None, 500):
        drv, port, clock = _setup("adc_incl", damage=False)
        address, count, chans, decoders = drv._plan[0]
        name, offset, decode, h = decoders[0]

        def nan_at_word(w: int, _d: Callable[[int], float] = decode) -> float:
            return math.nan if w == word else _d(w)
        drv._plan[0] = (address, count, chans, ((name, offset, nan_at_word, h),
                                                *decoders[1:]))
        runs.append(_play(drv, port, clock, 1500, window))
    assert any("-" in r[2] for r in runs[0][0])
    assert runs[0] == runs[1]


@pytest.mark.parametrize("channel", [
    Channel("signed", 0), Channel("offset_binary", 0, 0, 65535, 0.0, 10.0, 400.0, -2000.0),
    Channel("ints", 0, 0, 4095, 4, 20, 3, -7), Channel("odd", 0, -2048, 2047, -5.0, 5.0,
                                                       0.1, 1e-3)])
def test_columns_decode_as_the_channel_decodes(channel: Channel) -> None:
    words = np.arange(65536)
    want = [channel.word_decoder()(w) for w in words.tolist()]
    assert channel.decode_words(words).tolist() == want


def test_the_schedule_is_the_drivers_own() -> None:
    """Polls at 30 Hz on 10 ms ticks: the due times drift across the ticks."""
    drv, port, clock = _setup("adc_incl", damage=False)
    drv.config = dataclasses.replace(drv.config, poll_hz=30.0)
    a = _play(drv, port, clock, 2000, None)
    drv, port, clock = _setup("adc_incl", damage=False)
    drv.config = dataclasses.replace(drv.config, poll_hz=30.0)
    b = _play(drv, port, clock, 2000, 333)
    assert 590 <= len(a[0]) <= 610
    assert a == b
    assert np.all(np.diff([r[0] for r in a[0]]) >= 3)


@pytest.mark.parametrize("case", ["answers", "mixed", "none answered", "empty"])
def test_a_blocks_arrays_hold_each_reads_words_and_outcome(case: str) -> None:
    """``_block``: row i is read i's words when it answered with ``count`` words, zeros
    otherwise (a timeout, an exception, a short answer), whatever the mix."""
    from drivers.modbus_adc.span import _block

    ok = [RegisterRead(0.02 * i, 1, 4, 0, 3, registers=(i, 65535 - i, 7)) for i in range(6)]
    bad = [RegisterRead(0.5, 1, 4, 0, 3, error="timeout"),
           RegisterRead(0.6, 1, 4, 0, 3, error="exception", exception_code=6),
           RegisterRead(0.7, 1, 4, 0, 3, registers=(1, 2))]
    reads = {"answers": ok, "mixed": ok[:2] + bad + ok[2:], "none answered": bad,
             "empty": []}[case]
    b = _block(reads, 3)
    assert b.words.dtype == np.int64 and b.words.shape == (len(reads), 3)
    assert b.times.dtype == float and b.times.tolist() == [r.t for r in reads]
    for i, r in enumerate(reads):
        good = r.registers is not None and len(r.registers) == 3
        assert bool(b.answered[i]) is good
        assert b.words[i].tolist() == (list(r.registers) if good and r.registers is not None
                                       else [0, 0, 0])
