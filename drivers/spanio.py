"""A recorded serial stream as arrays, for drivers that read many ticks of it at once.

A replay stepped by its loop releases a recorded chunk at the first tick at or after
its time, and a streaming driver reads all that is released at each tick. A span
reader (:mod:`drivers.xsens.serial_span`, :mod:`drivers.acuity.span`) needs, for a
run of ticks, the bytes the driver would hold and how far into them each tick's
reads reach: :meth:`RecordedStream.released` gives both.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import DriverHealth


@dataclass
class Released:
    """What ticks ``k0 .. k0 + len(t) - 1`` release, after what the driver holds."""

    t: np.ndarray
    """Each tick's time (``k * period``, as the loop computes it)."""
    chunks: np.ndarray
    """Chunks released by the end of each tick (the port's position then)."""
    ends: np.ndarray
    """Bytes of ``data`` fed to the driver by the end of each tick."""
    data: np.ndarray
    """The bytes the driver held, then those the ticks release (uint8)."""


class RecordedStream:
    """A port's recorded chunks as arrays; ``port`` has ``recording()`` (the chunks'
    times and bytes) and ``position`` (chunks released so far), as the fast replay's
    in-memory port."""

    def __init__(self, port: Any) -> None:
        self.port = port
        self._n = -1

    def _prepare(self) -> None:
        """The recording as arrays (again if it changed since)."""
        times, chunks = self.port.recording()
        if len(times) == self._n:
            return
        self.times = np.array(times, dtype=float)
        lens = np.fromiter(map(len, chunks), dtype=np.int64, count=len(chunks))
        self.offsets = np.concatenate([[0], np.cumsum(lens)])
        self.data = np.frombuffer(b"".join(chunks), dtype=np.uint8)
        self._n = len(times)

    @property
    def chunk_count(self) -> int:
        return self._n

    def released(self, held: bytes | bytearray, k0: int, k1: int, period: float) -> Released:
        """The ticks ``k0 .. k1 - 1``: what they release after ``held`` (the driver's
        unparsed bytes)."""
        self._prepare()
        t = np.arange(k0, k1) * period
        i0 = self.port.position
        j = np.maximum(np.searchsorted(self.times, t, side="right"), i0)
        base = self.offsets[i0]
        ends = len(held) + self.offsets[j] - base
        data = np.concatenate([np.frombuffer(bytes(held), dtype=np.uint8),
                               self.data[base:self.offsets[j[-1]]]])
        return Released(t, j, ends, data)


@dataclass
class SpanResult:
    """What a span reader's reads of ticks ``k0 .. k0 + ticks - 1`` did; each driver's
    subclass adds what its health after each tick needs (:meth:`health_after`)."""

    k0: int
    ticks: int
    reading_ticks: np.ndarray
    """Tick of each emitted reading."""
    values: dict[str, np.ndarray]
    """Each quantity the driver reads, per emitted reading."""
    exhausted: np.ndarray
    """Per tick: the recording had nothing left to release after it."""
    base: DriverHealth
    """The driver's health before the first tick."""

    def health_after(self, i: int) -> DriverHealth:
        """A copy of the driver's health as it was after tick ``k0 + i``."""
        raise NotImplementedError
