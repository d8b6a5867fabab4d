"""A gpsd-style packet sniffer: find frames in a byte stream, resync on garbage, count losses.

Serial lines deliver bytes, not messages: a driver may start listening mid-frame, a
cable may glitch, a device at the wrong baud rate sends noise. :class:`PacketSniffer`
keeps one buffer, looks for a sync marker with ``bytes.find`` (no per-byte Python
loop), asks a protocol-specific ``measure`` callback whether a complete, valid frame
starts there, and otherwise drops *one* byte and searches again, so a damaged or
truncated frame never swallows the good frame behind it.

Every byte that is not part of a delivered frame is counted in ``rejected_bytes``;
every candidate that had a plausible header but failed its check is counted in
``bad_frames``. Invariant (tested): bytes fed == bytes in delivered frames +
``rejected_bytes`` + ``pending``.

A protocol plugs in with a ``measure(buf, start) -> int`` function:

* ``n > 0``: a complete, valid frame of ``n`` bytes starts at ``start``;
* :data:`NEED_MORE`: the header looks plausible but more bytes are needed;
* :data:`NOT_A_FRAME`: the header is implausible (e.g. a length out of range);
* :data:`BAD_FRAME`: the frame is complete but its check (checksum, CRC) failed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

NEED_MORE = 0
NOT_A_FRAME = -1
BAD_FRAME = -2

Measure = Callable[[bytearray, int], int]
Make = Callable[[bytearray, int, int], Any]


class PacketSniffer:
    """Streaming frame finder with resynchronisation and loss counters.

    ``sync`` is the byte string every frame starts with (``b"\\xfa\\xff"`` for Xbus,
    ``b"\\n"``-terminated protocols can use the previous terminator). ``max_pending``
    bounds memory when a stream never yields a frame: the oldest bytes are dropped
    and counted as rejected. ``make(buf, start, length)`` builds what :meth:`feed`
    returns for a frame (default: the frame's bytes), saving a second copy per frame.
    """

    __slots__ = ("sync", "measure", "make", "max_pending", "rejected_bytes", "bad_frames",
                 "frames", "_buf")

    def __init__(self, sync: bytes, measure: Measure, max_pending: int = 1 << 16,
                 make: Make | None = None) -> None:
        if not sync:
            raise ValueError("sync marker must not be empty")
        self.sync = bytes(sync)
        self.measure = measure
        self.make = make
        self.max_pending = max_pending
        self.rejected_bytes = 0
        self.bad_frames = 0
        self.frames = 0
        self._buf = bytearray()

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Any]:
        """Add bytes; return every complete valid frame now available, in stream order."""
        buf = self._buf
        buf += data
        out: list[bytes] = []
        sync = self.sync
        measure = self.measure
        make = self.make
        pos = 0
        n = len(buf)
        while True:
            i = buf.find(sync, pos)
            if i < 0:
                # Keep a tail that could be the start of a split sync marker.
                keep = 0
                for k in range(min(len(sync) - 1, n - pos), 0, -1):
                    if buf.endswith(sync[:k]):
                        keep = k
                        break
                self.rejected_bytes += n - pos - keep
                pos = n - keep
                break
            if i > pos:
                self.rejected_bytes += i - pos
            r = measure(buf, i)
            if r > 0:
                out.append(bytes(buf[i:i + r]) if make is None else make(buf, i, r))
                pos = i + r
                continue
            if r == NEED_MORE:
                pos = i
                break
            if r == BAD_FRAME:
                self.bad_frames += 1
            # Drop only the first byte: the next good frame may start inside this one.
            self.rejected_bytes += 1
            pos = i + 1
        if pos:
            del buf[:pos]
        if len(buf) > self.max_pending:
            drop = len(buf) - self.max_pending
            self.rejected_bytes += drop
            del buf[:drop]
        self.frames += len(out)
        return out

    def finish(self) -> int:
        """End of stream: count what is left (a truncated frame) as rejected; return it."""
        n = len(self._buf)
        if n:
            self.rejected_bytes += n
            if self._buf.startswith(self.sync):
                self.bad_frames += 1
            self._buf.clear()
        return n

    def reset(self) -> None:
        """Forget buffered bytes (e.g. after reopening a port); counters are kept."""
        self._buf.clear()
