"""Channel map of a Modbus analog-input module: register words <-> engineering units.

Each channel is one 16-bit register carrying an ADC count. The count maps
linearly onto the module's input voltage range, and the voltage onto the
quantity the transducer measures::

    volts = volts_min + (raw - raw_min) * (volts_max - volts_min) / (raw_max - raw_min)
    value = volts * scale + offset

For a +-10 V module reporting -32768..32767 and a 4000 A Hall transducer giving
+-10 V, ``scale`` = 400 A/V. Modules differ in their raw range (signed
-32768..32767, offset-binary 0..65535, 0..4095, ...), so the raw range is
configuration, not code. ``raw_min < 0`` means the register word is read as a
two's-complement signed value. The inverse (:meth:`Channel.to_raw`) is what an
emulator puts in its registers, so driver and emulator share one set of numbers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.base import check_keys

#: Signals-table columns an ADC channel may feed.
ADC_COLUMNS: tuple[str, ...] = (
    "hoist1_a", "hoist2_a", "hoist_field_a", "crowd_a", "crowd_field_a", "swing_a",
    "swing_field_a", "boom_deg", "roll_deg", "pitch_deg",
)
_CHANNEL_KEYS = ("name", "register", "raw_min", "raw_max", "volts_min", "volts_max", "scale",
                 "offset")
MAX_BLOCK = 125
"""Registers per read request (Modbus limit for function codes 3 and 4)."""


@dataclass(frozen=True)
class Channel:
    """One analog input: which register, and how its count becomes a value."""

    name: str
    register: int
    raw_min: int = -32768
    raw_max: int = 32767
    volts_min: float = -10.0
    volts_max: float = 10.0
    scale: float = 1.0
    """Engineering units per volt (400 A/V for a 4000 A / 10 V transducer)."""
    offset: float = 0.0
    """Added after scaling (units)."""

    @property
    def signed(self) -> bool:
        return self.raw_min < 0

    def word_to_raw(self, word: int) -> int:
        """Register word (0..65535) -> ADC count in this channel's raw range."""
        if self.signed and word >= 0x8000:
            return word - 0x10000
        return word

    def raw_to_word(self, raw: int) -> int:
        return raw & 0xFFFF

    def from_raw(self, raw: int) -> float:
        """ADC count -> engineering value."""
        v = self.volts_min + (raw - self.raw_min) * (self.volts_max - self.volts_min) / (
            self.raw_max - self.raw_min)
        return v * self.scale + self.offset

    def word_decoder(self) -> Callable[[int], float]:
        """:meth:`from_word` as one closure over this channel's constants (the driver's
        per-poll path); the same arithmetic, so the same values to the last bit."""
        signed = self.signed
        vmin, rmin = self.volts_min, self.raw_min
        vspan, rspan = self.volts_max - self.volts_min, self.raw_max - self.raw_min
        scale, offset = self.scale, self.offset

        def decode(word: int) -> float:
            raw = word - 0x10000 if signed and word >= 0x8000 else word
            return (vmin + (raw - rmin) * vspan / rspan) * scale + offset
        return decode

    def decode_words(self, words: np.ndarray) -> np.ndarray:
        """:meth:`word_decoder` on an array of words, for replays that decode many polls
        at once: the same operations in the same order on the same types (integers
        below 2**53 convert exactly), so the same values to the last bit."""
        vmin, rmin = self.volts_min, self.raw_min
        vspan, rspan = self.volts_max - self.volts_min, self.raw_max - self.raw_min
        w = np.asarray(words, dtype=np.int64)
        raw = np.where(w >= 0x8000, w - 0x10000, w) if self.signed else w
        out = (vmin + (raw - rmin) * vspan / rspan) * self.scale + self.offset
        return np.asarray(out, dtype=float)

    def from_word(self, word: int) -> float:
        return self.from_raw(self.word_to_raw(word))

    def to_raw(self, value: float) -> int:
        """Engineering value -> ADC count (rounded, clamped to the raw range)."""
        volts = (value - self.offset) / self.scale
        raw = self.raw_min + (volts - self.volts_min) * (self.raw_max - self.raw_min) / (
            self.volts_max - self.volts_min)
        return int(min(max(round(raw), self.raw_min), self.raw_max))

    def to_word(self, value: float) -> int:
        return self.raw_to_word(self.to_raw(value))

    def saturated(self, raw: int) -> bool:
        """At either end of the range: the true value may lie beyond it."""
        return raw <= self.raw_min or raw >= self.raw_max

    @property
    def resolution(self) -> float:
        """Engineering units per count."""
        return abs((self.volts_max - self.volts_min) * self.scale / (self.raw_max - self.raw_min))


