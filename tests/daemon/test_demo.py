"""``shoveld demo``: calibrates, plays the virtual shovel, runs the daemon and the cab view."""

from __future__ import annotations

import subprocess
import sys

from .conftest import free_port


def test_demo_runs_out_of_the_box_and_ends_by_itself() -> None:
    """The default path (calibration included) on one pass at 5x, stdout not a TTY."""
    port = free_port()
    r = subprocess.run([sys.executable, "-m", "shoveld", "demo", "--passes", "1", "--speed", "5",
                        "--port", str(port)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "calibrating the simulated shovel" in out
    assert f"Zenoh on tcp/127.0.0.1:{port}" in out
    assert "demo pass 1 truck 1:" in out and " kg +- " in out
    assert "demo truck 1 CLOSED: 1 pass," in out
    assert "demo finished." in out and "truck 1: 1 pass," in out
    assert "cab page: http://127.0.0.1:" in out


def test_demo_refuses_a_busy_port() -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = subprocess.run([sys.executable, "-m", "shoveld", "demo", "--port", str(port)],
                           capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "in use" in r.stderr
