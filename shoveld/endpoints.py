"""Zenoh endpoints as the commands and the configuration take them (a light module: the
command line's argument types use it before anything heavy is imported)."""

from __future__ import annotations

import argparse
import re

IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
"""Zenoh's link protocols whose address is HOST:PORT."""


def endpoint_error(ep: str) -> str | None:
    """Why ``ep`` is not a Zenoh endpoint (``tcp/10.0.0.5:7447``, ``tls/[::1]:7447``,
    ``unixsock-stream//run/x.sock``), or None. Zenoh itself would ignore a malformed
    listen endpoint or fail with a message from its Rust sources."""
    example = "e.g. 'tcp/10.0.0.5:7447'"
    m = re.fullmatch(r"([a-z0-9-]+)/([^#?]+)(?:[#?].*)?", ep)
    if not m:
        return f"endpoint {ep!r} is not PROTO/ADDRESS ({example})"
    proto, addr = m.groups()
    if proto == "unixsock-stream":
        return None
    if proto not in IP_PROTOCOLS:
        return (f"endpoint {ep!r}: unknown protocol {proto!r} (expected one of "
                f"{', '.join(IP_PROTOCOLS)}, unixsock-stream)")
    host, sep, port = addr.rpartition(":")
    if not sep or not host or host in ("[", "[]"):
        return f"endpoint {ep!r}: the address must be HOST:PORT ({example})"
    if not port.isdigit() or not 0 <= int(port) < 65536:
        return f"endpoint {ep!r}: port {port!r} is not a number from 0 to 65535"
    if host.startswith("[") != host.endswith("]"):
        return f"endpoint {ep!r}: an IPv6 host goes in brackets, e.g. 'tcp/[::1]:7447'"
    return None


def endpoint_arg(text: str) -> str:
    """An argparse type: the endpoint, or a one-line error naming what was expected."""
    why = endpoint_error(text)
    if why:
        raise argparse.ArgumentTypeError(why)
    return text
