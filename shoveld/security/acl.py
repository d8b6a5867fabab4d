"""Zenoh access-control lists for the site: who may publish, subscribe and query what.

Zenoh (1.x) matches a remote peer by its TLS certificate's common name
(``cert_common_names``), and a rule applies to a message whose key expression is
*included* in the rule's. The router's list is built from the certificates issued in
the PKI folder (their role is in the subject's OU), so a new cab means re-running
``shoveld pki router-config`` and restarting the router (Zenoh reads the list at start).

Per role, at the router (``ingress`` = from that peer, ``egress`` = to it):
- shovel NAME: may put, reply, declare its queryable and liveliness token only under
  ``PREFIX/NAME/**``; receives subscriber declarations and queries (so it knows who
  listens and answers ``status``), never another peer's data.
- cab, office: may subscribe (data and liveliness) under ``PREFIX/**`` and query
  ``PREFIX/*/status``; receive data, replies and tokens; may publish nothing.
- maintenance: as the office, and may query anything under ``PREFIX/**``.
- router: another site router; everything passes (each router applies its own list).
- every role may also ask the router for its metrics, ``@/<zid>/router/metrics`` in its
  admin space (its id and version), and nothing else there: the question by which
  shovels and screens see a hung or cut-off router sooner than its lease
  (``shoveld.daemon.router_probe``). Its description (``@/<zid>/router``: every peer
  linked to it, with its address) is not readable by any role.
Everything else is denied (``default_permission: deny``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from shoveld.security.pki import CertInfo

VIEW_IN = ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"]
VIEW_OUT = ["put", "delete", "reply", "liveliness_token"]
PROBE_KEYS = ["@/*/router/metrics"]
"""The admin-space key a router answers ``shoveld.daemon.router_probe``'s question on."""
ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"]


def _rule(rid: str, flow: str, messages: list[str], keys: list[str]) -> dict[str, Any]:
    return {"id": rid, "permission": "allow", "flows": [flow], "messages": messages,
            "key_exprs": keys}


def router_acl(certs: Iterable[CertInfo], prefix: str = "shovel") -> dict[str, Any]:
    """The ``access_control`` section of a site router, from the issued certificates."""
    by_role: dict[str, list[str]] = {}
    for c in certs:
        if c.role is not None:
            by_role.setdefault(c.role, []).append(c.common_name)
    rules: list[dict[str, Any]] = [
        _rule("to-shovels", "egress", ["query", "declare_subscriber",
                                       "declare_liveliness_subscriber", "liveliness_query"],
              [f"{prefix}/**"]),
        _rule("view-in", "ingress", VIEW_IN, [f"{prefix}/**"]),
        _rule("view-status", "ingress", ["query"], [f"{prefix}/*/status"]),
        _rule("view-out", "egress", VIEW_OUT, [f"{prefix}/**"]),
        _rule("maintenance-query", "ingress", ["query"], [f"{prefix}/**"]),
        _rule("router-in", "ingress", ALL_MESSAGES, ["**"]),
        _rule("router-out", "egress", ALL_MESSAGES, ["**"]),
        _rule("probe-in", "ingress", ["query"], PROBE_KEYS),
        _rule("probe-out", "egress", ["reply"], PROBE_KEYS),
    ]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for name in sorted(by_role.get("shovel", [])):
        rules.append(_rule(f"shovel-{name}-in", "ingress",
                           ["put", "delete", "reply", "declare_queryable", "liveliness_token"],
                           [f"{prefix}/{name}/**"]))
        subjects.append({"id": f"shovel-{name}", "cert_common_names": [name]})
        policies.append({"id": f"shovel-{name}", "subjects": [f"shovel-{name}"],
                         "rules": [f"shovel-{name}-in", "to-shovels", "probe-in",
                                   "probe-out"]})
    probe = ["probe-in", "probe-out"]
    grants = {"cab": ["view-in", "view-status", "view-out", *probe],
              "office": ["view-in", "view-status", "view-out", *probe],
              "maintenance": ["view-in", "view-status", "view-out", "maintenance-query", *probe],
              "router": ["router-in", "router-out"]}
    for role, rule_ids in grants.items():
        names = sorted(by_role.get(role, []))
        if not names:  # an empty list would be a wildcard: leave the role out
            continue
        subjects.append({"id": role, "cert_common_names": names})
        policies.append({"id": role, "subjects": [role], "rules": rule_ids})
    used = {r for p in policies for r in p["rules"]}
    return {"enabled": True, "default_permission": "deny",
            "rules": [r for r in rules if r["id"] in used], "subjects": subjects,
            "policies": policies}


