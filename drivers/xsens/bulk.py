"""Xbus framing and MTData2 decoding over a whole buffer at once, with numpy.

A configured MTi streams one MTData2 layout back to back, so a buffer of its bytes is
a matrix: one frame per row, each field a fixed column range. :func:`clean_run` finds
the run of frames at the start of a buffer that :class:`~drivers.xsens.xbus.XbusParser`
would deliver one by one without losing a byte (preamble, bus id, header, checksum,
layout all as the first frame's), and :class:`FrameLayout` pulls the fields out of
those rows with big-endian dtypes. What breaks the run (noise, a bad checksum, another
message) is left to the streaming parser, which alone knows how to resynchronise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.xsens.mtdata2 import (
    FLOAT32,
    FLOAT64,
    FP1220,
    ITEM_TYPES,
    PRECISION_MASK,
    PRECISION_SIZE,
    TYPE_MASK,
    iter_packets,
    packet_ids,
)
from drivers.xsens.xbus import BID_MASTER, EXTENDED_LENGTH, MID, PREAMBLE

_INTS = {">H": ">u2", ">I": ">u4", ">B": "u1"}
"""MTData2 integer items (struct code) as numpy dtypes."""


@dataclass(frozen=True)
class Field:
    """Where one MTData2 item sits in a frame, and how to read it."""

    offset: int
    """First data byte, from the frame's preamble."""
    count: int
    """Values (reals) or 1 (integers)."""
    precision: int | None
    """The real precision, or None for an integer item."""
    dtype: str = ""
    """The integer item's numpy dtype."""


class FrameLayout:
    """One MTData2 frame layout: its header bytes and where each wanted item is.

    Built from a frame the device sent; :meth:`fields_of` says whether every frame with
    these header bytes decodes (in :func:`~drivers.xsens.mtdata2.mtdata2_values`) to the
    given items, each once and well formed.
    """

    def __init__(self, frame: np.ndarray, head: int) -> None:
        self.length = len(frame)
        self.head = head
        payload = frame[head:-1].tobytes()
        self.fields: dict[int, Field] = {}
        seen: dict[int, int] = {}
        structure = np.ones(self.length, dtype=bool)  # bytes every frame must share
        structure[-1] = False  # the checksum
        end = 0
        for xdi, off, size in iter_packets(payload):
            key = xdi & TYPE_MASK
            seen[key] = seen.get(key, 0) + 1
            structure[head + off:head + off + size] = False
            end = off + size
            f = _field(xdi, head + off, size)
            if f is not None:
                self.fields[key] = f
        if end < len(payload):  # a truncated tail: every byte of it must match
            structure[head + end:-1] = True
        self.repeated = {k for k, n in seen.items() if n > 1}
        self.ids = packet_ids(payload)
        """The packets' full identifiers, the same for every frame with these header
        bytes (:func:`~drivers.xsens.mtdata2.packet_ids`)."""
        self.structure = np.flatnonzero(structure)
        self.template = frame[self.structure].copy()

    def fields_of(self, keys: tuple[int, ...]) -> dict[int, Field] | None:
        """The fields of ``keys`` if each is in the layout once and well formed."""
        if any(k not in self.fields or k in self.repeated for k in keys):
            return None
        return {k: self.fields[k] for k in keys}

    @staticmethod
    def column(rows: np.ndarray, f: Field) -> np.ndarray:
        """The item's values of every row: (n, count) floats, or (n,) int64."""
        if f.precision is None:
            size = np.dtype(f.dtype).itemsize
            raw = np.ascontiguousarray(rows[:, f.offset:f.offset + size])
            return raw.view(f.dtype)[:, 0].astype(np.int64)
        width = PRECISION_SIZE[f.precision]
        raw = np.ascontiguousarray(rows[:, f.offset:f.offset + width * f.count])
        if f.precision == FLOAT32:
            return raw.view(">f4").astype(np.float64)
        if f.precision == FLOAT64:
            return raw.view(">f8").astype(np.float64)
        if f.precision == FP1220:
            return raw.view(">i4").astype(np.float64) / float(1 << 20)
        # fp16.32: a 32-bit fraction, then the signed 16-bit integer part (exact in int64)
        parts = raw.reshape(len(rows), f.count, 6)
        frac = np.ascontiguousarray(parts[:, :, :4]).view(">u4")[:, :, 0].astype(np.int64)
        whole = np.ascontiguousarray(parts[:, :, 4:]).view(">i2")[:, :, 0].astype(np.int64)
        return (whole * 4294967296 + frac).astype(np.float64) / float(1 << 32)


def _field(xdi: int, offset: int, size: int) -> Field | None:
    """How to read an item that :func:`mtdata2_values` decodes as a number (or None)."""
    t = ITEM_TYPES.get(xdi & TYPE_MASK)
    if t is None:
        return None
    if t.kind == "real":
        prec = xdi & PRECISION_MASK
        n, rem = divmod(size, PRECISION_SIZE[prec])
        if rem or n == 0 or (t.count and n != t.count):
            return None
        return Field(offset, n, prec)
    dtype = _INTS.get(t.kind)
    if dtype is None or np.dtype(dtype).itemsize != size:
        return None
    return Field(offset, 1, None, dtype)


@dataclass
class Run:
    """Frames at the start of a buffer that the streaming parser takes without a loss."""

    rows: np.ndarray
    """(n, length) bytes, one whole frame per row."""
    layout: FrameLayout
    clean_end: int
    """Bytes from the start that the parser takes with nothing rejected: the frames,
    then the start of one more that only waits for its rest."""


def frame_header(buf: np.ndarray, max_payload: int) -> tuple[int, int] | None:
    """(header bytes, frame bytes) of the MTData2 frame at the start of ``buf``."""
    if len(buf) < 6 or buf[0] != PREAMBLE or buf[1] != BID_MASTER or buf[2] != MID.MTDATA2:
        return None
    ln = int(buf[3])
    if ln != EXTENDED_LENGTH:
        return 4, ln + 5
    ln = (int(buf[4]) << 8) | int(buf[5])
    return (6, ln + 7) if ln <= max_payload else None


def clean_run(buf: np.ndarray, max_payload: int,
              layouts: dict[bytes, FrameLayout]) -> Run | None:
    """The back-to-back MTData2 frames at the start of ``buf`` with the first one's layout
    and a good checksum, as :class:`XbusParser` finds them: a frame at the very start of
    its buffer is taken when its checksum holds, then the next begins right after.
    ``layouts`` caches layouts by their first frame's structure bytes."""
    hl = frame_header(buf, max_payload)
    if hl is None or len(buf) < hl[1]:
        return None
    head, length = hl
    n = len(buf) // length
    rows = buf[:n * length].reshape(n, length)
    key = rows[0, :head].tobytes() + bytes(length.to_bytes(2, "big"))
    lay = layouts.get(key)
    if lay is None or not np.array_equal(rows[0, lay.structure], lay.template):
        lay = FrameLayout(rows[0], head)
        layouts[key] = lay
    good = (rows[:, lay.structure] == lay.template).all(axis=1)
    good &= (rows[:, 1:].sum(axis=1, dtype=np.uint32) & 0xFF) == 0
    bad = np.flatnonzero(~good)
    m = int(bad[0]) if len(bad) else n
    end = m * length
    if m == n:  # what follows the last whole frame: the start of another like it?
        tail = buf[end:]
        h = min(len(tail), head)
        if np.array_equal(tail[:h], rows[0, :h]):
            end = len(buf)
    return Run(rows[:m], lay, end)

