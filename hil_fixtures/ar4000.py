"""AR4000 emulator on a real pseudo-terminal: the driver opens ``emulator.port``.

It obeys the ASCII commands the driver uses (``A`` output mode, ``S`` sample
interval in microseconds, ``F`` maximum range, ``P``/``M`` amplitude window),
streams calibrated distances at the commanded interval, sends zero when there is
no valid target, and can misbehave on demand: go silent (``silent = True``),
babble (``babble`` = fraction of lines replaced by garbage), measure something
other than its target (``stray`` = fraction of samples from a return 0.5-3 m off:
dust, a rope, the boom in the beam), or look like a
device at another baud rate (it compares the speed the driver set on the tty
with its own and, on a mismatch, ignores commands and sends only noise, as a UART
receiving at the wrong rate would). Its cable can be pulled and plugged back in
(:meth:`unplug`, :meth:`plug`): ``port`` is a link to the pty that vanishes with it.

The distance comes from a *source*: ``source(t) -> metres | None`` (None = no
target), optionally ``(metres | None, amplitude)``; :func:`source_from_table`
builds one from a signals table through ``Installation.laser_m``.
"""

from __future__ import annotations

import math
import os
import random
import shutil
import tempfile
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from drivers.capture.ptylink import open_pty_link
from shoveld.installation import Installation
from shoveld.signals import SignalsTable

DistanceSource = Callable[[float], Any]
"""``t -> metres | None | (metres | None, amplitude)``."""

_UNIT_M = {1: 0.0254, 4: 0.001}


def source_from_table(table: SignalsTable, installation: Installation | None = None,
                      t_offset: float | None = None) -> DistanceSource:
    """Laser distance along a signals table: ``laser_m(crowd_m)`` interpolated in time.

    ``t`` is seconds since the emulator clock's origin; it maps to table time
    ``t_offset + t`` (default: the table's first time). Past the end the last row
    holds; a blank crowd (NaN) means no target.
    """
    inst = installation or Installation()
    tt = np.asarray(table.time, dtype=float)
    crowd = np.asarray(table["crowd_m"], dtype=float)
    off = float(tt[0]) if t_offset is None else t_offset

    def source(t: float) -> float | None:
        c = float(np.interp(t + off, tt, crowd))
        if math.isnan(c):
            return None
        return inst.laser_m(c)

    return source


