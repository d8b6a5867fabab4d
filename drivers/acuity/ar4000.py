"""Acuity AccuRange AR4000 laser distance sensor over RS-232 (ASCII protocol).

The laser measures the saddle-block-to-handle distance that becomes crowd
extension (see :class:`shoveld.installation.Installation`). The driver configures
the sensor, reads its continuous ASCII stream and emits ``distance_m``.

Protocol facts, from the *AR4000 User's Manual* (Acuity/Schmitt, LLL004001 Rev 2.7,
sections 9.1 "Output Data Formats" and 13.1 "Command Quick Reference"):

* serial data: 8 data bits, no parity, 1 stop bit.
* ``S<Interval>`` sets the sample interval, 20 <= Interval <= 9999999; the
  factory default 5 samples/s is listed as ``S200000``, so the unit is the
  microsecond.
* ``A<Mode>`` enables serial output: 1 = calibrated distance in inches,
  2 = uncalibrated sensor data, 3 = flow control, 4 = calibrated distance in
  millimetres. Factory default: calibrated (inches) output on.
* ``F[<MaxRange>]`` sets the maximum range, 0..99999; factory default 650 inches.
* ``P[<Amplitude>]`` / ``M[<Amplitude>]`` set the minimum / maximum valid
  amplitude (signal strength); outside that window the calibrated distance output
  "will be zero". Factory defaults 0 and 1023; the manual says 0..999 may be
  entered.
* ASCII calibrated output, one sample per line: ``[DD]D.DD<CR><LF>`` (4 to 6
  characters before CR LF).
* A calibrated distance of zero therefore means *no valid target* (amplitude out
  of window, out of range); it is emitted as ``invalid={"distance_m"}``, never as
  a distance.

Not confirmed from the manual excerpts available, hence configurable:

* the command terminator (``terminator``, default CR): the quick reference counts
  command lengths without one, but optional numeric parameters need a delimiter;
* the millimetre output layout (the parser accepts digits with an optional
  decimal fraction in either unit);
* the unit of the ``F`` parameter when millimetre output is selected
  (``max_range_unit``, default inches, as the factory default is quoted);
* the factory baud rate (``baudrate``, default 9600);
* whether the sensor acknowledges commands. The driver does not rely on an
  acknowledgement: the device counts as answering when a well-formed distance line
  arrives within ``answer_timeout_s`` after configuration.
"""

from __future__ import annotations

import logging
import re
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any

from drivers.base import (
    TARGETS_TAKEN,
    DeviceError,
    Driver,
    Reading,
    Sink,
    check_keys,
    port_error_words,
)
from drivers.capture.clock import clock_wait_until
from drivers.capture.tap import ByteTap, SerialFactory, open_serial
from drivers.serialio import direct_reader
from shoveld.installation import CROWD_SPEED_MAX_MPS, LASER_STEP_NOISE_M

log = logging.getLogger(__name__)

DISTANCE = "distance_m"
_UNIT_TO_M = {"mm": 0.001, "in": 0.0254}
_OUTPUT_MODE = {"in": 1, "mm": 4}
# Optional sign (zero point / span can reverse the axis), 1-7 integer digits,
# optional fraction. Anything else on a line is garbage.
_LINE_RE = re.compile(rb"^ *(-?)(\d{1,7})(?:\.(\d{1,4}))? *$")

NO_TARGET = 0.0
REFERENCE_LINES = 5
"""Sample intervals for which the last distance used alone says where the next may be
(after them a distance must also follow the line before it); and for which something
else in the beam is remembered between two of its lines."""


def parse_line(line: bytes, unit_m: float) -> float | None:
    """Parse one output line (without CR LF) to metres; None if malformed.

    Returns ``0.0`` for the sensor's zero (no valid target); the caller decides.
    """
    m = _LINE_RE.match(line)
    if m is None:
        return None
    sign, whole, frac = m.groups()
    value = int(whole) + (int(frac) / 10 ** len(frac) if frac else 0.0)
    if value == 0:
        return NO_TARGET
    return (-value if sign else value) * unit_m


def follows(value: float, t: float, ref: tuple[float, float], cfg: Ar4000Config,
            slack: float = 0.0) -> bool:
    """Whether a distance at ``t`` is within what the handle moves from ``ref`` (value,
    time) in the time between them (at least one sample interval), plus the noise (and
    ``slack``)."""
    return abs(value - ref[0]) <= (cfg.max_speed_mps * max(t - ref[1], cfg.interval_s)
                                   + cfg.jump_noise_m + slack)


