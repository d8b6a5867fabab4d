"""Fast replay's bulk front end: each device decoded on its own, samples built with numpy.

The stepped fast replay (:mod:`shoveld.replay.sync`) runs the four drivers, the
store and the assembler inside every 10 ms tick. Nothing a driver does there depends
on another device or on the engine, so here each device's driver runs alone over a
span of ticks (:class:`~shoveld.replay.sync.SyncDevice`, the same stepping,
handshakes, parsers and health rules), and its readings are kept with their ticks.
Where nothing but the usual can happen, a driver's span reader does the work of many
of its per-tick reads at once on the recording as numpy arrays (the MTi's frames, the
laser's lines, the ADC's polls; ``drivers/*/span.py``, ``drivers/xsens/serial_span.py``).
The samples of the whole span are then built at once with numpy by the assembler's
rules (:meth:`BulkFeed._assemble`), and the loop only hands each one to the engine
(:class:`BulkAssembler` stands in for the service's assembler).

Work goes in spans of ``span_ticks`` so that memory does not grow with the capture.
``tests/replay/test_bulk.py`` checks sample for sample and pass for pass that this
gives what the stepped path gives on every committed capture.
"""

from __future__ import annotations

import gc
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.acuity.ar4000 import Ar4000Driver
from drivers.acuity.span import Ar4000SpanReader
from drivers.base import TARGETS_TAKEN, DriverHealth, Reading
from drivers.modbus_adc.driver import ModbusAdcDriver
from drivers.modbus_adc.span import ModbusSpanReader
from drivers.spanio import SpanResult
from drivers.xsens.serial_driver import MtiSerialDriver
from drivers.xsens.serial_span import MtiSpanReader
from shoveld.daemon.assemble import DeviceState
from shoveld.daemon.config import LASER_KINDS, MTI_KINDS, DeviceConfig
from shoveld.daemon.store import ReadingStore
from shoveld.installation import Installation
from shoveld.replay.sync import MemoryModbus, MemorySerial, SyncDevice, SyncReplay
from shoveld.sample import CROWD_TARGET_CHANGED, SIGNAL_FIELDS, Sample
from shoveld.signals.columns import BY_NAME

_COL = {name: i for i, name in enumerate(SIGNAL_FIELDS)}
_MARKS = (*SIGNAL_FIELDS, CROWD_TARGET_CHANGED)
_BIT = {name: 1 << i for i, name in enumerate(_MARKS)}
"""A bit per signal (and for the laser's change of target), for a tick's invalid set as
one integer."""
_EMPTY: frozenset[str] = frozenset()
SpanReader = MtiSpanReader | Ar4000SpanReader | ModbusSpanReader
"""A driver's reads of a run of ticks at once (``read(k0, k1)``; None where it cannot)."""
_SPAN_READ_TICKS = 3000
"""Ticks a span read takes on at most (its buffers stay small; its cost is per call)."""
_RETRY_MAX_TICKS = 64
"""The longest wait, in ticks, before trying a span read again after one could not start."""
OK, INVALID, STALE, DISCONNECTED, NO_DATA = range(5)
STATES = ("ok", "invalid", "stale", "disconnected", "no_data")
"""Device states as the assembler names them (:class:`DeviceState`)."""


def _keys(dev: DeviceConfig) -> tuple[str, ...]:
    """The reading quantities the assembler uses from a device of this kind."""
    if dev.kind in MTI_KINDS:
        return ("pitch_deg", "yaw_deg")
    if dev.kind in LASER_KINDS:
        return ("distance_m", TARGETS_TAKEN)
    return tuple(dev.signals)