class Ar4000Emulator:
    """A pretend AR4000 behind a pty; start with :meth:`start` or ``with``."""

    def __init__(self, source: DistanceSource, *, baudrate: int = 9600,
                 clock: Callable[[], float] | None = None, sample_interval_us: int = 200_000,
                 output_mode: int = 1, terminators: bytes = b"\r\n", amplitude: int = 500,
                 seed: int = 1) -> None:
        self.source = source
        self.baudrate = baudrate
        self.link = open_pty_link()
        self._dir = tempfile.mkdtemp(prefix="ar4000-emu-")
        self.port = os.path.join(self._dir, "ttyLASER")
        """A link to the pty's slave side: the path the driver opens, stable across
        :meth:`unplug` and :meth:`plug` as a udev name is."""
        os.symlink(self.link.slave_path, self.port)
        self._plugged = True
        self._io = threading.Lock()
        self._origin = time.monotonic()
        self.clock: Callable[[], float] = clock or (lambda: time.monotonic() - self._origin)
        self.sample_interval_us = sample_interval_us
        self.output_mode = output_mode
        self.max_range: int = 650
        self.min_amplitude = 0
        self.max_amplitude = 1023
        self.amplitude = amplitude
        self.terminators = terminators
        self.silent = False
        """True: sends nothing and ignores commands (device off, cable cut)."""
        self.babble = 0.0
        """Fraction of output lines replaced by garbage."""
        self.stray = 0.0
        """Fraction of samples measured off something else in the beam, 0.5-3 m off."""
        self.commands: list[str] = []
        self.lines_sent = 0
        self.garbage_sent = 0
        self._rng = random.Random(seed)
        self._cmd_buf = bytearray()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- lifecycle -----------------------------------------------------------------------

    def start(self) -> Ar4000Emulator:
        self._thread = threading.Thread(target=self._run, name="ar4000-emulator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._plugged:
            self.link.close()
        shutil.rmtree(self._dir, ignore_errors=True)

    def unplug(self) -> None:
        """Pull the cable: the pty closes (the driver's reads fail) and the path vanishes."""
        with self._io:
            if self._plugged:
                self._plugged = False
                self.link.close()
                os.unlink(self.port)

    def plug(self) -> None:
        """Plug it back in: a new pty behind the same path; the device streams at the
        interval it was set to (an AR4000 keeps its settings through a power cut)."""
        with self._io:
            if not self._plugged:
                self.link = open_pty_link()
                tmp = self.port + ".new"
                os.symlink(self.link.slave_path, tmp)
                os.replace(tmp, self.port)
                self._plugged = True

    def __enter__(self) -> Ar4000Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- behaviour -----------------------------------------------------------------------

    def baud_matches(self) -> bool:
        rate = self.link.driver_baudrate()
        return rate is None or rate == self.baudrate

    def _command(self, text: str) -> None:
        self.commands.append(text)
        if not text:
            return
        letter, arg = text[0], text[1:].strip()
        num = int(arg) if arg.isdigit() else None
        if letter == "S" and num is not None and 20 <= num <= 9_999_999:
            self.sample_interval_us = num
        elif letter == "A" and num in (1, 4):
            self.output_mode = num
        elif letter == "F" and num is not None and num <= 99999:
            self.max_range = num
        elif letter == "P" and num is not None and num <= 1023:
            self.min_amplitude = num
        elif letter == "M" and num is not None and num <= 1023:
            self.max_amplitude = num

    def _take_commands(self, data: bytes) -> None:
        self._cmd_buf += data
        while True:
            idx = [i for i in (self._cmd_buf.find(bytes([c])) for c in self.terminators)
                   if i >= 0]
            if not idx:
                break
            i = min(idx)
            text = bytes(self._cmd_buf[:i]).decode("ascii", "replace").strip()
            del self._cmd_buf[:i + 1]
            if text:
                self._command(text)
        if len(self._cmd_buf) > 64:
            self._cmd_buf.clear()

    def format_sample(self, t: float) -> bytes:
        """The line the sensor sends for time ``t`` (CR LF included)."""
        v = self.source(t)
        amp = self.amplitude
        if isinstance(v, tuple):
            v, amp = v
        if v is not None and self.stray and self._rng.random() < self.stray:
            v = max(0.1, v + self._rng.choice((-1, 1)) * self._rng.uniform(0.5, 3.0))
        unit = _UNIT_M.get(self.output_mode, 0.0254)
        valid = (v is not None and math.isfinite(v) and v > 0
                 and self.min_amplitude <= amp <= self.max_amplitude)
        if self.output_mode == 4:
            text = f"{round(v / unit)}" if valid else "0"
        else:
            text = f"{v / unit:.2f}" if valid else "0.00"
        return text.encode("ascii") + b"\r\n"

    def _garbage(self) -> bytes:
        n = self._rng.randint(3, 12)
        body = bytes(self._rng.choice(b"#@!?xZ\x00\x7f\x8a\xfe3.") for _ in range(n))
        return b"#" + body + b"\r\n"  # '#' guarantees it can never parse as a distance

    def _run(self) -> None:
        next_t = self.clock()
        while not self._stop.is_set():
            with self._io:
                plugged = self._plugged
                if plugged:
                    next_t = self._step(next_t)
            if not plugged:
                time.sleep(0.005)
                next_t = self.clock()

    def _step(self, next_t: float) -> float:
        """One wait for commands and, when due, one line out; the next line's time."""
        interval = self.sample_interval_us * 1e-6
        now = self.clock()
        wait = max(0.0, min(next_t - now, 0.005))
        data = self.link.read(wait)
        if data and not self.silent and self.baud_matches():
            self._take_commands(data)
        now = self.clock()
        if now < next_t:
            return next_t
        next_t += interval
        if next_t < now - 10 * interval:  # the clock jumped; do not burst to catch up
            next_t = now + interval
        if self.silent:
            return next_t
        if not self.baud_matches():
            noise = bytes(self._rng.randrange(256) for _ in range(8)).replace(b"\n", b"\x80")
            self.link.write(noise, timeout_s=0.05)
            self.garbage_sent += 1
        elif self.babble and self._rng.random() < self.babble:
            self.link.write(self._garbage(), timeout_s=0.05)
            self.garbage_sent += 1
        else:
            self.link.write(self.format_sample(now), timeout_s=0.05)
            self.lines_sent += 1
        return next_t
