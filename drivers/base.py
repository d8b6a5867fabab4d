"""The one driver abstraction (the python-can ``BusABC`` of shoveld).

A driver owns one device: it opens its transport, configures the device,
parses what arrives, and emits timestamped :class:`Reading` objects to a sink.
``run()`` is the thread body: it reconnects with exponential back-off and keeps
:class:`DriverHealth` current, so a device that is unplugged and plugged back is
recovered and reported rather than fatal.
"""

from __future__ import annotations

import copy
import logging
import math
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger(__name__)


def check_keys(where: str, table: Mapping[str, Any], known: Iterable[str],
               required: Mapping[str, str] | None = None) -> None:
    """Refuse a config table with an unknown or a missing key, naming the key: a typo
    must never fall back silently to a default. ``required`` maps each required key to
    what it should hold, for the message."""
    allowed = sorted(set(known))
    for k in table:
        if k not in allowed:
            raise ValueError(f"{where}: unknown key {k!r}; known keys: {allowed}")
    for k, what in (required or {}).items():
        if k not in table:
            raise ValueError(f"{where}: key {k!r} is required ({what})")


TARGETS_TAKEN = "targets_taken"
"""A quantity in a range finder's distance readings once it has taken something else in
its beam as its target: how many times it has. A count, not an event, so that a reading
the loop misses between two ticks cannot hide the change: the loop marks the tick where
the count grows (``shoveld.sample.CROWD_TARGET_CHANGED``)."""


@dataclass(slots=True)
class Reading:
    """Decoded values from one device message, stamped with the host receive time.

    ``values`` maps quantity names (e.g. ``pitch_deg``, ``distance_m``,
    ``hoist1_a``) to floats; ``invalid`` names quantities the device reported as
    not valid in this message (a laser with no target, a Modbus channel that
    timed out), which must never be turned into numbers downstream.
    """

    device: str
    t_host: float
    values: dict[str, float]
    invalid: frozenset[str] = frozenset()
    t_device: float | None = None


@dataclass
class DriverHealth:
    """Counters and state published on the health topic."""

    connected: bool = False
    messages: int = 0
    bad_frames: int = 0
    rejected_bytes: int = 0
    timeouts: int = 0
    reconnects: int = 0
    last_reading_t: float | None = None
    last_error: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self, now: float | None = None) -> dict[str, Any]:
        d: dict[str, Any] = {
            "connected": self.connected, "messages": self.messages,
            "bad_frames": self.bad_frames, "rejected_bytes": self.rejected_bytes,
            "timeouts": self.timeouts, "reconnects": self.reconnects,
            "last_error": self.last_error,
        }
        if now is not None and self.last_reading_t is not None:
            d["age_s"] = now - self.last_reading_t
        d.update(self.extra)
        return d

    def snapshot(self) -> DriverHealth:
        """A copy that later changes to this one do not reach (``extra`` included)."""
        return DriverHealth(self.connected, self.messages, self.bad_frames,
                            self.rejected_bytes, self.timeouts, self.reconnects,
                            self.last_reading_t, self.last_error, plain_copy(self.extra))


_SCALARS = (str, int, float, bool, type(None))


def plain_copy(x: Any) -> Any:
    """A deep copy of health data (dicts, lists and scalars; anything else by
    ``copy.deepcopy``): replays copy health at every health tick, and deepcopy's
    generality costs about ten times as much."""
    t = type(x)
    if t is dict:
        return {k: plain_copy(v) for k, v in x.items()}
    if t is list:
        return [plain_copy(v) for v in x]
    if t in _SCALARS:
        return x
    return copy.deepcopy(x)


class DeviceError(RuntimeError):
    """A device fault worth a clear message (wrong baud rate, no answer, Error message)."""