@dataclass(slots=True)
class OtherTarget:
    """Something else in the laser's beam: lines that follow each other, the first of
    them well out of the handle's reach."""

    since: float
    """When its first line came."""
    last: float
    """Its last distance (m) and that line's time."""
    last_t: float


class RecentShare:
    """Flags of the last ``size`` lines and how many are set, kept as each line comes
    (not summed per chunk): the malformed lines for ``babbling``, the jumps among the
    distances for ``jumping``."""

    def __init__(self, size: int) -> None:
        self._flags: deque[bool] = deque(maxlen=size)
        self.count = 0

    def __len__(self) -> int:
        return len(self._flags)

    def add(self, flag: bool) -> None:
        flags = self._flags
        if len(flags) == flags.maxlen and flags[0]:
            self.count -= 1  # the oldest set flag drops out
        flags.append(flag)
        self.count += flag

    def add_clear(self, n: int) -> None:
        """``n`` lines with the flag clear (at most a window's worth changes anything)."""
        for _ in range(min(n, self._flags.maxlen or n)):
            self.add(False)

    def over(self, ratio: float, least: int) -> bool:
        """At least ``least`` lines, and more than ``ratio`` of them set."""
        n = len(self._flags)
        return n >= least and self.count / n > ratio


class LineSplitter:
    """Cuts the byte stream into lines and counts what is not a line.

    Bytes are accumulated until LF; a line longer than ``max_line`` without LF is
    discarded (counted as garbage) so a babbling device cannot grow the buffer, and so is
    the rest of it up to the next LF: the tail of an overlong line ("...12345\r\n") is
    not a distance.
    """

    def __init__(self, max_line: int = 32) -> None:
        self.max_line = max_line
        self._buf = bytearray()
        self.overflow_bytes = 0
        self._skipping = False

    def feed(self, data: bytes) -> list[bytes]:
        self._buf += data
        out: list[bytes] = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                break
            line = bytes(self._buf[:i])
            del self._buf[:i + 1]
            if self._skipping:  # the end of an overlong line: garbage too
                self._skipping = False
                self.overflow_bytes += len(line) + 1
                out.append(b"\x00" + line)  # reported as malformed (never parses)
                continue
            if line.endswith(b"\r"):
                line = line[:-1]
            if len(line) > self.max_line:
                self.overflow_bytes += len(line) + 1
                out.append(b"\x00" + line)
                continue
            out.append(line)
        if len(self._buf) > self.max_line:
            self.overflow_bytes += len(self._buf)
            out.append(b"\x00" + bytes(self._buf))  # reported as one malformed line
            self._buf.clear()
            self._skipping = True
        return out

    def clear(self) -> None:
        self._buf.clear()
        self._skipping = False


