"""Clocks for the fixed-rate loop: the host's monotonic clock live, simulated in replay.

The loop asks a clock for ``now()``, waits with ``sleep_until(t)``, and stamps
published messages with ``wall(t)``. Live, time is ``time.monotonic`` (the drivers
stamp readings with the same clock) and wall time is Unix time. In replay the
clock is simulated: with a stepped clock ``sleep_until`` *moves* time instead of
waiting, so a replay processes the same data at the same tick times on every run
and therefore gives the same passes, however loaded the machine is.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Protocol


class Clock(Protocol):
    """What the loop needs from time."""

    def now(self) -> float:
        """Current time in seconds (the time base of readings and ticks)."""

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> bool:
        """Return once ``now() >= t``; False if ``stop`` was set first."""

    def wall(self, t: float) -> float:
        """Unix time of clock time ``t`` (for published messages and the pass log)."""

    @property
    def simulated(self) -> bool:
        """True when time does not pass by itself (jitter means nothing then)."""


def boot_id() -> str | None:
    """This boot's id (Linux): monotonic times compare only within one boot."""
    try:
        with open("/proc/sys/kernel/random/boot_id") as f:
            return f.read().strip() or None
    except OSError:
        return None


class MonotonicClock:
    """The live clock: ``time.monotonic``, sleeping for real."""

    simulated = False

    def __init__(self) -> None:
        self._offset = time.time() - time.monotonic()

    def now(self) -> float:
        return time.monotonic()

    STOP_CHECK_S = 0.05
    """Longest single sleep: a stop request is noticed within this."""

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> bool:
        # time.sleep, not stop.wait(left): one clock_nanosleep instead of a condition
        # variable with a new lock per call (a third of the loop thread's CPU per tick
        # went into waiting); a stop is seen at the next deadline or within STOP_CHECK_S
        while True:
            if stop is not None and stop.is_set():
                return False
            left = t - time.monotonic()
            if left <= 0:
                return True
            time.sleep(left if left < self.STOP_CHECK_S else self.STOP_CHECK_S)

    def wall(self, t: float) -> float:
        return self._offset + t

    def boot_stamp(self, t: float) -> str | None:
        """``t`` as "<boot id> <seconds>": an NTP step cannot move it, so a restart within
        the same boot measures the time since the last dump exactly (wall time after)."""
        b = boot_id()
        return None if b is None else f"{b} {t!r}"

    def since_boot_stamp(self, stamp: str) -> float | None:
        """Seconds from ``stamp`` to now, or None if it was taken in another boot."""
        b, _, t = stamp.partition(" ")
        try:
            return time.monotonic() - float(t) if b and b == boot_id() else None
        except ValueError:
            return None

    def __call__(self) -> float:
        return time.monotonic()


class SimClock:
    """A simulated clock that jumps to each deadline (tests feed readings directly)."""

    simulated = True

    def __init__(self, start: float = 0.0, wall_origin: float = 1.7e9) -> None:
        self._t = float(start)
        self.wall_origin = wall_origin

    def now(self) -> float:
        return self._t

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> bool:
        if stop is not None and stop.is_set():
            return False
        if t > self._t:
            self._t = float(t)
        return True

    def wall(self, t: float) -> float:
        return self.wall_origin + t

    def __call__(self) -> float:
        return self._t


class ReplayStepClock:
    """Replay as fast as possible on the drivers' stepped :class:`ReplayClock`.

    ``sleep_until(t)`` advances the replay clock to ``t``, which releases the
    recorded data up to ``t`` into the virtual hardware and returns when the
    drivers have consumed it; tick times are capture times, so runs are identical.
    """

    simulated = True

    def __init__(self, replay_clock: Any, wall_origin: float) -> None:
        if not replay_clock.stepped:
            raise ValueError("ReplayStepClock needs a stepped ReplayClock (speed=None)")
        self.rc = replay_clock
        self.wall_origin = wall_origin

    def now(self) -> float:
        return float(self.rc.now())

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> bool:
        if stop is not None and stop.is_set():
            return False
        if t > self.rc.now():
            self.rc.advance_to(t)
        return True

    def wall(self, t: float) -> float:
        return self.wall_origin + t


class ReplayPacedClock:
    """Replay at ``speed`` times the recorded pace on a paced :class:`ReplayClock`."""

    simulated = False

    def __init__(self, replay_clock: Any, wall_origin: float) -> None:
        if replay_clock.stepped:
            raise ValueError("ReplayPacedClock needs a paced ReplayClock")
        self.rc = replay_clock
        self.wall_origin = wall_origin
        self.speed = float(replay_clock.speed)

    def now(self) -> float:
        return float(self.rc.now())

    def sleep_until(self, t: float, stop: threading.Event | None = None) -> bool:
        while True:
            left = (t - self.rc.now()) / self.speed
            if left <= 0:
                return True
            if stop is not None:
                if stop.wait(left):
                    return False
            else:
                time.sleep(left)

    def wall(self, t: float) -> float:
        return self.wall_origin + t
