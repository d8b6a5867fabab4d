"""Virtual MTi-600 on a python-can bus (``interface="virtual"`` in tests).

Each output group (one sample) is sent as the configured CAN messages in ascending
id order - SampleTime, GroupCounter, StatusWord, EulerAngles or Quaternion,
RateOfTurn, Acceleration - encoded with :class:`drivers.xsens.can_driver.MtiCanCodec`
so the layout (ids, scalings, byte order) is the driver's, by construction. Values come
from ``angles_at(t) -> (roll, pitch, yaw)`` degrees like :class:`hil_fixtures.mti.MtiEmulator`.

Faults: :meth:`go_silent` / :meth:`come_back`, :meth:`drop_groups` (lose whole groups:
the group counter jumps), :meth:`drop_next` (lose one message kind of the next group),
:meth:`send_error`.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any

import can

from drivers.xsens.can_driver import DEFAULT_MESSAGES, MtiCanCodec, MtiCanLayout
from drivers.xsens.orientation import body_rates, euler_deg_to_quat, gravity_in_sensor
from hil_fixtures.mti import AnglesAt

_ORDER = ("error", "sample_time", "group_counter", "status_word", "quaternion", "euler_angles",
          "rate_of_turn", "acceleration")


class MtiCanEmulator:
    """Streams MTi CAN output groups at ``rate_hz`` on ``channel`` from a thread."""

    def __init__(self, angles_at: AnglesAt, channel: str, *, interface: str = "virtual",
                 rate_hz: int = 100, layout: MtiCanLayout | None = None,
                 messages: tuple[str, ...] = DEFAULT_MESSAGES,
                 clock: Callable[[], float] = time.monotonic, tick_s: float = 0.002,
                 status_word: int = 0x00000003,
                 bus_factory: Callable[..., can.BusABC] = can.Bus,
                 t0: float | None = None) -> None:
        self.angles_at = angles_at
        self.channel = channel
        self.interface = interface
        self.rate_hz = rate_hz
        self.codec = MtiCanCodec(layout)
        self.messages = tuple(sorted(messages, key=_ORDER.index))
        self.clock = clock
        self.tick_s = tick_s
        self.status_word = status_word
        self.bus_factory = bus_factory
        self.sent_groups = 0
        self._silent = False
        self._skip_groups = 0
        self._drop_kinds: set[str] = set()
        self._pending_error: int | None = None
        self._counter = 0
        # Sample k is taken at t0 + k / rate on the clock. A virtual shovel passes its
        # clock's origin so every emulator shares one time line with the table.
        self._t0 = clock() if t0 is None else t0
        self._next_k = 0
        self._bus: can.BusABC | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def start(self) -> MtiCanEmulator:
        self._bus = self.bus_factory(interface=self.interface, channel=self.channel)
        self._next_k = math.floor((self.clock() - self._t0) * self.rate_hz) + 1
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="mti-can-emulator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def __enter__(self) -> MtiCanEmulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def go_silent(self) -> None:
        with self._lock:
            self._silent = True

    def come_back(self) -> None:
        with self._lock:
            self._silent = False
            self._next_k = math.floor((self.clock() - self._t0) * self.rate_hz) + 1

    def drop_groups(self, n: int) -> None:
        """Do not send the next ``n`` groups (their counter values are consumed)."""
        with self._lock:
            self._skip_groups += n

    def drop_next(self, kind: str) -> None:
        """Leave message ``kind`` out of the next group."""
        with self._lock:
            self._drop_kinds.add(kind)

    def send_error(self, code: int = 0x01) -> None:
        with self._lock:
            self._pending_error = code

    def _run(self) -> None:
        while not self._stop.wait(self.tick_s):
            with self._lock:
                if self._silent:
                    continue
                due = math.floor((self.clock() - self._t0) * self.rate_hz)
                if due - self._next_k > self.rate_hz:
                    self._next_k = due
                while self._next_k <= due:
                    self._send_group(self._next_k)
                    self._next_k += 1

    def group(self, k: int) -> list[tuple[str, Any]]:
        """(kind, values) of group ``k``, in sending order."""
        st = round(k / self.rate_hz / self.codec.layout.sample_time_scale_s)
        t = st * self.codec.layout.sample_time_scale_s
        r, p, y = self.angles_at(t)
        h = 0.005
        a, b = self.angles_at(t - h), self.angles_at(t + h)
        rates = tuple(((bv - av + 180.0) % 360.0 - 180.0) / (2 * h)
                      for av, bv in zip(a, b, strict=True))
        out: list[tuple[str, Any]] = []
        for kind in self.messages:
            if kind == "sample_time":
                out.append((kind, float(st)))
            elif kind == "group_counter":
                out.append((kind, float(self._counter & 0xFFFF)))
            elif kind == "status_word":
                out.append((kind, float(self.status_word)))
            elif kind == "euler_angles":
                out.append((kind, (r, p, y)))
            elif kind == "quaternion":
                out.append((kind, euler_deg_to_quat(r, p, y)))
            elif kind == "rate_of_turn":
                out.append((kind, body_rates((r, p, y), rates)))  # type: ignore[arg-type]
            elif kind == "acceleration":
                out.append((kind, gravity_in_sensor(r, p)))
        return out

    def _send_group(self, k: int) -> None:
        assert self._bus is not None
        if self._pending_error is not None:
            self._bus.send(self.codec.encode("error", float(self._pending_error)))
            self._pending_error = None
        msgs = self.group(k)
        self._counter += 1
        if self._skip_groups:
            self._skip_groups -= 1
            return
        for kind, vals in msgs:
            if kind in self._drop_kinds:
                continue
            self._bus.send(self.codec.encode(kind, vals))
        self._drop_kinds.clear()
        self.sent_groups += 1