@dataclass(frozen=True)
class Ar4000Config:
    """Configuration of one AR4000 (keys of the ``[devices.<name>]`` table)."""

    port: str
    """Serial device path or pyserial URL (``/dev/ttyS1``, ``/dev/serial/by-id/...``)."""
    baudrate: int = 9600
    sample_interval_us: int = 20000
    """``S`` command; 20000 us = 50 samples/s."""
    units: str = "mm"
    """Calibrated output unit: ``mm`` (``A4``) or ``in`` (``A1``)."""
    max_range_m: float | None = None
    """``F`` command; None leaves the sensor's setting alone."""
    max_range_unit: str = "in"
    min_amplitude: int | None = None
    """``P`` command; None leaves the sensor's setting alone."""
    max_amplitude: int | None = None
    """``M`` command; None leaves the sensor's setting alone."""
    configure: bool = True
    """Send the configuration commands on open (False: only listen)."""
    terminator: str = "\r"
    command_gap_s: float = 0.05
    answer_timeout_s: float = 2.0
    silent_timeout_s: float = 1.0
    """No well-formed line for this long (clock seconds) -> silent, reconnect."""
    read_timeout_s: float = 0.05
    max_line_bytes: int = 32
    babble_window: int = 50
    """Lines considered when judging whether the device babbles."""
    babble_ratio: float = 0.3
    """Fraction of malformed lines in the window above which ``babbling`` is reported."""
    max_plausible_m: float = 20.0
    """Distances outside [0, this] are reported invalid (AR4000 range is 16.5 m)."""
    max_speed_mps: float = CROWD_SPEED_MAX_MPS
    """The fastest the target on the handle moves along the beam. A distance further
    from the last one used than this speed covers (over the time between them, at least
    one sample interval) plus ``jump_noise_m`` is a jump, reported invalid: the protocol
    has no checksum, so a corrupted digit would otherwise be a distance."""
    jump_noise_m: float = LASER_STEP_NOISE_M
    """What two consecutive lines may differ by at rest."""
    other_target_s: float = 5.0
    """How long something else in the beam (lines that follow each other, the first of
    them well out of the handle's reach) stays refused before it is taken as the target.
    It cannot be the handle while the last distance used is right; only if that one was
    wrong (something in the beam at a connection, a crowd faster than
    ``max_speed_mps``) is it, and only time can tell. Refused, it costs the loop the
    crowd for as long (its ticks are not used: a pass has fewer samples); taken, it is a
    crowd metres off (a pass tonnes off: 2 s here let a 3 s block of dust move passes by
    1 t, median; 5 s, by 27 kg, ``bench/laser_strays.py --blocks``). So the longer of
    the two: about a pass's lift and swing."""

    @classmethod
    def from_config(cls, d: Mapping[str, Any]) -> Ar4000Config:
        """Build from a config table; ``ValueError`` names the offending key."""
        known = {f.name: f for f in fields(cls)}
        ignored = {"kind", "name"}
        check_keys("ar4000", d, [*known, *ignored], {"port": "serial device path"})
        kw: dict[str, Any] = {}
        for k, v in d.items():
            if k in ignored:
                continue
            kw[k] = _coerce(k, v, known[k].type)
        cfg = cls(**kw)
        cfg.validate()
        return cfg

    def validate(self) -> None:
        def bad(key: str, why: str) -> ValueError:
            return ValueError(f"ar4000: key {key!r} {why} (got {getattr(self, key)!r})")

        if not self.port:
            raise bad("port", "must be a non-empty device path")
        if self.baudrate not in (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200):
            raise bad("baudrate", "must be a standard rate 1200..115200")
        if not 20 <= self.sample_interval_us <= 9_999_999:
            raise bad("sample_interval_us", "must be in 20..9999999 (microseconds)")
        if self.units not in _UNIT_TO_M:
            raise bad("units", "must be 'mm' or 'in'")
        if self.max_range_unit not in _UNIT_TO_M:
            raise bad("max_range_unit", "must be 'mm' or 'in'")
        if self.max_range_m is not None and not (
                0 < self.max_range_m and self.max_range_m / _UNIT_TO_M[self.max_range_unit]
                <= 99999):
            raise bad("max_range_m", "must be > 0 and fit the F command (0..99999 units)")
        for key in ("min_amplitude", "max_amplitude"):
            v = getattr(self, key)
            if v is not None and not 0 <= v <= 1023:
                raise bad(key, "must be in 0..1023")
        if (self.min_amplitude is not None and self.max_amplitude is not None
                and self.min_amplitude >= self.max_amplitude):
            raise bad("min_amplitude", "must be below max_amplitude")
        if self.terminator not in ("", "\r", "\n", "\r\n"):
            raise bad("terminator", "must be one of '', CR, LF, CR LF")
        for key in ("answer_timeout_s", "silent_timeout_s", "read_timeout_s"):
            if not getattr(self, key) > 0:
                raise bad(key, "must be > 0 seconds")
        if self.command_gap_s < 0:
            raise bad("command_gap_s", "must be >= 0")
        if not 8 <= self.max_line_bytes <= 1024:
            raise bad("max_line_bytes", "must be in 8..1024")
        if self.babble_window < 1 or not 0 < self.babble_ratio <= 1:
            raise bad("babble_ratio", "must be in (0, 1] with babble_window >= 1")
        for key in ("max_plausible_m", "max_speed_mps", "other_target_s"):
            if not getattr(self, key) > 0:
                raise bad(key, "must be > 0")
        if not self.jump_noise_m >= 0:
            raise bad("jump_noise_m", "must be >= 0")

    @property
    def unit_m(self) -> float:
        return _UNIT_TO_M[self.units]

    @property
    def interval_s(self) -> float:
        return self.sample_interval_us * 1e-6

    @property
    def sample_reach_m(self) -> float:
        """How far the handle moves in one sample interval at most."""
        return self.max_speed_mps * self.interval_s

    def commands(self) -> list[bytes]:
        """The configuration commands, in the order they are sent."""
        term = self.terminator.encode()
        cmds = [f"A{_OUTPUT_MODE[self.units]}", f"S{self.sample_interval_us}"]
        if self.max_range_m is not None:
            cmds.append(f"F{round(self.max_range_m / _UNIT_TO_M[self.max_range_unit])}")
        if self.min_amplitude is not None:
            cmds.append(f"P{self.min_amplitude}")
        if self.max_amplitude is not None:
            cmds.append(f"M{self.max_amplitude}")
        return [c.encode("ascii") + term for c in cmds]


