"""Pseudo-terminal pairs for emulators and replay: a real tty a driver opens by path.

The far side (emulator or replay feeder) keeps the master fd *and* one slave fd
open: the slave fd keeps the pair alive while the driver closes and reopens the
port (otherwise reads on the master fail with EIO), lets the far side see how
full the driver's input queue is (``FIONREAD``), and exposes the termios speed the
driver set, so an emulator can behave like a device at a different baud rate.
"""

from __future__ import annotations

import errno
import fcntl
import os
import select
import struct
import termios
import tty
from dataclasses import dataclass, field

#: termios speed constants by baud rate (only the rates pyserial sets natively).
_SPEEDS: dict[int, int] = {
    b: getattr(termios, f"B{b}") for b in (
        1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)
    if hasattr(termios, f"B{b}")
}


@dataclass
class PtyLink:
    """The far end of a pseudo-terminal whose slave path a driver opens."""

    master_fd: int
    slave_fd: int
    slave_path: str
    closed: bool = field(default=False)

    def write(self, data: bytes, timeout_s: float = 1.0) -> int:
        """Write all of ``data`` to the driver side; give up after ``timeout_s``.

        Returns the number of bytes written (less than ``len(data)`` only if the
        driver stopped reading and the queue stayed full for the whole timeout).
        """
        view = memoryview(data)
        done = 0
        while done < len(view):
            _, w, _ = select.select([], [self.master_fd], [], timeout_s)
            if not w:
                break
            try:
                done += os.write(self.master_fd, view[done:])
            except BlockingIOError:
                continue
        return done

    def read(self, timeout_s: float) -> bytes:
        """Bytes the driver wrote, waiting at most ``timeout_s``; b"" if none."""
        r, _, _ = select.select([self.master_fd], [], [], timeout_s)
        if not r:
            return b""
        try:
            return os.read(self.master_fd, 4096)
        except OSError as e:
            if e.errno in (errno.EIO, errno.EAGAIN):
                return b""
            raise

    def pending_to_driver(self) -> int:
        """Bytes written to the driver side that it has not read yet."""
        buf = fcntl.ioctl(self.slave_fd, termios.FIONREAD, b"\0\0\0\0")
        return int(struct.unpack("i", buf)[0])

    def driver_baudrate(self) -> int | None:
        """The baud rate the driver configured on its side (None if non-standard)."""
        attrs = termios.tcgetattr(self.slave_fd)
        speed = attrs[5]  # ospeed
        for baud, const in _SPEEDS.items():
            if const == speed:
                return baud
        return None

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for fd in (self.master_fd, self.slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass


def open_pty_link() -> PtyLink:
    """Create a raw pseudo-terminal pair; the driver opens ``slave_path``.

    The slave is put in raw mode at once so that bytes written before the driver
    opens it are not echoed or CR/LF-translated by the line discipline.
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    attrs = termios.tcgetattr(slave)
    attrs[3] &= ~termios.ECHO
    termios.tcsetattr(slave, termios.TCSANOW, attrs)
    os.set_blocking(master, False)
    return PtyLink(master, slave, os.ttyname(slave))
