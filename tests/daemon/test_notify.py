"""sd_notify over $NOTIFY_SOCKET with the standard library, and journal log levels."""

from __future__ import annotations

import logging
import os
import socket
from pathlib import Path

from shoveld.daemon.logs import JournalFormatter
from shoveld.daemon.notify import Notifier


def listen(path: str) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    s.settimeout(1.0)
    return s


def test_ready_status_watchdog(tmp_path: Path) -> None:
    path = str(tmp_path / "notify")
    srv = listen(path)
    n = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000",
                  "WATCHDOG_PID": str(os.getpid())})
    assert n.enabled and n.watchdog_s == 2.0
    assert n.ready("running")
    assert srv.recv(100) == b"READY=1\nSTATUS=running"
    assert n.watchdog(now=100.0)
    assert srv.recv(100) == b"WATCHDOG=1"
    assert not n.watchdog(now=100.5)  # at most every half interval
    assert n.watchdog(now=101.0)
    assert srv.recv(100) == b"WATCHDOG=1"
    assert n.stopping()
    assert srv.recv(100) == b"STOPPING=1"
    n.close()
    srv.close()


def test_abstract_socket_and_foreign_watchdog_pid() -> None:
    name = f"shoveld-test-{os.getpid()}"
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    srv.bind("\0" + name)
    srv.settimeout(1.0)
    n = Notifier({"NOTIFY_SOCKET": "@" + name, "WATCHDOG_USEC": "1000000",
                  "WATCHDOG_PID": "1"})
    assert n.watchdog_s is None  # the watchdog is meant for another process
    assert n.status("x")
    assert srv.recv(100) == b"STATUS=x"
    srv.close()


def test_outside_systemd_everything_is_a_no_op() -> None:
    n = Notifier({})
    assert not n.enabled
    assert not n.ready() and not n.watchdog() and not n.stopping()


def test_journal_prefixes_levels() -> None:
    f = JournalFormatter("%(levelname)s %(name)s: %(message)s")
    rec = logging.LogRecord("shoveld", logging.WARNING, __file__, 1, "a\nb", None, None)
    assert f.format(rec) == "<4>WARNING shoveld: a\n<4>b"
    rec = logging.LogRecord("shoveld", logging.ERROR, __file__, 1, "x", None, None)
    assert f.format(rec).startswith("<3>")