class Column:
    """A column of a span grown by single values (the per-tick steps) and by whole
    arrays (the span reads), in their order. The span reads' arrays stay arrays: they
    went through Python lists and back to numpy before (0.4 us a tick of the replay)."""

    __slots__ = ("items", "parts", "dtype")

    def __init__(self, dtype: type) -> None:
        self.items: list[Any] = []
        """Values appended one by one since the last array (cleared, never replaced: a
        sink holds its bound ``append``)."""
        self.parts: list[np.ndarray] = []
        self.dtype = dtype

    def _close_items(self) -> None:
        if self.items:
            self.parts.append(np.array(self.items, dtype=self.dtype))
            self.items.clear()

    def extend(self, a: np.ndarray) -> None:
        """Append an array's values after those appended so far."""
        self._close_items()
        self.parts.append(np.asarray(a, dtype=self.dtype))

    def array(self) -> np.ndarray:
        """All values, as one array (kept as the column's only part)."""
        self._close_items()
        parts = self.parts
        if len(parts) != 1:
            parts[:] = [np.concatenate(parts) if parts else np.empty(0, self.dtype)]
        return parts[0]

    def __len__(self) -> int:
        return sum(map(len, self.parts)) + len(self.items)

    def keep_last(self) -> None:
        """Only the last value stays (none if there is none), copied: a view would keep
        the whole span's array alive."""
        a = self.array()
        self.parts[:] = [a[-1:].copy()]

    def clear(self) -> None:
        self.items.clear()
        self.parts.clear()


@dataclass
class Track:
    """One device's readings over a span, as columns (NaN: invalid or missing)."""

    keys: tuple[str, ...]
    tick: Column = field(default_factory=lambda: Column(np.int64))
    """Tick index at which each reading reached the store."""
    t_host: Column = field(default_factory=lambda: Column(np.float64))
    cols: list[Column] = field(default_factory=list)
    connected: Column = field(default_factory=lambda: Column(np.bool_))
    """The driver's ``health.connected`` after each tick of the span."""
    done: Column = field(default_factory=lambda: Column(np.bool_))
    """After each tick of the span: the capture's end has passed and nothing is left."""
    health: dict[int, DriverHealth] = field(default_factory=dict)
    """Copies of the driver's health where the service may look at it (its health
    ticks, and where ``connected`` changed)."""
    dropped: int = 0
    """Readings of earlier spans no longer in the columns."""
    last_invalid: list[str] = field(default_factory=list)
    """The device's invalid signals at its last tick with a usable reading."""

    def __post_init__(self) -> None:
        self.cols = [Column(np.float64) for _ in self.keys]

    def sink(self, at: list[int]) -> Callable[[Reading], None]:
        """A driver sink that keeps only what the assembler uses; ``at[0]``: the tick."""
        nan = math.nan
        appends = [(k, c.items.append) for k, c in zip(self.keys, self.cols, strict=True)]
        tick, t_host = self.tick.items.append, self.t_host.items.append

        def put(r: Reading) -> None:
            tick(at[0])
            t_host(r.t_host)
            vals, bad = r.values, r.invalid
            for k, add in appends:
                add(nan if k in bad else vals.get(k, nan))
        return put

    def keep_last(self) -> None:
        """Start a new span, keeping the newest reading (the next span may still use it)."""
        n = len(self.tick)
        if n:
            self.dropped += n - 1
            self.tick.keep_last()
            self.t_host.keep_last()
            for c in self.cols:
                c.keep_last()
        self.connected.clear()
        self.done.clear()
        self.health.clear()


@dataclass
class Span:
    """Samples of ticks ``k0 .. k0 + len(samples) - 1`` and what the service may show."""

    k0: int
    samples: list[Sample]
    views: dict[int, dict[str, tuple[DriverHealth, DeviceState, int]]]
    """Per tick where the service looks at health: per device (driver health, device
    state, readings so far)."""


