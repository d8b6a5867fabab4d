"""``shoveld pki``: the site CA, a certificate per peer, and the router's configuration.

``init`` makes the CA, ``issue NAME --role ROLE`` a peer's certificate and key (a
shovel's NAME is its ``shovel.id``), ``list`` shows what was issued, and
``router-config`` writes a router's Zenoh configuration: mutual TLS, the access
control built from the issued certificates (``shoveld.security.acl``), its admin space
open to the probe's question and the lease by which its peers see it gone when it hangs.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from shoveld.cli import CliError
from shoveld.cli.options import KEY_PREFIX, number
from shoveld.words import n_of

LEASE_S = number(0.5, 600.0, unit="seconds",
                 hint="below half a second a busy network's pause drops the link")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "pki", help="site CA, peer certificates and the router's TLS + access control",
        description="Mutual TLS for the site's Zenoh network: a site CA, a certificate "
                    "per shovel, cab display, office subscriber, maintenance laptop and "
                    "router, and the routers' access-control configuration.")
    ps = p.add_subparsers(dest="pki_command", metavar="ACTION", required=True)
    i = ps.add_parser("init", help="make the site CA (ca.crt, ca.key)")
    i.add_argument("--dir", required=True, type=Path, help="the PKI folder (keep it offline)")
    i.add_argument("--site", default="shoveld site", help="organisation name in the CA")
    i.add_argument("--days", type=int, default=3650)
    i.set_defaults(func=run_init)
    s = ps.add_parser("issue", help="make a peer's certificate and key (NAME.crt, NAME.key)")
    s.add_argument("name", help="the peer's name (common name); a shovel's is its shovel.id")
    s.add_argument("--role", required=True,
                   choices=("shovel", "cab", "office", "maintenance", "router"))
    s.add_argument("--dir", required=True, type=Path)
    s.add_argument("--host", action="append", default=[], metavar="NAME_OR_IP",
                   help="an address others dial this peer at (repeatable; localhost, "
                        "127.0.0.1 and ::1 are always in)")
    s.add_argument("--days", type=int, default=825)
    s.set_defaults(func=run_issue)
    ls = ps.add_parser("list", help="the certificates issued in the folder")
    ls.add_argument("--dir", required=True, type=Path)
    ls.set_defaults(func=run_list)
    r = ps.add_parser("router-config",
                      help="a router's Zenoh config (JSON5): mutual TLS and access control")
    r.add_argument("name", help="the router's certificate name (issued with --role router)")
    r.add_argument("--dir", required=True, type=Path)
    r.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                   help="tls/ endpoint to listen on (repeatable; default tls/0.0.0.0:7447)")
    r.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="another router to connect to (repeatable)")
    r.add_argument("--prefix", type=KEY_PREFIX, default="shovel",
                   help="the shovels' key prefix (zenoh.prefix)")
    r.add_argument("--lease-s", type=LEASE_S, default=None, metavar="SECONDS",
                   help="how long the router's peers wait for its keep-alives before "
                        "they count it gone (a hung router, a cut cable): they see it "
                        "within this (default 2)")
    r.add_argument("-o", "--output", type=Path, default=None, help="file (default: stdout)")
    r.set_defaults(func=run_router_config)


def run_init(args: argparse.Namespace) -> int:
    from shoveld.security.pki import PkiError, init_ca

    try:
        path = init_ca(args.dir, args.site, args.days)
    except PkiError as e:
        raise CliError(str(e)) from None
    print(f"site CA: {path} (key {args.dir / 'ca.key'}, owner-only)")
    return 0


def run_issue(args: argparse.Namespace) -> int:
    from shoveld.security.pki import PkiError, issue, read_cert

    try:
        crt, key = issue(args.dir, args.name, args.role, tuple(args.host), args.days)
        info = read_cert(crt)
    except PkiError as e:
        raise CliError(str(e)) from None
    print(f"{args.role} {args.name}: {crt} (key {key}, owner-only), valid until "
          f"{info.not_after:%Y-%m-%d}, hosts {', '.join(info.hosts)}")
    return 0


def run_list(args: argparse.Namespace) -> int:
    from shoveld.security.pki import PkiError, key_words, list_certs

    try:
        certs = list_certs(args.dir)
    except PkiError as e:
        raise CliError(str(e)) from None
    for c in certs:
        print(f"{c.common_name:20s} {c.role or '?':12s} until {c.not_after:%Y-%m-%d}  "
              f"{c.path}  ({key_words(c.path)})")
    return 0


def run_router_config(args: argparse.Namespace) -> int:
    from shoveld.security.acl import ROUTER_LEASE_S, router_config
    from shoveld.security.pki import CA_CERT, PkiError, list_certs

    listen = args.listen or ["tls/0.0.0.0:7447"]
    for ep in [*listen, *args.connect]:
        if not ep.startswith("tls/"):
            raise CliError(f"endpoint {ep!r} is not tls/HOST:PORT (the routers speak TLS only)")
    d = args.dir.resolve()
    try:
        certs = list_certs(d)
    except PkiError as e:
        raise CliError(str(e)) from None
    mine = [c for c in certs if c.common_name == args.name]
    if not mine or mine[0].role != "router":
        raise CliError(f"{d / (args.name + '.crt')}: no router certificate {args.name!r} "
                       f"(make it with 'shoveld pki issue {args.name} --role router "
                       f"--dir {args.dir} --host ADDRESS')")
    if not (d / CA_CERT).is_file():
        raise CliError(f"{d / CA_CERT}: no site CA")
    lease_s = ROUTER_LEASE_S if args.lease_s is None else args.lease_s
    cfg = router_config(listen, str(d / CA_CERT), str(d / f"{args.name}.crt"),
                        str(d / f"{args.name}.key"), certs, args.prefix, args.connect, lease_s)
    text = json.dumps(cfg, indent=2) + "\n"
    if args.output is None:
        print(text, end="")
    else:
        args.output.write_text(text)
        roles = sorted({c.role or "?" for c in certs})
        print(f"{args.output}: router {args.name} on {', '.join(listen)}; "
              f"{n_of(len(certs), 'certificate', 'certificates')} ({', '.join(roles)}); "
              f"lease {lease_s:g} s")
    return 0