def _coerce(key: str, v: Any, typ: Any) -> Any:
    """Check a config value against the field's annotated type (given as a string)."""
    t = str(typ)
    if v is None and "None" in t:
        return None
    if t.startswith("int"):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"ar4000: key {key!r} must be an integer, got {v!r}")
        return v
    if t.startswith("float"):
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ValueError(f"ar4000: key {key!r} must be a number, got {v!r}")
        return float(v)
    if t.startswith("str"):
        if not isinstance(v, str):
            raise ValueError(f"ar4000: key {key!r} must be a string, got {v!r}")
        return v
    if t.startswith("bool"):
        if not isinstance(v, bool):
            raise ValueError(f"ar4000: key {key!r} must be true or false, got {v!r}")
        return v
    return v


class Ar4000Driver(Driver):
    """Reads calibrated distances from an AR4000 and emits ``distance_m`` readings.

    The protocol has no checksum; what stops a corrupted digit is the handle's speed. A
    distance is used only if it can follow from the last distance used, no further from
    it than the handle moves in the time between them (``max_speed_mps``, plus
    ``jump_noise_m``), no-target lines in between or not. Before the first distance
    there is none, and after :data:`REFERENCE_LINES` sample intervals with none used
    the one there is allows much: a distance must then also follow in the same way from
    the well-formed line just before it (so the first after a start or a long no-target
    stretch is reported invalid). Something else that stays in the beam (a line out of
    reach by more than two samples' reach, and the lines after it each within a
    sample's reach of the one before) stays a jump when the handle's reach grows to it,
    until it has held for ``other_target_s`` (then it is taken as the target, counted in
    ``extra["other_target"]``, and every later distance carries that count as
    :data:`TARGETS_TAKEN`). A reconnect keeps the last distance used: the handle moves
    no faster while the port is down.

    Health: ``bad_frames`` counts malformed lines, ``rejected_bytes`` their bytes,
    ``timeouts`` silent periods; ``extra`` carries ``no_target`` (zero readings),
    ``implausible``, ``jumps`` (distances that cannot follow from the last one used),
    ``other_target`` (something else in the beam taken as the target), ``silent``,
    ``babbling`` (malformed fraction of the recent lines above
    ``babble_ratio``) and ``jumping`` (the same for jumps among the recent distances).
    """

    def __init__(self, name: str, config: Ar4000Config,
                 clock: Callable[[], float] = time.monotonic,
                 backoff_s: tuple[float, float] = (0.2, 5.0),
                 serial_factory: SerialFactory | None = None) -> None:
        super().__init__(name, clock, backoff_s)
        self.config = config
        self.tap: ByteTap | None = None
        """Set by the recorder: every byte read/written is copied to it."""
        self._factory = serial_factory
        self._ser: Any = None
        self._direct: Callable[[float], bytes] | None = None
        self._splitter = LineSplitter(config.max_line_bytes)
        self._malformed = RecentShare(config.babble_window)
        """Of the recent lines, the malformed ones."""
        self._jumped = RecentShare(config.babble_window)
        """Of the recent distance lines, the jumps."""
        self._pending: list[Reading] = []
        self._last_good = 0.0
        self._garbage_since_good = 0
        self._prev: tuple[float, float] | None = None
        """The last well-formed line's value (metres, 0 for no target) and time."""
        self._used: tuple[float, float] | None = None
        """The last distance used and its time."""
        self._other: OtherTarget | None = None
        """Something else in the beam, refused since the last distance used."""
        self.health.extra.update({"no_target": 0, "implausible": 0, "jumps": 0,
                                  "other_target": 0,
                                  "silent": False, "babbling": False, "jumping": False})

    @classmethod
    def from_config(cls, name: str, d: Mapping[str, Any], **kw: Any) -> Ar4000Driver:
        return cls(name, Ar4000Config.from_config(d), **kw)

    # -- transport ---------------------------------------------------------------------

    def open(self) -> None:
        cfg = self.config
        self.close()
        extra = {"factory": self._factory} if self._factory is not None else {}
        try:
            self._ser = open_serial(cfg.port, cfg.baudrate, cfg.read_timeout_s, self.tap,
                                    **extra)
        except Exception as e:  # noqa: BLE001 - pyserial raises OSError/SerialException
            raise DeviceError(f"cannot open AR4000 port {cfg.port}: {port_error_words(e)}"
                              ) from e
        self._splitter.clear()
        self._pending.clear()
        # A new connection: the lines before it are not the line before the next one,
        # but the last distance used still bounds where the handle can be, so something
        # else in the beam beyond the handle's reach over the gap is refused and counted
        # like one that comes while connected (after the default 1 s of silence that
        # reach is 3 m: docs/drivers-ar4000.md, "A reconnect keeps the handle's reach").
        self._prev = self._other = None
        if cfg.configure:
            for cmd in cfg.commands():
                self._ser.write(cmd)
                if cfg.command_gap_s:  # on the driver's clock: a fast replay has no device
                    gap_end = self.clock() + cfg.command_gap_s  # to give time to
                    clock_wait_until(self.clock, gap_end, max_real_s=cfg.command_gap_s)
            # lines already queued may be in the old unit: start clean
            self._ser.reset_input_buffer()
        self._direct = direct_reader(self._ser)
        # The device answers when a well-formed line arrives; real time, because a
        # stepped replay clock may not move while we wait.
        deadline = time.monotonic() + cfg.answer_timeout_s
        while time.monotonic() < deadline:
            data = self._ser.read(max(1, self._ser.in_waiting))
            if data and self._parse(data, self._pending.append, self.clock()):
                self._last_good = self.clock()
                self.health.extra["silent"] = False
                return
        port, baud = cfg.port, cfg.baudrate
        self.close()
        raise DeviceError(f"no answer from AR4000 on {port} at {baud}: "
                          "wrong baud rate or device off?")

    def close(self) -> None:
        self._direct = None
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: BLE001
                pass

    # -- parsing -----------------------------------------------------------------------

    def _parse(self, data: bytes, out: Callable[[Reading], None], now: float) -> int:
        """Parse a chunk received at ``now``; hand readings to ``out``; count good lines.

        Every line completed by the chunk is stamped with the chunk's receive time
        (taken right after the read, so a busy parser thread does not delay it). The
        handle's rule (:meth:`_takes`) times each line by when the device sent it: a
        chunk of k lines took k samples to send, so the one n lines before its last was
        sent n sample intervals before the chunk came, and never before the line before
        it. A busy host reads a second of lines at once; timed by the chunk, the first of
        them looked a second after the line before it, and far from it was within the
        handle's reach (a stray taken, something else in the beam forgotten).
        """
        cfg = self.config
        good = 0
        lines = self._splitter.feed(data)
        last = len(lines) - 1
        for i, line in enumerate(lines):
            value = parse_line(line, cfg.unit_m)
            if value is None:
                if line.strip():
                    self.health.bad_frames += 1
                    self.health.rejected_bytes += len(line) + 1
                    self._garbage_since_good += len(line) + 1
                    self._malformed.add(True)
                continue
            good += 1
            self._malformed.add(False)
            self._garbage_since_good = 0
            prev = self._prev
            sent = now - (last - i) * cfg.interval_s  # now itself for the chunk's last
            if prev is not None and sent < prev[1]:
                sent = prev[1]
            self._prev = (value, sent)
            if value == NO_TARGET:
                self.health.extra["no_target"] += 1
                out(Reading(self.name, now, {}, frozenset({DISTANCE})))
            elif not 0.0 <= value <= cfg.max_plausible_m:
                self.health.extra["implausible"] += 1
                out(Reading(self.name, now, {}, frozenset({DISTANCE})))
            elif self._takes(value, sent, prev):
                self._used, self._other = (value, sent), None
                self._jumped.add(False)
                taken = self.health.extra["other_target"]
                out(Reading(self.name, now, {DISTANCE: value, TARGETS_TAKEN: float(taken)}
                            if taken else {DISTANCE: value}))
            else:
                out(Reading(self.name, now, {}, frozenset({DISTANCE})))
        self._update_babbling()
        return good

    def _takes(self, value: float, now: float, prev: tuple[float, float] | None) -> bool:
        """Whether a distance is the handle's (see the class's docstring). A refused one
        is counted as a jump, unless nothing could be measured against it (no distance
        used since a connection or for a while, and no distance on the line before)."""
        cfg = self.config
        used, other = self._used, self._other
        line = prev if prev is not None and prev[0] != NO_TARGET else None
        recent = cfg.interval_s * (REFERENCE_LINES + 0.5)
        reach = used is None or follows(value, now, used, cfg)
        if other is not None and not (now - other.last_t <= recent and abs(
                value - other.last) <= cfg.sample_reach_m + cfg.jump_noise_m):
            other = None  # gone, or not it (it moves no faster than the handle could)
        if other is not None:
            if now - other.since >= cfg.other_target_s:
                assert used is not None
                self.health.extra["other_target"] += 1
                log.warning("%s: AR4000 takes as its target what held %.1f s in the beam, "
                            "%+.3f m from the last distance used", self.name,
                            now - other.since, value - used[0])
                return True
            other.last, other.last_t = value, now
        elif reach:
            # with no recent distance used to say so, confirmed by the line before it
            if used is not None and now - used[1] <= recent:
                return True
            if line is None:
                return False
            if follows(value, now, line, cfg):
                return True
        elif used is not None and not follows(value, now, used, cfg,
                                              slack=2 * cfg.sample_reach_m):
            # out of reach by more than two samples' reach: further than the handle can
            # be even if the distance used was a corrupted line just inside the bound
            # (off by up to that, with the handle moving away): something else
            self._other = OtherTarget(now, value, now)
        self.health.extra["jumps"] += 1
        self._jumped.add(True)
        return False

    def _update_babbling(self) -> None:
        """``babbling`` (malformed lines) and ``jumping`` (distances the handle cannot
        reach: a dirty target, something in the beam), each when its share of the recent
        lines exceeds ``babble_ratio``."""
        cfg = self.config
        least = min(10, cfg.babble_window)
        n, bad = len(self._malformed), self._malformed.count
        babbling = self._malformed.over(cfg.babble_ratio, least)
        if babbling and not self.health.extra["babbling"]:
            log.warning("%s: AR4000 babbling: %d of the last %d lines malformed",
                        self.name, bad, n)
            self.health.last_error = f"babbling: {bad} of the last {n} lines malformed"
        self.health.extra["babbling"] = babbling
        n, jumps = len(self._jumped), self._jumped.count
        jumping = self._jumped.over(cfg.babble_ratio, least)
        if jumping and not self.health.extra["jumping"]:
            log.warning("%s: AR4000 jumping: %d of the last %d distances further than the "
                        "handle moves (dirty target, something in the beam?)", self.name,
                        jumps, n)
            self.health.last_error = (f"jumping: {jumps} of the last {n} distances further "
                                      "than the handle moves")
        self.health.extra["jumping"] = jumping

    def idle(self, now: float) -> bool:
        """True if :meth:`read` at ``now`` with nothing received would change nothing (no
        reading queued by ``open``, not silent for ``silent_timeout_s``: the same test as
        ``read``'s), so a replay that steps the driver itself can skip the call."""
        return not self._pending and not now - self._last_good > self.config.silent_timeout_s

    def read(self, sink: Sink) -> None:
        ser = self._ser
        if ser is None:
            raise DeviceError("AR4000 port not open")
        if self._pending:
            pending, self._pending = self._pending, []
            for r in pending:
                self.emit(sink, r)
        try:
            if self._direct is not None:  # a plain port: one select, one read
                data = self._direct(self.config.read_timeout_s)
            else:
                data = ser.read(max(1, ser.in_waiting))
                if len(data) == 1:  # woke on a line's first byte: the rest came with it
                    n = ser.in_waiting
                    if n:
                        data += ser.read(n)
        except Exception as e:  # noqa: BLE001 - unplugged USB adapter etc.
            raise DeviceError(f"AR4000 read failed on {self.config.port}: {e}") from e
        t_rx = self.clock()
        if data and self._parse(data, lambda r: self.emit(sink, r), t_rx):
            self._last_good = t_rx
            self.health.extra["silent"] = False
            return
        quiet = self.clock() - self._last_good
        if quiet > self.config.silent_timeout_s:
            self.health.timeouts += 1
            self.health.extra["silent"] = True
            if self._garbage_since_good:
                why = (f"no valid distance for {quiet:.1f} s, only "
                       f"{self._garbage_since_good} bytes of garbage (babbling)")
            else:
                why = f"no data for {quiet:.1f} s (silent)"
            raise DeviceError(f"AR4000 on {self.config.port}: {why}")
