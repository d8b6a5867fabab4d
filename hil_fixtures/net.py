"""Loopback ports for what the tests, drills and benchmarks start: emulators' servers,
site routers, daemons' Zenoh listeners."""

from __future__ import annotations

import socket

DEMO_PORT = 7447
"""``shoveld demo``'s (and Zenoh's) default port: never handed out, so that a demo left
running, or its connections in TIME_WAIT, do not meet a test."""


def free_port() -> int:
    """A free TCP port on 127.0.0.1, the OS's choice (never :data:`DEMO_PORT`)."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        if port != DEMO_PORT:
            return port
