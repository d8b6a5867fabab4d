"""Zenoh to the cab and the office: JSON under ``<prefix>/<id>/``, liveliness, status query.

Topics (encoding ``application/json``): ``joints``, ``payload/live``, ``pass``,
``truck``, ``health``; the liveliness token ``<prefix>/<id>/alive`` and the
queryable ``<prefix>/<id>/status``. The session is opened by a background thread
that retries with back-off, because in client mode Zenoh's ``open`` fails (or
waits) while no router is reachable, and the shovel must weigh whether or not the
site network is up. Until it is open, messages are counted as dropped. Loop-side
topics use congestion control DROP, so a slow or vanished subscriber can never
stall the loop, and are not even encoded while no subscriber matches them (Zenoh's
matching status); passes and trucks, published from the pass-log thread, use BLOCK and
always go out.
"""

from __future__ import annotations

import json
import logging
import math
import re
import threading
import time
from collections.abc import Callable
from typing import Any

from shoveld.daemon.config import TlsConfig, ZenohConfig
from shoveld.daemon.router_probe import RouterProbe

_RUST_PLACE = re.compile(r"\s+at\s+\S+\.rs:\d+\.?\s*$")


def zenoh_words(e: BaseException) -> str:
    """A Zenoh error as mine IT reads it in the log: without the Rust source file and
    line its text ends with (``... at /root/.cargo/git/checkouts/zenoh-.../src/net/
    runtime/orchestrator.rs:447.``), which says nothing to them."""
    return _RUST_PLACE.sub("", str(e).strip()) or type(e).__name__


log = logging.getLogger(__name__)

TOPICS = ("joints", "payload/live", "pass", "truck", "health")
RELIABLE_TOPICS = frozenset({"pass", "truck"})


def zenoh_config(mode: str, listen: tuple[str, ...] | list[str] = (),
                 connect: tuple[str, ...] | list[str] = (), multicast: bool = False,
                 extra: dict[str, Any] | None = None, tls: TlsConfig | None = None,
                 acl: dict[str, Any] | None = None) -> Any:
    """A ``zenoh.Config`` from the few settings shoveld uses (plus raw extra keys);
    with ``tls``, mutual TLS with the site CA, and ``acl`` as its access control."""
    import zenoh

    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("listen/endpoints", json.dumps(list(listen)))
    c.insert_json5("connect/endpoints", json.dumps(list(connect)))
    c.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast)))
    if tls is not None:
        cert, key = str(tls.certificate), str(tls.key)
        c.insert_json5("transport/link/tls", json.dumps({
            "root_ca_certificate": str(tls.ca), "enable_mtls": True,
            "listen_certificate": cert, "listen_private_key": key,
            "connect_certificate": cert, "connect_private_key": key}))
    if acl is not None:
        c.insert_json5("access_control", json.dumps(acl))
    for k, v in (extra or {}).items():
        c.insert_json5(k, json.dumps(v))
    return c


