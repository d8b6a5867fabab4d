"""Loopback ports for what the tests, drills and benchmarks start: emulators' servers,
site routers, daemons' Zenoh listeners."""

from __future__ import annotations

import random
import socket
from pathlib import Path

DEMO_PORT = 7447
"""``shoveld demo``'s (and Zenoh's) default port: never handed out, so that a demo left
running, or its connections in TIME_WAIT, do not meet a test."""

LOWEST = 10000
"""The lowest port handed out (well above the system's well-known and registered
services on a test machine)."""

_pick = random.SystemRandom()
"""Not the ``random`` module's generator: a test that seeds that one would hand two
pytest workers the same ports."""


def ephemeral_range(path: Path = Path("/proc/sys/net/ipv4/ip_local_port_range")
                    ) -> tuple[int, int]:
    """The ports the kernel hands out by itself (Linux's default 32768-60999)."""
    try:
        lo, hi = (int(x) for x in path.read_text().split())
    except (OSError, ValueError):
        return 32768, 60999
    return lo, hi


def free_port() -> int:
    """A free TCP port on 127.0.0.1, below the kernel's ephemeral range (never
    :data:`DEMO_PORT`). A port the kernel chose (``bind`` to port 0) is free only until
    the kernel hands it again, to the next ``bind`` to port 0 or as the local port of an
    outgoing connection, which can happen before the caller binds it: once in CI a
    daemon's Zenoh listener found its port taken for good after the virtual shovel's
    emulators and drivers had started. A port below that range is taken only by
    whoever asks for it by number."""
    lo, _ = ephemeral_range()
    if lo - LOWEST < 1000:  # a machine whose kernel hands out nearly every port
        return _kernel_port()
    for _ in range(1000):
        port = _pick.randrange(LOWEST, lo)
        if port == DEMO_PORT:
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:  # in use, or in TIME_WAIT: another
                continue
        return port
    raise RuntimeError(f"no free TCP port on 127.0.0.1 in {LOWEST}-{lo - 1}")


def _kernel_port() -> int:
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        if port != DEMO_PORT:
            return port
