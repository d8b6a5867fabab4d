"""The shared store between driver threads and the loop: the freshest readings per device.

Driver threads only append (through :meth:`ReadingStore.sink`); the loop asks, at
each tick, for the readings that bracket the tick time. Each device keeps a few
recent readings so a reading that lands a moment after the tick's deadline can be
interpolated with the one before instead of being used as if it were on time.
Nothing here waits on a device: a silent device simply has old readings.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import NamedTuple

from drivers.base import Reading


class Stored(NamedTuple):
    """A reading plus when it reached the store (host monotonic, for latency figures).

    A named tuple, built with ``tuple.__new__`` by the sinks: a third of the cost of a
    dataclass' ``__init__``, on every reading. Identity matters, not equality (the
    assembler's cache asks ``is``)."""

    reading: Reading
    arrived: float
    seq: int


_new = tuple.__new__


class ReadingStore:
    """Recent readings per device; thread-safe, never blocks for long."""

    def __init__(self, devices: Iterable[str], depth: int = 8) -> None:
        self._lock = threading.Lock()
        self._recent: dict[str, deque[Stored]] = {d: deque(maxlen=depth) for d in devices}
        self._count: dict[str, int] = dict.fromkeys(self._recent, 0)

    @property
    def devices(self) -> list[str]:
        return list(self._recent)

    def sink(self, device: str, threaded: bool = True) -> Callable[[Reading], None]:
        """The callback a driver thread hands its readings to. ``threaded=False`` for a
        store that only one thread uses (fast replay steps the drivers in the loop's
        thread): the same bookkeeping without the lock."""
        recent = self._recent[device]  # KeyError for an unknown device
        count, lock, monotonic = self._count, self._lock, time.monotonic

        def put(r: Reading) -> None:  # = self.put(device, r), one call less per reading
            arrived = monotonic()
            with lock:
                n = count[device] + 1
                count[device] = n
                recent.append(_new(Stored, (r, arrived, n)))

        def put_unlocked(r: Reading) -> None:
            n = count[device] + 1
            count[device] = n
            recent.append(_new(Stored, (r, monotonic(), n)))
        return put if threaded else put_unlocked

    def put(self, device: str, r: Reading) -> None:
        arrived = time.monotonic()
        with self._lock:
            n = self._count[device] + 1
            self._count[device] = n
            self._recent[device].append(Stored(r, arrived, n))

    def bracket(self, device: str, t: float) -> tuple[Stored | None, Stored | None]:
        """(latest reading at or before ``t``, earliest reading after ``t``)."""
        recent = self._recent[device]
        try:
            newest = recent[-1]  # atomic: no lock needed to peek at the newest
        except IndexError:
            return None, None
        if newest.reading.t_host <= t:  # the usual case: nothing arrived after the tick
            return newest, None
        before: Stored | None = None
        after: Stored | None = None
        with self._lock:
            for s in reversed(recent):
                if s.reading.t_host <= t:
                    before = s
                    break
                after = s
        return before, after

    def recent(self, device: str) -> deque[Stored]:
        """The device's recent readings, oldest first (read-only for the caller; iterate
        under no circumstances without the lock: driver threads append to it)."""
        return self._recent[device]

    def times_after(self, device: str, t: float) -> list[float]:
        """Reading times (``t_host``) of the device's stored readings newer than ``t``."""
        snapshot = tuple(self._recent[device])  # one C-level copy: safe against appends
        return [s.reading.t_host for s in snapshot if s.reading.t_host > t]

    def latest_t(self, device: str) -> float | None:
        """Reading time (``t_host``) of the newest reading of ``device``, None before any."""
        try:
            return self._recent[device][-1].reading.t_host
        except IndexError:
            return None

    def set_count(self, device: str, n: int) -> None:
        """Say how many readings ``device`` has given: a feed that keeps its readings
        elsewhere (bulk replay) still shows the health topic's count and rate."""
        self._count[device] = n

    def count(self, device: str) -> int:
        """Readings received from ``device`` since start (for its sample rate)."""
        return self._count[device]