class BulkFeed:
    """Samples of a capture for the service's ticks, built a span at a time."""

    def __init__(self, sync: SyncReplay, installation: Installation, rate_hz: float,
                 health_period_s: float, *, span_ticks: int = 6000,
                 until_s: float | None = None) -> None:
        self.sync = sync
        self.inst = installation
        self.period = 1.0 / rate_hz
        self.health_period_s = health_period_s
        self.span_ticks = span_ticks
        self.until_s = until_s
        self.devices = sync.devices
        self._at = [0]
        self.tracks: dict[str, Track] = {}
        self._devs: dict[str, SyncDevice] = {}
        for name, dev in self.devices.items():
            tr = Track(_keys(dev))
            self.tracks[name] = tr
            self._devs[name] = SyncDevice(name, sync.drivers[name], sync.transports[name],
                                          tr.sink(self._at), sync.clock)
        self._readers: dict[str, SpanReader] = {}
        """Devices whose driver reads a run of ticks at once (:mod:`drivers.xsens.serial_span`)."""
        self._retry: dict[str, tuple[int, int]] = {}
        """Per device with a span reader: (first tick to try one again, ticks to wait after
        the next failure)."""
        for name in self.devices:
            drv, port = sync.drivers[name], sync.transports[name]
            if isinstance(drv, MtiSerialDriver) and isinstance(port, MemorySerial):
                self._readers[name] = MtiSpanReader(drv, port, self.period)
            elif isinstance(drv, Ar4000Driver) and isinstance(port, MemorySerial):
                self._readers[name] = Ar4000SpanReader(drv, port, self.period)
            elif isinstance(drv, ModbusAdcDriver) and isinstance(port, MemoryModbus):
                self._readers[name] = ModbusSpanReader(drv, port, port.registers, self.period)
        self._swing_prev = math.nan
        self._taken: dict[str, float] = {}
        """Per laser, the largest count of targets taken so far (as the assembler's)."""
        self._next_health = -math.inf
        self.ticks = 0
        """Ticks produced so far; after the last span, the replay's length in ticks."""
        self.finished = False

    def tick_time(self, k: int) -> float:
        """Time of tick ``k`` as the loop computes it (``base + k * period``, base 0)."""
        return 0.0 + k * self.period

    # -- decoding ----------------------------------------------------------------------------
    def _health_ticks(self, k0: int, k1: int) -> set[int]:
        """Ticks of ``[k0, k1)`` at which the service publishes health (its own rule)."""
        out = set()
        nxt, hp = self._next_health, self.health_period_s
        t = np.arange(k0, k1) * self.period  # tick_time of each
        i = int(np.searchsorted(t, nxt, side="left"))  # the first tick at or after nxt
        while i < len(t):
            nxt = float(t[i]) + hp
            out.add(k0 + i)
            i = int(np.searchsorted(t, nxt, side="left"))
        self._next_health = nxt
        return out

    def _run_device(self, name: str, k0: int, k1: int, look: set[int]) -> None:
        """Step one driver over ticks ``[k0, k1)``, alone (no other device's driver nor
        the engine runs in between: none depends on them). A driver with a span reader
        reads runs of ticks at once wherever that does the per-tick reads' work, and
        steps tick by tick elsewhere (handshakes, resynchronising on noise, timeouts)
        and for a while after a span read could not start, so that a damaged stretch
        does not cost an attempt per tick."""
        reader = self._readers.get(name)
        sd, tr = self._devs[name], self.tracks[name]
        transport, health = sd.transport, sd.driver.health
        clock, at, step = self.sync.clock, self._at, sd.step
        conn, done = tr.connected.items.append, tr.done.items.append
        end_t, period = self.sync.end_t, self.period
        prev: bool | None = None
        k, retry = k0, self._retry.get(name, (k0, 1))
        while k < k1:
            if reader is not None and health.connected and k >= retry[0]:
                got = reader.read(k, min(k1, k + _SPAN_READ_TICKS))
                if got is not None:
                    self._take(tr, got, look, first=prev is not True)
                    prev, retry = True, (k, 1)
                    k += got.ticks
                    clock.t, at[0] = 0.0 + (k - 1) * period, k - 1
                    continue
                retry = (k + retry[1], min(2 * retry[1], _RETRY_MAX_TICKS))
            t = 0.0 + k * period  # = self.tick_time(k), inline: once per tick and device
            clock.t = t
            at[0] = k
            step(t)
            c = health.connected
            conn(c)
            if c is not prev or k in look:
                tr.health[k] = health.snapshot()
                prev = c
            done(t >= end_t and getattr(transport, "exhausted", True)
                 and not transport.in_waiting)
            k += 1
        self._retry[name] = retry

    def _take(self, tr: Track, got: SpanResult, look: set[int], first: bool) -> None:
        """A span read's readings, connection, end and health into the device's track."""
        n, k0, period = got.ticks, got.k0, self.period
        rt = got.reading_ticks
        tr.tick.extend(rt)
        tr.t_host.extend(rt * period)  # tick_time of each
        for key, col in zip(tr.keys, tr.cols, strict=True):
            v = got.values.get(key)  # a quantity the driver does not read: NaN, as the sink
            col.extend(v if v is not None else np.full(len(rt), math.nan))
        tr.connected.extend(np.ones(n, dtype=bool))
        t = np.arange(k0, k0 + n) * period
        tr.done.extend((t >= self.sync.end_t) & got.exhausted)
        marks = sorted(k for k in look if k0 <= k < k0 + n)
        if first:
            marks = sorted({k0, *marks})
        for k in marks:
            tr.health[k] = got.health_after(k - k0)

    def _first_tick_at(self, t: float) -> int:
        """Index of the first tick at or after capture time ``t``."""
        k = max(0, int(t / self.period) - 1)
        while self.tick_time(k) < t:
            k += 1
        return k

    def _last_tick(self) -> int | None:
        """Index of the first tick at which ``until_s`` is reached, if given."""
        return None if self.until_s is None else self._first_tick_at(self.until_s)

    def spans(self) -> Iterator[Span]:
        """Spans of samples up to the end of the capture (or ``until_s``): the stepped
        replay stops after the first tick at which every device is done, or the first
        at or past ``until_s``."""
        k0 = 0
        k_until = self._last_tick()
        k_end = self._first_tick_at(self.sync.end_t)
        while not self.finished:
            # up to the capture's end; past it a few ticks at a time (a driver that goes on
            # after its data stops tries to reconnect, with handshakes that wait real time)
            k1 = min(k0 + self.span_ticks, k_end + 1) if k0 <= k_end else k0 + 8
            if k_until is not None and k1 > k_until:
                k1, self.finished = k_until + 1, True
            look = self._health_ticks(k0, k1)
            for name in self.devices:
                self._run_device(name, k0, k1, look)
            all_done = np.logical_and.reduce([tr.done.array()
                                              for tr in self.tracks.values()])
            hit = np.flatnonzero(all_done)
            if len(hit):
                k1, self.finished = k0 + int(hit[0]) + 1, True
            span = self._assemble(k0, k1, look)
            self.ticks = k1
            yield span
            for tr in self.tracks.values():
                tr.keep_last()
            k0 = k1

    # -- assembly ----------------------------------------------------------------------------
    def _assemble(self, k0: int, k1: int, look: set[int]) -> Span:
        """The samples of ticks ``[k0, k1)``, and what the service may show of health."""
        ks = np.arange(k0, k1)
        t = 0.0 + ks * self.period
        rows = np.full((len(ks), len(SIGNAL_FIELDS)), np.nan)
        rows[:, 0] = t
        bad = np.zeros(len(ks), dtype=np.int64)  # a bit per signal of the tick's invalid set
        views: dict[int, dict[str, tuple[DriverHealth, DeviceState, int]]] = {}
        for name, dev in self.devices.items():
            self._device(name, dev, ks, t, rows, bad, views)
        return Span(k0, self._samples(rows, bad), views)

    def _device(self, name: str, dev: DeviceConfig, ks: np.ndarray, t: np.ndarray,
                rows: np.ndarray, bad: np.ndarray,
                views: dict[int, dict[str, tuple[DriverHealth, DeviceState, int]]]) -> None:
        """One device's part of a span: its signals into ``rows`` where it is usable, its
        signals' bits into ``bad`` where not, and its state where health is looked at."""
        tr = self.tracks[name]
        n, k0 = len(ks), int(ks[0])
        conn = tr.connected.array()[:n]
        rk = tr.tick.array()
        # the newest reading by each tick: the readings at or before it, less one (the
        # ticks are k0, k0 + 1, ...: counted over the sorted reading ticks at once, as
        # searchsorted(rk, ks, side="right") - 1 gives, without a search per tick)
        idx = np.cumsum(np.bincount(np.clip(rk - k0, 0, n), minlength=n + 1)[:n]) - 1
        have = idx >= 0
        j = np.where(have, idx, 0)
        th = tr.t_host.array()
        if np.any(th > 0.0 + rk * self.period):  # the stepped clock cannot do this
            raise RuntimeError(f"{name}: a reading stamped after its tick; the bulk "
                               "replay assumes readings stamped by the stepped clock")
        age = t - th[j] if len(th) else np.full(n, np.nan)
        state = np.full(n, OK, dtype=np.int8)
        state[~have] = NO_DATA
        stale = have & (age > dev.max_age_s)
        state[stale] = STALE
        state[~conn] = DISCONNECTED
        live = have & conn & ~stale
        bad[~live] |= sum(_BIT[sg] for sg in dev.signals)
        cols = [c.array()[j] if len(c) else np.full(n, np.nan) for c in tr.cols]
        sig_bad = self._contribute(dev, cols, live, rows)
        bad |= sig_bad
        if dev.kind in LASER_KINDS:
            bad |= self._target_changed(name, cols[1], live)
        state[live & (sig_bad != 0)] = INVALID

        def invalid_at(i: int) -> list[str]:
            return sorted(sg for sg in dev.signals if int(sig_bad[i]) & _BIT[sg])
        # the assembler leaves a device's invalid list as it was while it is stale or
        # disconnected: the list of its last tick with a usable reading
        last_live = np.maximum.accumulate(np.where(live, np.arange(n), -1))
        for k in sorted(tr.health):
            i = k - k0
            if not 0 <= i < n:
                continue
            li = int(last_live[i])
            st = DeviceState(STATES[state[i]], float(age[i]) if have[i] else None,
                             tr.last_invalid if li < 0 else invalid_at(li))
            views.setdefault(k, {})[name] = (tr.health[k], st, tr.dropped + int(idx[i]) + 1)
        if n and last_live[-1] >= 0:
            tr.last_invalid = invalid_at(int(last_live[-1]))

    def _contribute(self, dev: DeviceConfig, cols: list[np.ndarray], live: np.ndarray,
                    rows: np.ndarray) -> np.ndarray:
        """Put one device's signals into ``rows`` at its live ticks (the assembler's
        rules, on columns); the bits of its signals that were invalid there."""
        inst = self.inst
        sig_bad = np.zeros(len(live), dtype=np.int64)
        if dev.kind in MTI_KINDS:
            pitch, yaw = cols
            handle = inst.handle_deg(pitch)
            lo, hi = BY_NAME["handle_deg"].lo, BY_NAME["handle_deg"].hi
            ok = (lo <= handle) & (handle <= hi)
            use = live & ok
            rows[use, _COL["handle_deg"]] = handle[use]
            sig_bad[live & ~ok] |= _BIT["handle_deg"]
            yaw_bad = np.isnan(yaw)
            sig_bad[live & yaw_bad] |= _BIT["swing_deg"]
            # the unwrapped swing carries state from tick to tick, as in the assembler
            at = np.flatnonzero(live & ~yaw_bad)
            out, self._swing_prev = unwrapped_swing(inst, yaw[at], self._swing_prev)
            rows[at, _COL["swing_deg"]] = out
        elif dev.kind in LASER_KINDS:
            v = cols[0]
            crowd = inst.crowd_m(v)  # NaN stays NaN
            lo, hi = BY_NAME["crowd_m"].lo, BY_NAME["crowd_m"].hi
            ok = (lo <= crowd) & (crowd <= hi)
            rows[live & ok, _COL["crowd_m"]] = crowd[live & ok]
            sig_bad[live & ~ok] |= _BIT["crowd_m"]
        else:
            for sg, v in zip(dev.signals, cols, strict=True):
                lo, hi = BY_NAME[sg].lo, BY_NAME[sg].hi
                ok = (lo <= v) & (v <= hi)
                rows[live & ok, _COL[sg]] = v[live & ok]
                sig_bad[live & ~ok] |= _BIT[sg]
        return sig_bad

    def _target_changed(self, name: str, taken: np.ndarray, live: np.ndarray) -> np.ndarray:
        """:data:`CROWD_TARGET_CHANGED`'s bit at each live tick whose newest reading's
        count of targets taken is above all before it (the assembler's rule)."""
        seen = np.where(live & ~np.isnan(taken), taken, -np.inf)
        top = np.maximum.accumulate(np.concatenate([[self._taken.get(name, 0.0)], seen]))
        self._taken[name] = float(top[-1])
        return np.where(top[1:] > top[:-1], _BIT[CROWD_TARGET_CHANGED], 0)

    @staticmethod
    def _samples(rows: np.ndarray, bad: np.ndarray) -> list[Sample]:
        """Sample objects of the rows; one frozenset per distinct invalid pattern."""
        sets: dict[int, frozenset[str]] = {0: _EMPTY}
        bits = bad.tolist()
        for b in set(bits):  # not np.unique: its first call imports numpy.ma (10 ms)
            if b:
                sets[b] = frozenset(sg for i, sg in enumerate(_MARKS) if b >> i & 1)
        # Sample called through map over the columns: no argument list built per row.
        # Without the cyclic collector meanwhile: samples hold only numbers and sets, so
        # there is no cycle to find, and each of the collections the 6,000 new objects
        # set off walked the columns' lists (90,000 items) and the growing result
        was = gc.isenabled()
        gc.disable()
        try:
            return list(map(Sample, *rows.T.tolist(), map(sets.__getitem__, bits)))
        finally:
            if was:
                gc.enable()