def _num(prefix: str, d: Mapping[str, Any], key: str, default: float | None, integer: bool
         ) -> Any:
    if key not in d:
        if default is None:
            raise ValueError(f"{prefix}.{key} is required")
        return default
    v = d[key]
    ok = isinstance(v, int) if integer else isinstance(v, int | float)
    if isinstance(v, bool) or not ok or (not integer and not math.isfinite(v)):
        kind = "an integer" if integer else "a finite number"
        raise ValueError(f"{prefix}.{key} must be {kind}, got {v!r}")
    return v if integer else float(v)


@dataclass(frozen=True)
class ChannelMap:
    """The channels of one module, addressable by name; builds the read blocks."""

    channels: tuple[Channel, ...]

    @classmethod
    def from_config(cls, items: Sequence[Mapping[str, Any]], prefix: str = "channels"
                    ) -> ChannelMap:
        """Build from a list of tables; ``ValueError`` names the bad entry and key."""
        if isinstance(items, Mapping) or not isinstance(items, Sequence) or not items:
            raise ValueError(f"{prefix} must be a non-empty list of channel tables")
        out: list[Channel] = []
        for i, d in enumerate(items):
            p = f"{prefix}[{i}]"
            if not isinstance(d, Mapping):
                raise ValueError(f"{p} must be a table")
            check_keys(p, d, _CHANNEL_KEYS)
            name = d.get("name")
            if not isinstance(name, str) or name not in ADC_COLUMNS:
                raise ValueError(f"{p}.name must be one of {list(ADC_COLUMNS)}, got {name!r}")
            p = f"{prefix}[{i}] ({name})"
            ch = Channel(
                name=name,
                register=_num(p, d, "register", None, True),
                raw_min=_num(p, d, "raw_min", -32768, True),
                raw_max=_num(p, d, "raw_max", 32767, True),
                volts_min=_num(p, d, "volts_min", -10.0, False),
                volts_max=_num(p, d, "volts_max", 10.0, False),
                scale=_num(p, d, "scale", 1.0, False),
                offset=_num(p, d, "offset", 0.0, False),
            )
            if not 0 <= ch.register <= 65535:
                raise ValueError(f"{p}.register must be in 0..65535, got {ch.register}")
            if not (-32768 <= ch.raw_min < ch.raw_max <= 65535) or (
                    ch.raw_min < 0 and ch.raw_max > 32767):
                raise ValueError(f"{p}.raw_min/raw_max must be a range inside one 16-bit word "
                                 f"(-32768..32767 or 0..65535), got {ch.raw_min}..{ch.raw_max}")
            if not ch.volts_min < ch.volts_max:
                raise ValueError(f"{p}.volts_min must be below volts_max")
            if ch.scale == 0:
                raise ValueError(f"{p}.scale must not be zero")
            out.append(ch)
        names = [c.name for c in out]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"{prefix}: channel name(s) {sorted(dup)} used twice")
        regs = [c.register for c in out]
        dupr = {r for r in regs if regs.count(r) > 1}
        if dupr:
            raise ValueError(f"{prefix}: register(s) {sorted(dupr)} used twice")
        return cls(tuple(out))

    def to_config(self) -> list[dict[str, Any]]:
        return [{k: getattr(c, k) for k in _CHANNEL_KEYS} for c in self.channels]

    def __iter__(self) -> Any:
        return iter(self.channels)

    def __len__(self) -> int:
        return len(self.channels)

    def __getitem__(self, name: str) -> Channel:
        for c in self.channels:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)

    def blocks(self, max_gap: int = 8) -> list[tuple[int, int, tuple[Channel, ...]]]:
        """Contiguous read blocks ``(address, count, channels)``.

        Neighbouring registers are merged into one request while the block stays
        within :data:`MAX_BLOCK` and the unused gap between channels is at most
        ``max_gap`` (one request per poll for a typical 8-channel module).
        """
        chans = sorted(self.channels, key=lambda c: c.register)
        out: list[tuple[int, int, tuple[Channel, ...]]] = []
        cur: list[Channel] = []
        for c in chans:
            if cur and (c.register - cur[-1].register - 1 > max_gap
                        or c.register - cur[0].register + 1 > MAX_BLOCK):
                out.append((cur[0].register, cur[-1].register - cur[0].register + 1, tuple(cur)))
                cur = []
            cur.append(c)
        if cur:
            out.append((cur[0].register, cur[-1].register - cur[0].register + 1, tuple(cur)))
        return out

    def decode(self, address: int, words: Sequence[int]) -> dict[str, float]:
        """Values of the channels inside the block starting at ``address``."""
        out: dict[str, float] = {}
        for c in self.channels:
            i = c.register - address
            if 0 <= i < len(words):
                out[c.name] = c.from_word(words[i])
        return out

    def encode(self, values: Mapping[str, float], address: int, count: int,
               fill: int = 0) -> list[int]:
        """Register words for a block from engineering values (the emulator's side).

        Channels without a value (missing or NaN) keep ``fill``.
        """
        words = [fill] * count
        for c in self.channels:
            i = c.register - address
            v = values.get(c.name)
            if 0 <= i < count and v is not None and not math.isnan(v):
                words[i] = c.to_word(v)
        return words