def daemon_acl(prefix: str, shovel_id: str) -> dict[str, Any]:
    """The daemon's own list (any peer that passed mutual TLS): it sends only under its
    own ``PREFIX/ID/**``, takes queries only there (or ``PREFIX/*/status``), and takes
    no data from anyone. It may ask its router the probe's question (and take the answer)."""
    own = f"{prefix}/{shovel_id}/**"
    return {"enabled": True, "default_permission": "deny",
            "rules": [
                _rule("own-out", "egress", ["put", "delete", "reply", "declare_queryable",
                                            "liveliness_token"], [own]),
                _rule("listeners-in", "ingress", VIEW_IN, [f"{prefix}/**"]),
                # the daemon answers nothing but status; which role may ask what is the
                # routers' business (this list cannot tell a cab from maintenance)
                _rule("status-in", "ingress", ["query"], [f"{prefix}/*/status", own]),
                _rule("probe-out", "egress", ["query"], PROBE_KEYS),
                _rule("probe-in", "ingress", ["reply"], PROBE_KEYS),
            ],
            "subjects": [{"id": "site"}],
            "policies": [{"subjects": ["site"],
                          "rules": ["own-out", "listeners-in", "status-in", "probe-out",
                                    "probe-in"]}]}


ROUTER_LEASE_S = 2.0
"""The site router's lease on its links (Zenoh's ``transport/link/tx/lease``; its
keep-alives go four times a lease). A router that hangs or is cut off with its sockets
open is seen by the shovels and screens whose probe cannot judge it (``shoveld.daemon.
router_probe``: its admin space closed to them, and they reach other routers or peers
too) only when the lease it declared runs out, between three quarters of it and all of
it: 1.6-2.0 s with this, 9.0-9.5 s with Zenoh's 10 s (measured with the router stopped
by SIGSTOP). Two seconds outlasts a Wi-Fi roam or an LTE handover (tens to hundreds of
milliseconds); ``router-config --lease-s`` sets another."""


def router_config(listen: list[str], ca: str, cert: str, key: str,
                  certs: Iterable[CertInfo], prefix: str = "shovel",
                  connect: list[str] | None = None,
                  lease_s: float = ROUTER_LEASE_S) -> dict[str, Any]:
    """A whole router configuration (for ``zenohd -c`` or ``zenoh.Config.from_json5``):
    mutual TLS with the site CA on ``listen``, the access control above, the lease by
    which its peers see it gone when it hangs, and its admin space open to reading (the
    access control lets its peers read only the probe's key), by which they see it sooner."""
    tls = {"root_ca_certificate": ca, "enable_mtls": True,
           "listen_certificate": cert, "listen_private_key": key,
           "connect_certificate": cert, "connect_private_key": key}
    return {"mode": "router", "listen": {"endpoints": list(listen)},
            "connect": {"endpoints": list(connect or [])},
            "scouting": {"multicast": {"enabled": False}},
            "transport": {"link": {"tls": tls, "tx": lease(lease_s)}},
            "adminspace": ADMINSPACE,
            "access_control": router_acl(certs, prefix)}


ADMINSPACE = {"enabled": True, "permissions": {"read": True, "write": False}}
"""A router's admin space, read-only: what answers ``shoveld.daemon.router_probe``."""


def lease(lease_s: float = ROUTER_LEASE_S) -> dict[str, int]:
    """Zenoh's ``transport/link/tx`` for a lease of ``lease_s`` (keep-alives four times
    in it, Zenoh's own ratio)."""
    return {"lease": round(lease_s * 1000), "keep_alive": 4}