def unwrapped_swing(inst: Installation, yaw: np.ndarray, prev: float
                    ) -> tuple[list[float], float]:
    """Swing angles of MTi yaws, each continued from the one before (the first from
    ``prev``), and the last: ``unwrap_deg(prev, inst.swing_deg(y))`` in turn, with their
    operations in their order (numpy's remainder is Python's float %), the swing of
    the whole column at once and the unwrapping inlined."""
    swing = inst.swing_yaw_sign * (np.remainder(yaw - inst.swing_yaw_zero_deg + 180.0,
                                                360.0) - 180.0)
    out = []
    for a in swing.tolist():
        prev = a if prev != prev else prev + ((a - prev + 180.0) % 360.0 - 180.0)
        out.append(prev)
    return out, prev


class ReplayedDriver:
    """What the service sees of a driver in bulk replay: its health as at the tick."""

    def __init__(self, name: str, health: DriverHealth) -> None:
        self.name = name
        self.health = health


class BulkSession:
    """The replay session of a bulk replay: the drivers' transports and the feed."""

    def __init__(self, sync: SyncReplay, assembler: BulkAssembler) -> None:
        self.sync = sync
        self.assembler = assembler
        self.clock = sync.clock

    def limit(self, until_s: float | None) -> None:
        """Stop at this capture time (before the first tick is served)."""
        self.assembler.feed.until_s = until_s

    @property
    def finished(self) -> bool:
        return self.assembler.finished

    @property
    def error(self) -> BaseException | None:
        return self.assembler.error

    def close(self) -> None:
        self.sync.close()


