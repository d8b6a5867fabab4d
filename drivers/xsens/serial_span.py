"""The MTi serial driver's ``read`` over many ticks of a recorded stream at once.

Fast replay steps each driver once per 10 ms tick; for the MTi that is a parser call
and a frame decode per tick in Python. :class:`MtiSpanReader` does what those reads
would do for a run of ticks in one go: the bytes each tick would release, framed and
checked by :func:`~drivers.xsens.bulk.clean_run`, the fields decoded as columns, and
the driver's own rules applied on the columns - :func:`consistent` for
``MtiSerialDriver._consistent``, the packet-counter gaps, the data timeout, the health
counters - with the driver's state (parser buffer, previous frame, counters) left as
the reads would leave it. It stops before the first tick where anything else could
happen (noise, a bad checksum, another message, a frame of another layout, a
timeout); the per-tick ``read`` takes over there.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base import DriverHealth
from drivers.spanio import RecordedStream, SpanResult
from drivers.xsens.bulk import FrameLayout, Run, clean_run
from drivers.xsens.mtdata2 import TYPE_MASK, XDI
from drivers.xsens.serial_driver import (
    ACC_MAX,
    AGREEMENT_DEG,
    GYR_MAX,
    SAMPLE_TIME_FINE_S,
    STATUS_RESERVED,
    STATUS_SELFTEST,
    TINY,
    MtiSerialDriver,
    orientations_agree,
    sample_time_slack_s,
)

if TYPE_CHECKING:
    from shoveld.replay.sync import MemorySerial

log = logging.getLogger(__name__)

_AGREE_S2 = math.sin(math.radians(AGREEMENT_DEG) / 2.0) ** 2
_MARGIN = 1e-12
"""Where numpy's sin/cos (not bit for bit libm's) could tip the agreement test either
way, far wider than their rounding: those frames are checked by the scalar function."""


def _pymax3(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Python's ``max(a, b, c)`` element-wise, NaN included (a later NaN never wins)."""
    m = np.where(b > a, b, a)
    return np.where(c > m, c, m)


def consistent(e: np.ndarray, g: np.ndarray | None, acc: np.ndarray | None,
               q: np.ndarray | None, pc: np.ndarray, stf: np.ndarray,
               prev: tuple[Any, ...] | None, rate: float, max_gap: int,
               sw: np.ndarray | None = None) -> np.ndarray:
    """``MtiSerialDriver._consistent`` of consecutive frames (each one's previous frame is
    the row before; the first one's is ``prev``), the same rules in the same order.
    Items not configured are None; ``sw`` (the status words) then counts as all zero."""
    n = len(pc)
    if sw is None:
        sw = np.zeros(n, np.int64)
    ok = ((np.abs(e[:, 0]) <= 180.0) & (np.abs(e[:, 1]) <= 90.0) & (np.abs(e[:, 2]) <= 180.0)
          & ((sw & STATUS_RESERVED) == 0))
    if g is not None:
        ok &= (np.abs(g) <= GYR_MAX).all(axis=1)
    if acc is not None:
        ok &= (np.abs(acc) <= ACC_MAX).all(axis=1)
    for v in (e, g, acc, q):
        if v is not None:
            a = np.abs(v)
            ok &= ~((a > 0.0) & (a < TINY)).any(axis=1)
    if q is not None:
        ok &= _agree(e, q)
    if n == 0:
        return ok
    gmax = (np.full(n, GYR_MAX / 3.0) if g is None
            else _pymax3(np.abs(g[:, 0]), np.abs(g[:, 1]), np.abs(g[:, 2])))
    ppc, pstf, pe = np.empty(n, np.int64), np.empty(n, np.int64), np.empty((n, 3))
    psw = np.empty(n, np.int64)
    ppc[1:], pstf[1:], pe[1:], psw[1:] = pc[:-1], stf[:-1], e[:-1], sw[:-1]
    if prev is not None:
        ppc[0], pstf[0], pe[0], psw[0] = prev[0], prev[1], prev[2], prev[3]
    steps = (pc - ppc) & 0xFFFF
    dt = ((stf - pstf) & 0xFFFFFFFF) * SAMPLE_TIME_FINE_S
    chain = ((1 <= steps) & (steps <= max_gap)
             & ~(np.abs(dt - steps / rate) > sample_time_slack_s(rate))
             & (((sw ^ psw) & STATUS_SELFTEST) == 0))
    limit = 2.0 + 3.0 * 57.3 * gmax * dt
    for a in range(3):
        chain &= ~(np.abs(np.remainder(e[:, a] - pe[:, a] + 180.0, 360.0) - 180.0) > limit)
    if prev is None:
        chain[0] = True
    return ok & chain


