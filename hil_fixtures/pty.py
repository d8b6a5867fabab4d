"""A pseudo-terminal pair for device emulators: real serial semantics without hardware.

The emulator owns the master side; the driver under test opens ``slave_path`` with
pyserial exactly as it would open ``/dev/ttyUSB0``. Two details make a pty usable for
binary protocols and reconnect tests, which is why this helper exists:

* the slave is put in raw mode at once, so bytes written before the driver opens
  the port are not echoed back to the emulator or CR/LF-translated;
* a slave descriptor is held open until :func:`close_pty_pair`, so the master does
  not see EIO/hang-up while the driver closes and reopens the port.

The master side sees the baud rate the driver configured:
``termios.tcgetattr(master_fd)[5]`` (output speed constant, e.g. ``termios.B115200``),
which lets an emulator imitate a device at a different baud rate.

Usage::

    with pty_pair() as (master_fd, slave_path):
        ser = serial.Serial(slave_path, 115200)
        os.write(master_fd, b"...")
"""

from __future__ import annotations

import os
import tty
from collections.abc import Iterator
from contextlib import contextmanager

_held_slaves: dict[int, int] = {}


def open_pty_pair() -> tuple[int, str]:
    """Open a raw pty pair; return ``(master_fd, slave_path)``; close with close_pty_pair."""
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    _held_slaves[master_fd] = slave_fd
    return master_fd, os.ttyname(slave_fd)


def close_pty_pair(master_fd: int) -> None:
    """Close the master and the held slave; an open driver then sees the device vanish."""
    slave_fd = _held_slaves.pop(master_fd, None)
    for fd in (master_fd, slave_fd):
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass


@contextmanager
def pty_pair() -> Iterator[tuple[int, str]]:
    """Context manager around :func:`open_pty_pair` / :func:`close_pty_pair`."""
    master_fd, slave_path = open_pty_pair()
    try:
        yield master_fd, slave_path
    finally:
        close_pty_pair(master_fd)