class BulkAssembler:
    """The service's assembler in bulk replay: the feed's samples, one per tick.

    Where the service looks at health (its health ticks, and while it waits for the
    drivers), the replayed drivers, the device states and the store's counts are set
    to what the stepped replay had at that tick.
    """

    def __init__(self, feed: BulkFeed, drivers: dict[str, ReplayedDriver],
                 store: ReadingStore) -> None:
        self.feed = feed
        self.drivers = drivers
        self.store = store
        self.state: dict[str, DeviceState] = {n: DeviceState() for n in feed.devices}
        self.new_arrivals: list[tuple[str, float]] = []
        self._spans = feed.spans()
        self._samples: list[Sample] = []
        self._views: dict[int, Any] = {}
        self._k0 = 0
        self._i = 0
        self._n = 0
        """Samples in the current span."""
        self._last_span = False
        self.finished = False
        """The last tick of the capture has been served (a plain attribute, not a
        property: the replay's loop asks at every tick)."""
        self.error: BaseException | None = None
        """What stopped the feed before the capture's end (the replay raises it)."""
        self.k = -1
        """Index of the last tick served."""

    def sample(self, t: float) -> Sample:
        i = self._i
        if i >= self._n:
            try:
                span = next(self._spans)
            except BaseException as e:  # the replay must end here, not fail every tick
                self.error, self._last_span, self._samples, self._n = e, True, [], 0
                self.finished = True
                raise
            self._samples, self._views, self._k0, i = span.samples, span.views, span.k0, 0
            self._n = len(span.samples)
            self._last_span = self.feed.finished  # the feed works lazily: it knows now
        self._i = i + 1
        if self._last_span and i + 1 >= self._n:
            self.finished = True
        k = self.k = self._k0 + i
        view = self._views.get(k)
        if view is not None:
            self._show(view)
        return self._samples[i]

    def _show(self, view: dict[str, tuple[DriverHealth, DeviceState, int]]) -> None:
        for name, (health, st, count) in view.items():
            self.drivers[name].health = health
            self.state[name] = st
            self.store.set_count(name, count)