def _agree(e: np.ndarray, q: np.ndarray) -> np.ndarray:
    """:func:`orientations_agree` of each row, the doubtful ones by the function itself."""
    q0, q1, q2, q3 = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    n2 = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    h = np.radians(e) * 0.5
    c, s = np.cos(h), np.sin(h)
    cr, cp, cy, sr, sp, sy = c[:, 0], c[:, 1], c[:, 2], s[:, 0], s[:, 1], s[:, 2]
    dot = ((cr * cp * cy + sr * sp * sy) * q0 + (sr * cp * cy - cr * sp * sy) * q1
           + (cr * sp * cy + sr * cp * sy) * q2 + (cr * cp * sy - sr * sp * cy) * q3)
    with np.errstate(invalid="ignore", divide="ignore"):
        s2 = 1.0 - dot * dot / n2
    out = (np.abs(n2 - 1.0) <= 1e-4) & (s2 <= _AGREE_S2)
    for i in np.flatnonzero(np.abs(s2 - _AGREE_S2) <= _MARGIN).tolist():
        out[i] = orientations_agree(tuple(e[i].tolist()), tuple(q[i].tolist()))
    return out


@dataclass
class SpanRead(SpanResult):
    """The MTi's span reads: each of the driver's ``value_keys`` per emitted reading
    (every one valid)."""

    cum: dict[str, np.ndarray]
    """Per tick: ``messages``, ``bad_frames``, ``dropped_packets`` added so far, and the
    ``last_reading_t`` then (NaN: unchanged)."""

    def health_after(self, i: int) -> DriverHealth:
        """A copy of the driver's health as it was after tick ``k0 + i``."""
        c = self.cum
        h = self.base.snapshot()
        h.messages += int(c["messages"][i])
        h.bad_frames += int(c["bad_frames"][i])
        t = float(c["last_reading_t"][i])
        if not math.isnan(t):
            h.last_reading_t = t
        h.extra["inconsistent_frames"] += int(c["bad_frames"][i])
        h.extra["dropped_packets"] += int(c["dropped_packets"][i])
        return h


