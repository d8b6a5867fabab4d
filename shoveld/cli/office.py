"""``shoveld office --web``: every shovel on the site's Zenoh network on one page."""

from __future__ import annotations

import argparse

from shoveld.cli.cab import add_tls_arg, run_web
from shoveld.cli.options import KEY_PREFIX, SECONDS, SHOVEL_OR_ALL
from shoveld.endpoints import endpoint_arg


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "office", help="mine office page: every shovel, its truck, shift totals and health",
        description="Serve the mine office's page: one card per shovel seen on Zenoh (through "
                    "the site's routers) with its state, live payload, current truck, passes "
                    "and tonnes this shift and its health; a shovel that goes silent is marked "
                    "within seconds.")
    p.add_argument("--web", action="store_true", default=True,
                   help="serve the page (the only form; kept for symmetry with 'cab --web')")
    p.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                   type=endpoint_arg,
                   help="Zenoh endpoint to connect to (repeatable; default tcp/127.0.0.1:7447)")
    p.add_argument("--mode", choices=("client", "peer"), default="client")
    p.add_argument("--shovel", type=SHOVEL_OR_ALL, default="*",
                   help="shovel id to show (default: all)")
    p.add_argument("--prefix", type=KEY_PREFIX, default="shovel",
                   help="key prefix (zenoh.prefix)")
    p.add_argument("--listen", default="127.0.0.1:8081", metavar="HOST:PORT",
                   help="address of the page (default 127.0.0.1:8081)")
    p.add_argument("--duration", type=SECONDS, default=None, help="exit after this many seconds")
    add_tls_arg(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    return run_web(args, "office")
