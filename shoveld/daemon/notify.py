"""systemd's notify protocol with the standard library: READY, STATUS, WATCHDOG, STOPPING.

``Type=notify`` units learn that the service is up from a datagram ``READY=1`` on
``$NOTIFY_SOCKET``; with ``WatchdogSec=`` systemd restarts the service unless it
hears ``WATCHDOG=1`` often enough. Outside systemd (no ``$NOTIFY_SOCKET``) every
call is a no-op, so the same code runs in a terminal and in tests.
"""

from __future__ import annotations

import logging
import os
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import socket

log = logging.getLogger(__name__)


class Notifier:
    """Sends sd_notify datagrams; pings the watchdog at most every half interval."""

    def __init__(self, env: dict[str, str] | None = None) -> None:
        env = dict(os.environ) if env is None else env
        self.address = env.get("NOTIFY_SOCKET") or None
        self.watchdog_s: float | None = None
        usec = env.get("WATCHDOG_USEC")
        pid = env.get("WATCHDOG_PID")
        if usec and (not pid or pid == str(os.getpid())):
            try:
                self.watchdog_s = int(usec) / 1e6
            except ValueError:
                log.warning("WATCHDOG_USEC=%r is not a number; no watchdog pings", usec)
        self._sock: socket.socket | None = None
        self._last_ping = -1e18
        self.pings = 0
        self.sent: list[str] = []
        """The last few messages (for tests and the health topic)."""

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def _send(self, msg: str) -> bool:
        if self.address is None:
            return False
        addr = self.address
        if addr.startswith("@"):
            addr = "\0" + addr[1:]  # abstract namespace socket
        try:
            if self._sock is None:
                import socket  # here: outside systemd (replays, tests) never needed

                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
                self._sock.setblocking(False)
            self._sock.sendto(msg.encode(), addr)
        except OSError as e:
            log.warning("sd_notify %r: %s", msg.split("\n")[0], e)
            return False
        self.sent = (self.sent + [msg])[-20:]
        return True

    def ready(self, status: str = "") -> bool:
        return self._send("READY=1" + (f"\nSTATUS={status}" if status else ""))

    def status(self, text: str) -> bool:
        return self._send(f"STATUS={text}")

    def stopping(self) -> bool:
        return self._send("STOPPING=1")

    def watchdog_due(self, now: float | None = None) -> bool:
        """Whether :meth:`watchdog` would ping now (so the caller checks its health only
        then, not at every tick)."""
        if self.watchdog_s is None or self.address is None:
            return False
        now = time.monotonic() if now is None else now
        return now - self._last_ping >= self.watchdog_s / 2

    def watchdog(self, now: float | None = None) -> bool:
        """Ping if half the watchdog interval has passed since the last ping."""
        if self.watchdog_s is None or self.address is None:
            return False
        now = time.monotonic() if now is None else now
        if now - self._last_ping < self.watchdog_s / 2:
            return False
        self._last_ping = now
        self.pings += 1
        return self._send("WATCHDOG=1")

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