def port_error_words(e: BaseException) -> str:
    """Why a serial port did not open, once: pyserial's text repeats the port twice
    ("could not open port X: [Errno 2] No such file or directory: 'X'") after the
    driver's own "cannot open ... port X"; a permission refused says what gives it."""
    import errno
    import os

    n = getattr(e, "errno", None)
    if n == errno.EACCES or n == errno.EPERM:
        return (f"{os.strerror(n)} (the daemon's user needs the group of the port, "
                "dialout, and the unit's DeviceAllow its kind of device)")
    if isinstance(n, int) and n > 0:
        return os.strerror(n)
    return str(e)


Sink = Callable[[Reading], None]

TickHint = Callable[[], "tuple[float, float] | None"]
"""The consumer's tick grid on the driver's clock: ``(a tick deadline, tick period)``, or
None while there is no grid. A driver that polls its device can then time each poll so
the answer lands just before a tick instead of waiting up to a period for one."""


class Driver(ABC):
    """Base class of every device driver."""

    name: str

    def __init__(self, name: str, clock: Callable[[], float] = time.monotonic,
                 backoff_s: tuple[float, float] = (0.2, 5.0)) -> None:
        self.name = name
        self.clock = clock
        self.health = DriverHealth()
        self.backoff_s = backoff_s
        self._lock = threading.Lock()
        self._measured = 0
        """Readings with a value in them (a Modbus poll nobody answered is a reading of
        none): the back-off starts again only after a link that gave one."""

    @abstractmethod
    def open(self) -> None:
        """Open the transport and configure the device; raise on failure."""

    @abstractmethod
    def read(self, sink: Sink) -> None:
        """Block briefly (well under a second), parse what arrived, emit readings."""

    @abstractmethod
    def close(self) -> None:
        """Release the transport; must be safe to call twice."""

    def align_to_ticks(self, hint: TickHint | None, slot: int = 0) -> bool:
        """Time polls by ``hint`` (None: the driver's own schedule again); True if this
        driver can. ``slot`` picks among the ticks a poll period apart, so that several
        polled devices need not all answer before the same tick. Streaming devices send
        on their own clock, so by default a driver cannot."""
        return False

    def emit(self, sink: Sink, reading: Reading) -> None:
        isfinite = math.isfinite
        for v in reading.values.values():
            if not isfinite(v):
                # A NaN or an infinity decoded from a frame (a float field's bit pattern, a
                # device's own "no value") is not a measurement: the quantity is invalid
                # in this reading, never a number the loop could use.
                bad = {k for k, x in reading.values.items() if not isfinite(x)}
                reading = Reading(reading.device, reading.t_host,
                                  {k: x for k, x in reading.values.items() if k not in bad},
                                  reading.invalid | bad, reading.t_device)
                self.health.bad_frames += 1
                break
        self.health.messages += 1
        self.health.last_reading_t = reading.t_host
        if reading.values:
            self._measured += 1
        sink(reading)

    def run(self, sink: Sink, stop: threading.Event) -> None:
        """Thread body: open, read until stopped, reconnect with back-off on faults."""
        delay = self.backoff_s[0]
        first = True
        while not stop.is_set():
            measured = self._measured
            try:
                self.open()
                self.health.connected = True
                if not first:
                    self.health.reconnects += 1
                    log.warning("%s: reconnected", self.name)
                first = False
                while not stop.is_set():
                    self.read(sink)
            except Exception as e:  # noqa: BLE001 - any device fault leads to reconnect
                if self._measured > measured:
                    # The back-off starts again after a link that gave measurements (a new
                    # fault), not after every open that succeeds: a device that takes the
                    # connection and never answers (a Modbus gateway whose serial side is
                    # dead) was retried every 0.2 s, two log lines each, for ever.
                    delay = self.backoff_s[0]
                self.health.connected = False
                self.health.last_error = f"{type(e).__name__}: {e}"
                log.error("%s: %s; retrying in %.1f s", self.name, self.health.last_error, delay)
                first = False
            finally:
                try:
                    self.close()
                except Exception:  # noqa: BLE001
                    pass
            if stop.wait(delay):
                break
            delay = min(delay * 2.0, self.backoff_s[1])
        self.health.connected = False
