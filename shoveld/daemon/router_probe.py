"""Whether the site's routers still answer: a small question to each, twice a second.

A router that hangs, or a network cut that leaves its sockets open (a cable or a radio
link gone, the usual field case), keeps a session's link until the lease that router
declared runs out: 1.6-2.0 s with ``shoveld pki router-config``'s 2 s, 9-10 s with
Zenoh's own; until then every put goes nowhere and nothing says so. A router with its
admin space open answers a query for its build line (``@/<zid>/router/metrics``) within
milliseconds, so one that stops answering is seen within :data:`SILENT_S`. A session
that reaches one router and no peer (a client, the usual shovel and screen) needs no
answer: that router ends every question it is asked (an empty answer where its admin
space is closed or its access list refuses the key), so a question that ends without
timing out is heard from it (once the session has reached it alone for
:data:`SILENT_S`: among other routers or peers a question ends when the last of them
has finished). Only a router so heard is held to it: one with its admin space closed,
reached among several routers or peers, is left to its lease, as before. The daemon's
publisher and the screens each run one (docs/zenoh.md).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

log = logging.getLogger(__name__)

PERIOD_S = 0.5
"""How often each router is asked. A question and its answer cost the asking process
about 1 ms of CPU on this project's machine (``bench/router_probe.py``), so twice a
second is about 0.2 % of a core; four times would see a hung router a quarter second
sooner for twice that."""

SILENT_S = 1.0
"""A router that answered before and has not for this long is taken as gone (0.5-1.0 s
after it stopped): two questions unanswered, well above a site network's round trip
(milliseconds) and a Wi-Fi roam's gap (tens to hundreds of milliseconds), under the
2 s lease, which sees it 1.5-2.0 s after."""

KEY = "@/{zid}/router/metrics?compression=false;descriptors=false"
"""What is asked: the router's metrics in its admin space, which a Zenoh built without its
``stats`` feature (``zenohd``'s and the Python wheel's default) answers with one line,
its id and version; the parameters spare it the compression and the comments. An answer
from the router is all the probe needs, and this one tells nothing else: the router's own
description (``@/<zid>/router``, asked until 2026-12-02) lists the id and address of
every peer linked to it. The access lists of ``shoveld.security.acl`` let every site
role ask this key and nothing else there."""


class RouterProbe:
    """Asks each router a Zenoh session reaches for :data:`KEY` every ``period_s`` in a
    thread of its own, and says whether all of them that have answered before have now
    been silent for ``silent_s`` (:meth:`silent`)."""

    def __init__(self, session: Any, period_s: float = PERIOD_S,
                 silent_s: float = SILENT_S) -> None:
        self.session = session
        self.period_s = period_s
        self.silent_s = silent_s
        self._answered: dict[str, float] = {}
        """Router id -> monotonic time of its last answer (only routers that answered)."""
        self._replied: set[str] = set()
        """Routers that have answered with data: judged wherever the session is."""
        self._alone_since: float | None = None
        """Since when the session has reached one router and no peer (monotonic), or
        None: the routers that only end their questions are judged while it lasts."""
        self._current: tuple[str, ...] = ()
        """The routers the session reached at the last round of questions."""
        self.asked = 0
        self.answers = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="zenoh-probe", daemon=True)

    def start(self) -> RouterProbe:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def _run(self) -> None:
        import zenoh

        # each answer as it comes: Zenoh's default consolidation holds them until every
        # router the question went to has finished, so one hung router would silence
        # the answers of the others until the question's timeout
        each = zenoh.ConsolidationMode.NONE
        while not self._stop.wait(self.period_s):
            try:
                info = self.session.info
                self._current = tuple(str(z) for z in info.routers_zid())
                # with no other router or peer, a question's end can only come from this
                # one; among several it comes when the last of them has finished
                alone = len(self._current) == 1 and next(iter(info.peers_zid()), None) is None
                if not alone:
                    self._alone_since = None
                elif self._alone_since is None:
                    self._alone_since = time.monotonic()
                for zid in self._current:
                    self.session.get(KEY.format(zid=zid),
                                     handler=zenoh.handlers.Callback(*self._handlers_of(
                                         zid, alone)),
                                     consolidation=each, timeout=self.silent_s)
                    self.asked += 1
            except Exception as e:  # noqa: BLE001 - the session closed under us: stop asking
                log.debug("zenoh: router probe stopped (%s)", e)
                return

    def _handlers_of(self, zid: str, alone: bool) -> tuple[Any, Any]:
        """One question's handlers: an answer from the router counts at once; its end
        without a timeout counts too when the router was the session's only link."""
        heard = [False]
        timed_out = [False]

        def on_reply(reply: Any) -> None:
            if reply.ok is not None:
                self._replied.add(zid)
                self._heard(zid, heard)
            else:  # a timeout comes as an error reply, before the end
                timed_out[0] = True

        def on_end() -> None:
            if alone and not timed_out[0] and not self._stop.is_set():
                self._heard(zid, heard)
        return on_reply, on_end

    def _heard(self, zid: str, heard: list[bool]) -> None:
        self._answered[zid] = time.monotonic()
        if not heard[0]:  # one answer per question in the count
            heard[0] = True
            self.answers += 1

    def silent(self, now: float | None = None) -> bool:
        """True when the session reaches routers, every one of them can be judged, and
        none has answered for ``silent_s``: all are hung or cut off. A router that cannot
        be judged (it never answered with data, and the session reaches other routers
        or peers too, or has reached it alone for less than ``silent_s``) counts as
        answering, so that its lease decides."""
        current = self._current
        if not current:
            return False
        now = time.monotonic() if now is None else now
        for zid in current:
            if not self._judges(zid, now) or now - self._answered[zid] <= self.silent_s:
                return False
        return True

    def _judges(self, zid: str, now: float) -> bool:
        """Whether router ``zid`` can be judged now: it has answered with data, or it has
        ended questions and the session has reached it alone for longer than ``silent_s``
        (so that a question asked since it was alone has had time to end)."""
        if zid not in self._answered:
            return False
        since = self._alone_since
        return zid in self._replied or (since is not None and now - since > self.silent_s)

    def judged(self) -> bool:
        """Whether any router this session reaches can be judged (the probe is in effect)."""
        now = time.monotonic()
        return any(self._judges(z, now) for z in self._current)