def _clean(o: Any) -> Any:
    """JSON has no NaN: unknown numbers become null (never a made-up number)."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: _clean(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_clean(v) for v in o]
    return o


_encode = json.JSONEncoder(separators=(",", ":"), allow_nan=False).encode


def dumps(obj: Any) -> str:
    """Compact JSON; NaN and infinities become null."""
    try:
        return _encode(obj)  # the usual case: nothing to clean, one pass in C
    except ValueError:  # a NaN or infinity somewhere: clean, then encode
        return _encode(_clean(obj))


def count_links(session: Any) -> dict[str, int]:
    """The routers and peers a Zenoh session reaches now."""
    info = session.info
    return {"routers": len(list(info.routers_zid())), "peers": len(list(info.peers_zid()))}


class Reach:
    """Whether a session reaches ``where`` (what it connects to), and since when it
    does not: said once in ``logger`` when lost (``lost_words`` with ``where`` in it)
    and once when reached again, not at every check. The daemon's publisher and the
    screens each keep one."""

    def __init__(self, where: str, lost_words: str, logger: logging.Logger) -> None:
        self.where = where
        self.lost_words = lost_words
        self.log = logger
        self.since: float | None = None
        """Host time since when ``where`` is not reached (None: reached)."""

    def update(self, reached: bool, now: float) -> float | None:
        """The seconds ``where`` has not been reached (None: reached)."""
        if not reached and self.since is None:
            self.since = now
            self.log.warning(self.lost_words, self.where)
        elif reached and self.since is not None:
            self.log.info("zenoh: %s reached again after %.1f s", self.where, now - self.since)
            self.since = None
        return None if self.since is None else now - self.since


class Publisher:
    """Owns the Zenoh session of the daemon; ``put`` never blocks the caller for long."""

    def __init__(self, cfg: ZenohConfig, shovel_id: str,
                 status: Callable[[], dict[str, Any]] | None = None,
                 retry_s: tuple[float, float] = (0.5, 10.0)) -> None:
        self.cfg = cfg
        self.base = f"{cfg.prefix}/{shovel_id}"
        self.status = status or (lambda: {})
        self.retry_s = retry_s
        self._session: Any = None
        self._pubs: dict[str, Any] = {}
        self._decls: list[Any] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.sent = 0
        self.dropped = 0
        self.unmatched = 0
        """Loop-topic messages not encoded because no subscriber matched their key."""
        self._matching: dict[str, bool] = {}
        self.errors = 0
        self.queries = 0
        self.last_error: str | None = None
        self.opened = threading.Event()
        self._links: tuple[float, dict[str, int]] | None = None
        """(host time, the routers and peers then) of :meth:`health`."""
        self._links_lock = threading.Lock()
        """The loop's health and a status query may count the links at once."""
        self._had_router = False
        self._probe: RouterProbe | None = None
        """Asks the routers whether they still answer (only with ``connect``)."""
        self.reach = Reach(", ".join(cfg.connect), "zenoh: cannot reach %s: nothing goes "
                           "through it to the screens and the office; passes are kept in "
                           "the pass log", log)
        """Whether what ``connect`` names is reached (:meth:`_watch_links`)."""

    def key(self, topic: str) -> str:
        return f"{self.base}/{topic}"

    # -- session lifecycle -----------------------------------------------------------------
    def start(self, wait_s: float = 0.0) -> Publisher:
        """Open the session in the background; optionally wait up to ``wait_s`` for it.
        Started already (a fast replay opens it while it reads the capture): only the
        wait."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._connect, name="zenoh-open",
                                            daemon=True)
            self._thread.start()
        if wait_s > 0:
            self.opened.wait(wait_s)
        return self

    def _connect(self) -> None:
        import zenoh

        delay = self.retry_s[0]
        while not self._stop.is_set():
            c = self.cfg
            try:
                session = zenoh.open(zenoh_config(c.mode, c.listen, c.connect,
                                                  c.multicast_scouting, c.extra, c.tls, c.acl))
            except Exception as e:  # noqa: BLE001 - zenoh.ZError and config errors
                self.last_error = f"zenoh open: {zenoh_words(e)}"
                log.warning("zenoh: cannot open session (%s); retrying in %.1f s",
                            zenoh_words(e), delay)
                if self._stop.wait(delay):
                    return
                delay = min(2 * delay, self.retry_s[1])
                continue
            try:
                self._declare(session)
            except Exception as e:  # noqa: BLE001
                self.last_error = f"zenoh declare: {e}"
                log.error("zenoh: %s", e)
                session.close()
                if self._stop.wait(delay):
                    return
                continue
            with self._lock:
                if self._stop.is_set():
                    session.close()
                    return
                self._session = session
                if c.connect:
                    self._probe = RouterProbe(session).start()
            self.last_error = None
            log.info("zenoh: %s session open (listen %s, connect %s) publishing under %s/",
                     c.mode, list(c.listen), list(c.connect), self.base)
            self.opened.set()
            return

    def _declare(self, session: Any) -> None:
        import zenoh

        pubs = {}
        for topic in TOPICS:
            reliable = topic in RELIABLE_TOPICS
            pubs[topic] = session.declare_publisher(
                self.key(topic), encoding=zenoh.Encoding.APPLICATION_JSON,
                congestion_control=(zenoh.CongestionControl.BLOCK if reliable
                                    else zenoh.CongestionControl.DROP),
                priority=zenoh.Priority.DATA_HIGH if reliable else zenoh.Priority.DATA)
        token = session.liveliness().declare_token(self.key("alive"))
        queryable = session.declare_queryable(self.key("status"), self._on_query)
        listeners = []
        for topic, pub in pubs.items():
            if topic in RELIABLE_TOPICS:
                continue  # passes and trucks always go out
            # loop topics: encode and put only while someone subscribes (the listener
            # follows subscribers coming and going; a status query serves late joiners)
            try:
                self._matching[topic] = bool(pub.matching_status.matching)
                listeners.append(pub.declare_matching_listener(
                    lambda st, _t=topic: self._matching.__setitem__(_t, bool(st.matching))))
            except Exception as e:  # noqa: BLE001 - no matching support: always publish
                log.debug("zenoh: no matching listener for %s (%s)", topic, e)
                self._matching.pop(topic, None)
        self._pubs = pubs
        self._decls = [*listeners, token, queryable, *pubs.values()]

    def _on_query(self, query: Any) -> None:
        import zenoh

        self.queries += 1
        try:
            query.reply(self.key("status"), dumps(self.status()),
                        encoding=zenoh.Encoding.APPLICATION_JSON)
        except Exception as e:  # noqa: BLE001 - a bad query must not kill the callback thread
            self.errors += 1
            log.warning("zenoh: status query: %s", e)

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            session, self._session = self._session, None
            decls, self._decls = self._decls, []
            self._pubs = {}
            self._matching = {}
            probe, self._probe = self._probe, None
        if probe is not None:
            probe.close()
        for d in decls:
            try:
                d.undeclare()
            except Exception:  # noqa: BLE001
                pass
        if session is not None:
            try:
                session.close()
            except Exception:  # noqa: BLE001
                pass
        if self._thread is not None:
            self._thread.join(timeout=5)

    # -- publishing ------------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        return self._session is not None

    def put(self, topic: str, obj: dict[str, Any] | str | None) -> bool:
        """Encode and publish (a ``str`` is JSON text already); False if it did not go
        out (no session, nobody subscribes to a loop topic, an error)."""
        pub = self._pubs.get(topic)
        if pub is None:
            self.dropped += 1
            return False
        if not self._matching.get(topic, True):
            self.unmatched += 1
            return False
        try:
            pub.put(obj if isinstance(obj, str) else dumps(obj))
        except Exception as e:  # noqa: BLE001 - never let the network take the loop down
            self.errors += 1
            self.last_error = f"put {topic}: {e}"
            return False
        self.sent += 1
        return True

    def put_text(self, topic: str, make: Callable[[], str | None]) -> bool:
        """:meth:`put` of the text ``make()`` returns, made only if it would go out: the
        loop topics are written at their rate whether or not anyone listens, and most of
        the time nobody does (counted as ``put`` counts)."""
        if self._pubs.get(topic) is None or not self._matching.get(topic, True):
            return self.put(topic, None)  # counts it, sends nothing
        return self.put(topic, make())

    def matching(self, topic: str = "pass") -> bool:
        """Whether any subscriber currently matches ``topic``."""
        pub = self._pubs.get(topic)
        if pub is None:
            return False
        try:
            return bool(pub.matching_status.matching)
        except Exception:  # noqa: BLE001
            return False

    def wait_subscribers(self, timeout_s: float, topic: str = "pass") -> bool:
        """Wait until a subscriber matches ``topic`` (replays that must not start unseen)."""
        return wait_until(lambda: self.matching(topic), timeout_s)

    def health(self) -> dict[str, Any]:
        d: dict[str, Any] = {"mode": self.cfg.mode, "open": self.connected, "sent": self.sent,
                             "dropped": self.dropped, "not_subscribed": self.unmatched,
                             "errors": self.errors,
                             "queries": self.queries, "last_error": self.last_error}
        s = self._session
        if s is not None:
            now = time.monotonic()
            with self._links_lock:
                if self._links is None or now - self._links[0] >= self.LINKS_MAX_AGE_S:
                    try:
                        self._links = (now, count_links(s))
                    except Exception:  # noqa: BLE001
                        self._links = None
                    else:
                        self._watch_links(now, **self._links[1])
                if self._links is not None:
                    d.update(self._links[1])
            if self.cfg.connect:
                d["connect"] = list(self.cfg.connect)
                probe = self._probe
                d["router_probe"] = probe is not None and probe.judged()
                since = self.reach.since
                d["unreached_s"] = None if since is None else round(now - since, 1)
        return d

    def _watch_links(self, now: float, routers: int, peers: int) -> None:
        """Whether the session reaches what ``connect`` names, said once in the log when
        that is lost and once when it is back. A client reaches only routers; a peer
        that has had a router must keep one (the cab beside it, a peer, does not carry
        the passes to the office); a peer that never had one, any peer. A router whose
        process ends is seen at once (its sockets close); one hung or cut off the network
        when it stops answering the probe (``router_probe``: 0.5-1.0 s), or, if the
        probe cannot judge it (its admin space closed, and the session reaching other
        routers or peers too), only when the lease it declared runs out (its
        ``transport/link/tx/lease``: 2 s in ``shoveld pki router-config``'s, Zenoh's own
        10 s: docs/faults.md)."""
        if not self.cfg.connect:
            return
        self._had_router = self._had_router or routers > 0
        probe = self._probe
        answering = routers > 0 and (probe is None or not probe.silent(now))
        self.reach.update(answering or (self.cfg.mode != "client" and not self._had_router
                                        and peers > 0), now)

    LINKS_MAX_AGE_S = 0.5
    """How long the routers and peers counted for :meth:`health` are reused (host
    time). The daemon asks once a second, so live every message counts afresh; a fast
    replay asks hundreds of times a second, and the two calls into Zenoh were a fifth
    of its health message."""


def wait_until(pred: Callable[[], bool], timeout: float, step: float = 0.01) -> bool:
    """Poll ``pred`` until true or ``timeout`` seconds (tests and the demo)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return pred()