class MtiSpanReader:
    """An :class:`MtiSerialDriver` read tick after tick from an in-memory recording.

    ``port`` holds ``stream`` (the recorded ``(time, bytes)`` chunks, released at the
    first tick at or after their time), ``position`` (chunks released so far),
    ``in_waiting`` and ``advance(j)``; the driver's data timeout must run on the clock
    that stamps its readings (capture time).
    """

    def __init__(self, driver: MtiSerialDriver, port: MemorySerial, period: float) -> None:
        self.driver = driver
        self.port = port
        self.period = period
        self.stream = RecordedStream(port)
        self._layouts: dict[bytes, FrameLayout] = {}
        self._keys = tuple(dict.fromkeys((XDI.EULER_ANGLES, *(
            x & TYPE_MASK for x, _ in driver.requested_outputs()))))
        """The items of the driver's configured packet, and the Euler angles the columns
        are read from (a packet without them is left to the per-tick read)."""

    def usable(self) -> bool:
        """Whether a span read can start now (connected, nothing unread on the port)."""
        d = self.driver
        return (d.health.connected and d._ser is self.port and not self.port.in_waiting
                and d.timeout_clock is d.clock)

    def read(self, k0: int, k1: int) -> SpanRead | None:
        """Do the reads of ticks ``k0 .. k1 - 1`` (as far as nothing else can happen);
        None if not even the first tick can be done so."""
        if not self.usable():
            return None
        d = self.driver
        rel = self.stream.released(d._parser._sniffer._buf, k0, k1, self.period)
        tk, j, buf = rel.t, rel.chunks, rel.data
        run = clean_run(buf, d._parser.max_payload, self._layouts)
        if run is None:
            return None
        fields = run.layout.fields_of(self._keys)
        ids = run.layout.ids
        if fields is None or ids is None or not ids <= d._ids:
            return None  # not the configured packet: the per-tick read drops it
        rows, length = run.rows, run.layout.length
        cols = {k: FrameLayout.column(rows, f) for k, f in fields.items()}
        e, g, acc = (cols[XDI.EULER_ANGLES], cols.get(XDI.RATE_OF_TURN),
                     cols.get(XDI.ACCELERATION))
        pc, stf = cols[XDI.PACKET_COUNTER], cols[XDI.SAMPLE_TIME_FINE]
        sw = cols.get(XDI.STATUS_WORD)
        rate = float(d.health.extra.get("output_rate_hz") or d.rate_hz)
        ok = consistent(e, g, acc, cols.get(XDI.QUATERNION), pc, stf, d._prev_frame, rate,
                        d.MAX_GAP, sw)
        nt = int(np.searchsorted(rel.ends, run.clean_end, side="right"))  # in clean bytes
        ends = (np.arange(len(rows)) + 1) * length
        arrive = np.searchsorted(rel.ends, ends, side="left")  # tick index of each frame
        # the data timeout: a tick whose read finds no frame for data_timeout_s raises
        got = np.full(len(tk), -np.inf)
        got[arrive[arrive < len(tk)]] = tk[arrive[arrive < len(tk)]]
        last_valid = np.maximum(np.maximum.accumulate(got), d._last_valid)
        late = np.flatnonzero(tk - last_valid > d.data_timeout_s)
        if len(late):
            nt = min(nt, int(late[0]))
        if nt == 0:
            return None
        nf = int(np.searchsorted(arrive, nt, side="left"))  # frames read by those ticks
        return self._commit(k0, nt, tk, j, rel.ends, buf, run, nf, ok[:nf], cols, e, g, acc, pc,
                            stf, sw, last_valid)

    def _commit(self, k0: int, nt: int, tk: np.ndarray, j: np.ndarray, rel: np.ndarray,
                buf: np.ndarray, run: Run, nf: int, ok: np.ndarray,
                cols: dict[int, np.ndarray], e: np.ndarray, g: np.ndarray | None,
                acc: np.ndarray | None, pc: np.ndarray, stf: np.ndarray,
                sw: np.ndarray | None, last_valid: np.ndarray) -> SpanRead:
        """Leave the driver, its parser and the port as the reads of ``nt`` ticks would."""
        d, port = self.driver, self.port
        h = d.health
        base = h.snapshot()
        arrive = np.searchsorted(rel, (np.arange(nf) + 1) * run.layout.length, side="left")
        em = np.flatnonzero(ok)  # the frames emitted
        counters = pc[:nf][em]
        prevs = np.empty(len(counters), np.int64)
        prevs[1:] = counters[:-1]
        gaps = np.zeros(len(counters), np.int64)
        if len(counters):
            if d._prev_counter is not None:
                prevs[0] = d._prev_counter
            gaps = (counters - prevs - 1) & 0xFFFF
            if d._prev_counter is None:
                gaps[0] = 0
            for i in np.flatnonzero(gaps >= 0x8000).tolist():
                log.warning("%s: packet counter jumped back from %d to %d", d.name,
                            int(prevs[i]), int(counters[i]))
            gaps[gaps >= 0x8000] = 0
            d._prev_counter = int(counters[-1])
        if nf:
            d._prev_frame = (int(pc[nf - 1]), int(stf[nf - 1]), tuple(e[nf - 1].tolist()),
                             0 if sw is None else int(sw[nf - 1]))
        em_tick = arrive[em]
        per_tick = {"messages": np.bincount(em_tick, minlength=nt)[:nt],
                    "bad_frames": np.bincount(arrive[~ok], minlength=nt)[:nt],
                    "dropped_packets": np.bincount(em_tick, weights=gaps, minlength=nt)[:nt]}
        cum = {k: np.cumsum(v).astype(np.int64) for k, v in per_tick.items()}
        last_t = np.full(nt, np.nan)
        last_t[em_tick] = tk[em_tick]
        cum["last_reading_t"] = _ffill(last_t)
        h.messages += len(em)
        h.bad_frames += int(len(ok) - len(em))
        h.extra["inconsistent_frames"] += int(len(ok) - len(em))
        h.extra["dropped_packets"] += int(gaps.sum())
        if len(em):
            h.last_reading_t = float(tk[em_tick[-1]])
        d._last_valid = float(last_valid[nt - 1])
        sniffer = d._parser._sniffer
        sniffer._buf = bytearray(buf[nf * run.layout.length:rel[nt - 1]].tobytes())
        sniffer.frames += nf
        port.advance(int(j[nt - 1]))
        vals = {"roll_deg": e[:, 0], "pitch_deg": e[:, 1], "yaw_deg": e[:, 2],
                "packet_counter": pc.astype(float), "sample_time_fine": stf.astype(float)}
        if g is not None:
            vals["gyr_x"], vals["gyr_y"], vals["gyr_z"] = g[:, 0], g[:, 1], g[:, 2]
        if acc is not None:
            vals["acc_x"], vals["acc_y"], vals["acc_z"] = acc[:, 0], acc[:, 1], acc[:, 2]
        if sw is not None:
            vals["status_word"] = sw.astype(float)
        every = len(em) == nf  # the usual case: views, no copies
        values = {k: vals[k][:nf] if every else vals[k][:nf][em] for k in d.value_keys}
        return SpanRead(k0, nt, k0 + em_tick, values, j[:nt] >= self.stream.chunk_count, base,
                        cum)


def _ffill(a: np.ndarray) -> np.ndarray:
    """Each NaN replaced by the last number before it (NaN where there is none)."""
    idx = np.where(~np.isnan(a), np.arange(len(a)), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, a[np.maximum(idx, 0)], np.nan)
