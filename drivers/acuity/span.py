"""The AR4000 driver's reads over many ticks of a recorded stream at once.

Fast replay steps each driver once per 10 ms tick; for the laser that is a line split
and a regular-expression parse per line in Python. :class:`Ar4000SpanReader` does what
those reads would do for a run of ticks in one go: the lines each tick completes,
found with numpy, each distinct line parsed once by the driver's :func:`parse_line`,
the rule that a distance follows from the one before it (the driver's
:func:`~drivers.acuity.ar4000.follows`, in numpy), the
silence timeout and the health counters, with the driver's state (line buffer,
malformed-line window, last good line, last distance used) left as the reads would
leave it. It starts only while the window of recent lines holds no malformed one and
the last line was a distance used, and stops before the first tick where anything
else could happen (a malformed, empty or overlong line, a line that is not a distance
used: no target, implausible, a jump; a line buffer over its bound, a silence); the
per-tick read takes over there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.acuity.ar4000 import DISTANCE, Ar4000Driver, parse_line
from drivers.base import TARGETS_TAKEN, DriverHealth
from drivers.spanio import RecordedStream, SpanResult

_LF = 0x0A
_CR = 0x0D
_MAX_PARSED = 100_000
"""Distinct lines remembered with their value (a laser's distances repeat)."""


@dataclass
class LineSpan(SpanResult):
    """The AR4000's span reads: a reading per line, each a distance used (the lines
    that are not stop the span)."""

    cum: dict[str, np.ndarray]
    """Per tick: ``messages`` added so far, and the time of the last line then (NaN:
    none yet in the span)."""

    def health_after(self, i: int) -> DriverHealth:
        """A copy of the driver's health as it was after tick ``k0 + i``."""
        c = self.cum
        h = self.base.snapshot()
        h.messages += int(c["messages"][i])
        t = float(c["last_t"][i])
        if t == t:  # a line by then: not silent, its time the last reading's
            h.last_reading_t = t
            h.extra["silent"] = False
        return h


def digit_lines(data: np.ndarray, starts: np.ndarray, lf: np.ndarray, unit_m: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """The lines ``data[starts:lf]`` that are 1 to 7 digits (after the splitter drops
    one CR), and their value as :func:`parse_line` gives it (``float(int) * unit_m``,
    exact in float64; 0 is :data:`NO_TARGET`, 0.0 too); NaN for the other lines."""
    cr = (lf > starts) & (data[np.maximum(lf - 1, 0)] == _CR)
    stop = lf - cr
    length = stop - starts
    digit = ((data >= 0x30) & (data <= 0x39)).astype(np.int64)
    count = np.concatenate([[0], np.cumsum(digit)])
    plain = (length >= 1) & (length <= 7) & (count[stop] - count[starts] == length)
    # the last 7 bytes of each line, by place value; bytes before the line count 0
    at = stop[:, None] - 7 + np.arange(7)
    d = np.where(at >= starts[:, None], data[np.maximum(at, 0)].astype(np.int64) - 0x30, 0)
    ints = d @ (10 ** np.arange(6, -1, -1, dtype=np.int64))
    vals = np.where(plain, ints.astype(float) * unit_m, np.nan)
    return plain, vals


class Ar4000SpanReader:
    """An :class:`Ar4000Driver` read tick after tick from an in-memory recording
    (``port`` as for :class:`~drivers.spanio.RecordedStream`, with ``in_waiting`` and
    ``advance(j)``)."""

    def __init__(self, driver: Ar4000Driver, port: Any, period: float) -> None:
        self.driver = driver
        self.port = port
        self.period = period
        self.stream = RecordedStream(port)
        self._parsed: dict[bytes, float] = {}

    def usable(self) -> bool:
        """Whether a span read can start now (connected, nothing unread or queued, no
        malformed line or jump in the windows, no overlong line being skipped, the last
        line a distance used: the next follows from it)."""
        d = self.driver
        sp = d._splitter
        return (d.health.connected and d._ser is self.port and not self.port.in_waiting
                and not d._pending and d._malformed.count == 0 and not sp._skipping
                and not d.health.extra["babbling"] and len(sp._buf) <= sp.max_line
                and d._used is not None and d._used == d._prev and d._jumped.count == 0
                and not d.health.extra["jumping"])

    def read(self, k0: int, k1: int) -> LineSpan | None:
        """Do the reads of ticks ``k0 .. k1 - 1`` (as far as nothing else can happen);
        None if not even the first tick can be done so."""
        if not self.usable():
            return None
        d = self.driver
        cfg = d.config
        sp = d._splitter
        rel = self.stream.released(sp._buf, k0, k1, self.period)
        tk, ends = rel.t, rel.ends
        nl = np.flatnonzero(rel.data == _LF)  # each line's LF
        raw = rel.data.tobytes()
        starts = np.concatenate([[0], nl[:-1] + 1]) if len(nl) else nl
        plain, vals = digit_lines(rel.data, starts, nl, cfg.unit_m)
        other = np.flatnonzero(~plain).tolist()
        if other:  # the rest through parse_line, each distinct line once
            lines = raw.split(b"\n")
            get = self._parsed.get
            for i in other:
                v = get(lines[i])
                vals[i] = self._parse(lines[i]) if v is None else v
        # each a distance that follows from the line before it, while all before it are
        # (the driver's reference is then the line before: see Ar4000Driver._parse)
        arrive = np.searchsorted(ends, nl + 1, side="left")  # tick index of each line
        prev = d._prev
        assert prev is not None  # usable()
        # when each line was sent, as the driver times it: its tick's time less an
        # interval for each later line of that tick, never before the line before it
        behind = np.searchsorted(arrive, arrive, side="right") - 1 - np.arange(len(arrive))
        t_line = tk[np.minimum(arrive, len(tk) - 1)] - behind * cfg.interval_s
        t_line = np.maximum.accumulate(np.concatenate([[prev[1]], t_line]))[1:]
        prev_v = np.concatenate([[prev[0]], vals[:-1]])[:len(vals)]
        prev_t = np.concatenate([[prev[1]], t_line[:-1]])[:len(vals)]
        used = ((vals > 0.0) & (vals <= cfg.max_plausible_m) & (
            np.abs(vals - prev_v)
            <= cfg.max_speed_mps * np.maximum(t_line - prev_t, cfg.interval_s)
            + cfg.jump_noise_m))
        bad = np.flatnonzero(~used)
        # bytes with nothing else in them: up to the first line that is not a reading
        clean_end = int(starts[bad[0]]) if len(bad) else len(rel.data)
        nt = int(np.searchsorted(ends, clean_end, side="right"))
        # the line buffer after each tick must stay within its bound
        done = np.searchsorted(nl + 1, ends, side="right")  # lines complete by each tick
        line_ends = np.concatenate([[0], nl + 1])  # after the held bytes' lines
        held = ends - line_ends[done]
        over = np.flatnonzero(held > sp.max_line)
        if len(over):
            nt = min(nt, int(over[0]))
        got = np.full(len(tk), -np.inf)
        got[arrive[arrive < len(tk)]] = tk[arrive[arrive < len(tk)]]
        last_good = np.maximum(np.maximum.accumulate(got), d._last_good)
        quiet = np.flatnonzero((got == -np.inf) & (tk - last_good > cfg.silent_timeout_s))
        if len(quiet):
            nt = min(nt, int(quiet[0]))
        if nt == 0:
            return None
        nlines = int(done[nt - 1])
        return self._commit(k0, nt, rel.chunks, ends, raw, nl, vals[:nlines],
                            arrive[:nlines], tk, last_good)

    def _parse(self, line: bytes) -> float:
        """What the driver makes of one line (CR still on): metres, or NaN for a line
        that is not a reading (overlong, malformed), remembered."""
        text = line[:-1] if line.endswith(b"\r") else line
        v = None if len(text) > self.driver._splitter.max_line else parse_line(
            text, self.driver.config.unit_m)
        if len(self._parsed) >= _MAX_PARSED:
            self._parsed.clear()  # noise must not grow memory
        out = self._parsed[line] = math.nan if v is None else v
        return out

    def _commit(self, k0: int, nt: int, chunks: np.ndarray, ends: np.ndarray, raw: bytes,
                nl: np.ndarray, vals: np.ndarray, arrive: np.ndarray, tk: np.ndarray,
                last_good: np.ndarray) -> LineSpan:
        """Leave the driver, its line buffer and the port as the reads of ``nt`` ticks
        would."""
        d = self.driver
        h = d.health
        base = h.snapshot()
        n = len(vals)
        cum = {"messages": np.cumsum(np.bincount(arrive, minlength=nt)[:nt])}
        last_t = np.full(nt, np.nan)
        last_t[arrive] = tk[arrive]
        idx = np.where(~np.isnan(last_t), np.arange(nt), -1)
        np.maximum.accumulate(idx, out=idx)
        cum["last_t"] = np.where(idx >= 0, last_t[np.maximum(idx, 0)], np.nan)
        if n:
            h.messages += n
            h.last_reading_t = float(tk[arrive[-1]])
            h.extra["silent"] = False
            h.extra["babbling"] = False
            d._malformed.add_clear(n)
            d._jumped.add_clear(n)
            d._garbage_since_good = 0
            d._last_good = float(last_good[nt - 1])
            d._prev = d._used = (float(vals[-1]), float(tk[arrive[-1]]))
        taken = int(nl[n - 1]) + 1 if n else 0
        d._splitter._buf = bytearray(raw[taken:int(ends[nt - 1])])
        self.port.advance(int(chunks[nt - 1]))
        values = {DISTANCE: vals}
        taken = h.extra["other_target"]
        if taken:  # as each line's reading carries it (Ar4000Driver._parse)
            values[TARGETS_TAKEN] = np.full(n, float(taken))
        return LineSpan(k0, nt, k0 + arrive, values,
                        chunks[:nt] >= self.stream.chunk_count, base, cum)
