"""The loopback ports the tests hand out (``hil_fixtures.net``)."""

from __future__ import annotations

import socket
from pathlib import Path

from hil_fixtures.net import DEMO_PORT, LOWEST, ephemeral_range, free_port


def test_ports_handed_out_are_free_and_never_ones_the_kernel_hands_out_itself() -> None:
    """A port from ``bind(("127.0.0.1", 0))`` may be handed again by the kernel (to the
    next such bind, or as an outgoing connection's local port) before the test binds it;
    one below the ephemeral range cannot be."""
    lo, _ = ephemeral_range()
    ports = [free_port() for _ in range(200)]
    assert all(LOWEST <= p < lo and p != DEMO_PORT for p in ports), ports
    assert len(set(ports)) > 150  # drawn, not one port again and again
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", ports[-1]))  # free when handed out


def test_the_ephemeral_range_is_read_or_linuxs_default(tmp_path: Path) -> None:
    (tmp_path / "range").write_text("40000\t50000\n")
    assert ephemeral_range(tmp_path / "range") == (40000, 50000)
    assert ephemeral_range(tmp_path / "missing") == (32768, 60999)
