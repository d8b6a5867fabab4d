"""The Modbus ADC driver's polls over many ticks of a recording at once.

Fast replay steps each driver once per 10 ms tick; for a polled module that is a
schedule test, a recorded-register lookup, a decode per channel and the channel
health per poll, in Python. :class:`ModbusSpanReader` does what the driver's
free-running polls (``_read_free``) would do over a run of ticks in one go: the poll
ticks from the same sequential schedule, each block's latest recorded answer found
with ``searchsorted``, the words decoded as columns (:meth:`Channel.decode_words`,
the channels' decoders' arithmetic), the health and channel health as the polls
leave them. It stops before the first poll that could do anything else (a recorded
timeout or exception, no answer yet, a value that is not finite, the schedule
falling behind); the per-tick read takes over there.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base import DriverHealth
from drivers.capture.format import RegisterRead
from drivers.modbus_adc.driver import ModbusAdcDriver
from drivers.spanio import SpanResult

if TYPE_CHECKING:
    from drivers.capture.replay import RecordedRegisters


@dataclass
class _Block:
    """One read block's recording as arrays: when, whether it answered, the words."""

    times: np.ndarray
    answered: np.ndarray
    words: np.ndarray


def _block(reads: list[RegisterRead], count: int) -> _Block:
    """The recording as arrays; the words of all answered reads in one ``np.array``
    (a row assignment per read was 5 ms of a 100 s replay's start per module)."""
    regs = list(map(_REGISTERS, reads))
    answered = [e is None and r is not None and len(r) == count
                for e, r in zip(map(_ERROR, reads), regs, strict=True)]
    ok = np.array(answered, dtype=bool)
    if all(answered):
        words = np.array(regs, dtype=np.int64).reshape(len(reads), count)
    else:
        words = np.zeros((len(reads), count), dtype=np.int64)
        rows = np.flatnonzero(ok)
        if len(rows):
            words[rows] = np.array([regs[i] for i in rows.tolist()], dtype=np.int64)
    return _Block(np.array(list(map(_TIME, reads)), dtype=float), ok, words)


_REGISTERS = operator.attrgetter("registers")
_ERROR = operator.attrgetter("error")
_TIME = operator.attrgetter("t")


@dataclass
class PollSpan(SpanResult):
    """The ADC's span reads: a reading per poll, every channel valid; ``exhausted`` is
    always True (a recording of registers has no stream to run out of)."""

    polls: np.ndarray
    """Per tick: polls done so far in the span."""
    times: np.ndarray
    """Time of each poll."""

    def health_after(self, i: int) -> DriverHealth:
        """A copy of the driver's health as it was after tick ``k0 + i``."""
        h = self.base.snapshot()
        n = int(self.polls[i])
        if n:
            _polled(h, n, float(self.times[n - 1]))
        return h


def _polled(h: DriverHealth, n: int, t: float) -> None:
    """Health after ``n`` more polls, all answered with finite values, the last at ``t``."""
    h.messages += n
    h.last_reading_t = t
    for ch in h.extra["channels"].values():
        ch["last_ok_t"] = t
        ch["state"], ch["last_error"] = "ok", None
        ch["stale"] = False


class ModbusSpanReader:
    """A :class:`ModbusAdcDriver` polling on its own schedule, read from recorded registers.

    ``client`` is the driver's client; ``recording`` gives a block ``(function, address,
    count)``'s recorded reads (``RecordedRegisters.columns`` or ``.recorded``) and
    answers at the time of the clock that stamps the driver's readings.
    """

    def __init__(self, driver: ModbusAdcDriver, client: Any, recording: RecordedRegisters,
                 period: float) -> None:
        self.driver = driver
        self.client = client
        self.period = period
        fc = driver.config.function_code
        self._blocks: list[_Block] | None = []
        for address, count, _chans, _dec in driver._plan:
            cols = recording.columns((fc, address, count))
            if cols is not None:  # every record an answer: the words as they are
                self._blocks.append(_Block(np.array(cols.times, dtype=float),
                                           np.ones(len(cols.times), dtype=bool), cols.words))
                continue
            reads = recording.recorded((fc, address, count))
            if reads is None:  # answered from another block's recording: per tick only
                self._blocks = None
                break
            self._blocks.append(_block(reads, count))

    def usable(self) -> bool:
        """Whether span reads can start now (connected, polling on its own schedule)."""
        d = self.driver
        return (self._blocks is not None and d.health.connected and d._client is self.client
                and d.tick_hint is None and d.register_log is None
                and getattr(self.client, "connected", False))

    def read(self, k0: int, k1: int) -> PollSpan | None:
        """Do the reads of ticks ``k0 .. k1 - 1`` (as far as nothing else can happen);
        None if not even the first tick can be done so."""
        if not self.usable():
            return None
        d, period = self.driver, 1.0 / self.driver.config.poll_hz
        tk = np.arange(k0, k1) * self.period
        n = len(tk)
        first = d._next_poll if d._next_poll is not None else float(tk[0])
        due = np.add.accumulate(np.concatenate([[first], np.full(n, period)]))  # sequential
        at = np.searchsorted(tk, due, side="left")  # the tick each poll is due at
        # each poll's next due time must fall after its tick (else the next poll comes on
        # the next tick, or the schedule restarts: the per-tick read does that)
        late = np.flatnonzero(due[1:] <= tk[np.minimum(at[:-1], n - 1)])
        m_in = int(np.searchsorted(at, n, side="left"))  # polls due inside the ticks
        m = min(m_in, int(late[0]) + 1) if len(late) else m_in
        nt = n if m == m_in else int(at[m - 1]) + 1  # a late one: stop after its tick
        pt = tk[at[:m]]
        ok = np.ones(m, dtype=bool)
        words = []
        for b in self._blocks or ():
            idx = np.searchsorted(b.times, pt, side="right") - 1
            ok &= idx >= 0
            ok &= b.answered[np.maximum(idx, 0)]
            words.append(b.words[np.maximum(idx, 0)])
        values: dict[str, np.ndarray] = {}
        for (address, _c, chans, _dec), w in zip(d._plan, words, strict=True):
            for ch in chans:
                values[ch.name] = v = ch.decode_words(w[:, ch.register - address])
                ok &= np.isfinite(v)
        bad = np.flatnonzero(~ok)
        if len(bad):  # stop before that poll's tick
            m = int(bad[0])
            nt = int(at[m])
        if nt == 0 or (m == 0 and d._next_poll is None):
            return None
        h = d.health
        base = h.snapshot()
        if m:
            t_last = float(pt[m - 1])
            _polled(h, m, t_last)
            nxt = float(due[m])
            d._next_poll = t_last + period if nxt < t_last - period else nxt
            d._failed_polls = 0
        polls = np.bincount(at[:m], minlength=nt)[:nt].cumsum()
        return PollSpan(k0, nt, k0 + at[:m], {k: v[:m] for k, v in values.items()},
                        np.ones(nt, dtype=bool), base, polls, pt[:m])
