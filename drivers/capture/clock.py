"""ReplayClock: the capture-time clock that replay, emulators and drivers share.

Two modes, one interface (``now()``, also callable as ``clock()`` so it can be
passed wherever a driver takes ``clock=``):

* **paced** (``speed`` = 1.0 for recorded pace, 10.0 for ten times faster):
  capture time runs with the host monotonic clock times ``speed``.
* **stepped** (``speed=None``): time stands still until the consumer calls
  :meth:`ReplayClock.advance` / :meth:`ReplayClock.advance_to`. Replay feeders
  then release every recorded byte, frame and register value up to the new time,
  and ``advance`` returns once they report *settled* (data delivered and, where
  it can be seen, consumed by the driver), so a fixed-rate loop runs as fast as
  the machine allows and sees the same data at the same capture times as live.

A consumer's fixed-rate loop on a stepped clock::

    session = open_replay(capture_dir, speed=None)
    clock = session.clock
    drivers = [...constructed with clock=clock and the session's endpoints...]
    start driver threads
    tick = 0.01
    while not session.finished:
        t = clock.advance(tick)          # releases data up to t, waits until settled
        sample = assemble(latest readings, t)

Drivers that wait for time to pass (a poll interval) call
:meth:`ReplayClock.wait_until` when their clock has one, so they wake exactly
when the consumer advances instead of sleeping real seconds.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

SettleCheck = Callable[[float], bool]


class ReplayClock:
    """Capture-time clock, paced (``speed`` > 0) or stepped (``speed`` None)."""

    def __init__(self, start: float = 0.0, speed: float | None = 1.0,
                 settle_timeout_s: float = 0.5) -> None:
        if speed is not None and not speed > 0:
            raise ValueError(f"speed must be > 0 or None (stepped), got {speed!r}")
        self.speed = speed
        self.settle_timeout_s = settle_timeout_s
        self._t = float(start)
        self._m0 = time.monotonic()
        self.held = False
        """Paced mode: time stands still (at ``_t``) until :meth:`restart`."""
        self._cond = threading.Condition()
        self._checks: list[SettleCheck] = []
        self._listeners: list[Callable[[], None]] = []
        self._waiting: dict[int, float] = {}
        self._busy: dict[int, float] = {}
        self.busy_max_s = 0.2
        """A released waiter that has not waited again after this long is not waited for."""
        self.unsettled_steps = 0
        """Steps whose settle checks did not all pass within ``settle_timeout_s``."""

    @property
    def stepped(self) -> bool:
        return self.speed is None

    def now(self) -> float:
        """Current capture time in seconds."""
        if self.speed is None or self.held:
            return self._t
        return self._t + (time.monotonic() - self._m0) * self.speed

    __call__ = now

    def restart(self, start: float | None = None) -> None:
        """Paced mode: restart counting from ``start`` (default: the current time) now,
        and from a :meth:`hold`."""
        with self._cond:
            self._t = self.now() if start is None else float(start)
            self._m0 = time.monotonic()
            self.held = False
            self._cond.notify_all()
        self._notify()

    def hold(self) -> None:
        """Paced mode: stop time where it is until :meth:`restart` (a paced replay holds
        it while the service starts: a driver whose thread is not up yet would find the
        recording run ahead of it, its port's buffer full of stale frames)."""
        with self._cond:
            self._t = self.now()
            self.held = True

    def add_listener(self, fn: Callable[[], None]) -> None:
        """Call ``fn()`` whenever time is moved by :meth:`advance_to` or :meth:`restart`
        (feeders use it to wake up a ``select`` at once)."""
        self._listeners.append(fn)

    def _notify(self) -> None:
        for fn in self._listeners:
            fn()

    def add_settle_check(self, check: SettleCheck) -> None:
        """Register ``check(t) -> bool``; ``advance`` waits until all return True."""
        self._checks.append(check)

    def advance(self, dt: float) -> float:
        """Stepped mode: move time forward by ``dt`` and wait until settled."""
        return self.advance_to(self._t + dt)

    def advance_to(self, t: float) -> float:
        """Stepped mode: set time to ``t`` (never backwards), release data, wait to settle."""
        if self.speed is not None:
            raise RuntimeError("advance() needs a stepped clock (speed=None)")
        with self._cond:
            if t > self._t:
                self._t = float(t)
            t = self._t
            now_m = time.monotonic()
            for ident, target in list(self._waiting.items()):
                if target <= t:  # released: busy until it waits on the clock again
                    del self._waiting[ident]
                    self._busy[ident] = now_m
            self._cond.notify_all()
        self._notify()
        deadline = time.monotonic() + self.settle_timeout_s
        while True:
            if not self._waiters_busy() and all(c(t) for c in self._checks):
                break
            if time.monotonic() > deadline:
                self.unsettled_steps += 1
                break
            time.sleep(0.0002)
        return t

    def _waiters_busy(self) -> bool:
        """A thread released by the last advance has not come back to wait_until yet."""
        with self._cond:
            if not self._busy:
                return False
            old = time.monotonic() - self.busy_max_s
            for ident, since in list(self._busy.items()):
                if since < old:  # gone elsewhere (reconnecting, exited): stop waiting for it
                    del self._busy[ident]
            return bool(self._busy)

    def wait_until(self, t: float, timeout: float) -> bool:
        """Block (at most ``timeout`` real seconds) until ``now() >= t``; True if reached.

        On a stepped clock a thread released here counts as *busy* (its work for the
        step is running) until it calls ``wait_until`` again; ``advance`` waits for
        that, so a driver's poll triggered by a step completes within the step.
        """
        me = threading.get_ident()
        end = time.monotonic() + timeout
        with self._cond:
            self._busy.pop(me, None)
            while True:
                now = self.now()
                if now >= t:
                    self._waiting.pop(me, None)
                    if self.speed is None:
                        self._busy[me] = time.monotonic()
                    return True
                left = end - time.monotonic()
                if left <= 0:
                    self._waiting.pop(me, None)
                    return False
                if self.speed is None:
                    self._waiting[me] = t
                    self._cond.wait(left)
                else:
                    self._cond.wait(min(left, (t - now) / self.speed))

    def sleep(self, dt: float, timeout: float | None = None) -> bool:
        """Wait ``dt`` seconds of capture time (bounded by ``timeout`` real seconds)."""
        if timeout is None:
            timeout = dt / self.speed if self.speed else 3600.0
        return self.wait_until(self.now() + dt, timeout)


def clock_wait_until(clock: Callable[[], float], t: float, max_real_s: float) -> None:
    """Wait until ``clock() >= t``: via ``clock.wait_until`` if it has one, else sleeping.

    Drivers use this for poll intervals so the same code paces itself on the host
    clock live and on a :class:`ReplayClock` in replay.
    """
    wait = getattr(clock, "wait_until", None)
    if wait is not None:
        wait(t, max_real_s)
        return
    left = t - clock()
    if left > 0:
        time.sleep(min(left, max_real_s))
