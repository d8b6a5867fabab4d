"""A fleet through a router: two shovels, three cab displays, one mine-office subscriber.

The router is a separate Python process (zenoh-python in router mode) with the site's
configuration from ``shoveld pki router-config``: mutual TLS and the access control by
certificate name; the shovels' daemons are clients of it, as in production, each with
its own certificate; the cabs and the office are clients too, with theirs.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh

from hil_fixtures.router import Router, start_router
from shoveld.cli.cab import CabClient, CabState, watch_link
from shoveld.daemon.health import problems
from shoveld.daemon.publisher import Publisher, zenoh_config
from shoveld.daemon.router_probe import PERIOD_S, SILENT_S, RouterProbe
from shoveld.model.params import ModelParams
from shoveld.replay.table import table_service
from shoveld.security.acl import ROUTER_LEASE_S
from shoveld.signals.table import SignalsTable

from .conftest import Collector, Site, free_port, make_cfg, wait_for

CAB_CERTS = {"s1-a": "cab-s1", "s1-b": "cab-s1b", "s2-a": "cab-s2"}


def test_fleet_through_a_router(tmp_path: Path, e2e_table: SignalsTable,
                                params: ModelParams, site: Site) -> None:
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = start_router(site.router_config(endpoint, tmp_path / "router.json5"))
    made: list[Any] = []
    try:
        services = []
        for sid in ("s1", "s2"):
            cfg = make_cfg(tmp_path / sid, shovel={"id": sid},
                           zenoh={"mode": "client", "listen": [], "connect": [endpoint],
                                  "tls": site.tls_table(sid)})
            svc, feed = table_service(e2e_table, cfg, params, close_truck_at_end=True)
            svc.start(zenoh_wait_s=5.0)
            assert svc.publisher.connected
            services.append((svc, feed))
        cabs = {name: CabState() for name in ("s1-a", "s1-b", "s2-a")}
        for name, state in cabs.items():
            made.append(CabClient(state, [endpoint], "client", name[:2],
                                  tls=site.tls(CAB_CERTS[name])))
        office = Collector(endpoint, tls=site.tls("office"))
        made.append(office)
        for svc, _ in services:
            assert svc.publisher.wait_subscribers(5.0)
        time.sleep(0.3)
        runs = [threading.Thread(target=svc.run, args=(threading.Event(),),
                                 kwargs={"done": lambda f=feed: f.finished})
                for svc, feed in services]
        for th in runs:
            th.start()
        for th in runs:
            th.join(60)
        for svc, _ in services:
            svc.flush()
        assert office.wait(lambda: len(office.of("pass")) >= 6)
        # the office sees both shovels; each cab only its own
        by_shovel: dict[str, list[int]] = {}
        for key, msg, _ in office.samples:
            if key.endswith("/pass"):
                by_shovel.setdefault(key.split("/")[1], []).append(msg["pass"])
        assert by_shovel == {"s1": [1, 2, 3], "s2": [1, 2, 3]}
        time.sleep(0.3)
        for name, state in cabs.items():
            assert set(state.shovels) == {name[:2]}
            view = state.shovels[name[:2]]
            assert [c["truck"] for c in view.closed] == [1, 2]
            assert [p["pass"] for p in view.passes] == [3]
        # status and liveliness through the router
        replies = list(office.session.get("shovel/*/status", timeout=3.0))
        ids = sorted(json.loads(r.ok.payload.to_bytes())["shovel"] for r in replies if r.ok)
        assert ids == ["s1", "s2"]
        alive = sorted(str(r.ok.key_expr) for r in
                       office.session.liveliness().get("shovel/*/alive", timeout=3.0) if r.ok)
        assert alive == ["shovel/s1/alive", "shovel/s2/alive"]
        # a shovel that goes away is seen as gone by the cabs
        services[1][0].close()
        assert wait_for(lambda: cabs["s2-a"].shovels["s2"].alive is False, 5.0)
        assert cabs["s1-a"].shovels["s1"].alive
    finally:
        for m in made:
            m.close()
        for svc, _ in locals().get("services", []):
            svc.close()
        router.communicate("", timeout=10)


def test_cab_catches_up_on_passes_made_while_the_router_was_down(
        tmp_path: Path, e2e_table: SignalsTable, params: ModelParams, site: Site) -> None:
    """Zenoh does not re-send what was published while a link was down; the cab asks
    ``status`` when the daemon's liveliness token comes back, so it still shows every
    pass of the open truck."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router_cfg = site.router_config(endpoint, tmp_path / "router.json5")
    router = start_router(router_cfg)
    cab = CabState()
    client: CabClient | None = None
    svc = None
    try:
        cfg = make_cfg(tmp_path, shovel={"id": "s1"},
                       zenoh={"mode": "client", "listen": [], "connect": [endpoint],
                              "tls": site.tls_table("s1")})
        svc, feed = table_service(e2e_table, cfg, params)  # the last truck stays open
        svc.start(zenoh_wait_s=5.0)
        client = CabClient(cab, [endpoint], "client", "s1", tls=site.tls("cab-s1"))
        assert wait_for(lambda: "s1" in cab.shovels and cab.shovels["s1"].alive, 5.0)
        router.communicate("", timeout=10)  # the router goes away
        assert wait_for(lambda: cab.shovels["s1"].alive is False, 10.0)
        svc.run(threading.Event(), done=lambda: feed.finished)  # all passes, heard by nobody
        svc.flush()
        assert [p["pass"] for p in svc.status()["truck_passes"]] == [3]
        assert cab.shovels["s1"].passes == []  # nothing reached the cab
        router = start_router(router_cfg)
        # both sessions reconnect; the token reappears and the cab asks status
        assert wait_for(lambda: [p["pass"] for p in cab.shovels["s1"].passes] == [3], 30.0), \
            cab.shovels["s1"]
        view = cab.shovels["s1"]
        assert view.alive and view.truck is not None
        assert view.truck["truck"] == 2 and view.truck["passes"] == 1
        assert view.passes[0]["payload_kg"] == svc.status()["truck_passes"][0]["payload_kg"]
    finally:
        if client is not None:
            client.close()
        if svc is not None:
            svc.close()
        router.communicate("", timeout=10)


def _unreached(pub: Publisher) -> list[str]:
    """The daemon's problems about Zenoh, from its publisher's health as it sends it."""
    return [p for p in problems({}, {}, pub.health(), {}) if p.startswith("zenoh:")]


@pytest.mark.parametrize("mode", ["client", "peer"])
def test_a_router_that_goes_away_is_named_and_said_once_in_the_log(
        tmp_path: Path, mode: str, caplog: pytest.LogCaptureFixture) -> None:
    """A site router whose process ends is named in health at the next health message
    (its sockets close), said once in the log when lost and once when back; a peer
    beside the shovel (a cab on its switch) does not hide it; nothing to connect to is
    never a problem."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = Router(endpoint).start()
    cfg = make_cfg(tmp_path, zenoh={"mode": mode, "connect": [endpoint],
                                    **({"listen": []} if mode == "client" else {})})
    pub = Publisher(cfg.zenoh, "s1")
    alone = Publisher(make_cfg(tmp_path).zenoh, "s2")  # peer, listening, no connect
    beside = None
    caplog.set_level(logging.INFO, logger="shoveld.daemon.publisher")
    try:
        assert pub.start(wait_s=10.0).connected and alone.start(wait_s=10.0).connected
        if mode == "peer":
            beside = zenoh.open(zenoh_config("peer", (), list(cfg.zenoh.listen)))
            assert wait_for(lambda: pub.health().get("peers") == 1, 5.0)
        assert wait_for(lambda: pub.health().get("routers") == 1, 5.0)
        assert _unreached(pub) == [] and pub.health()["unreached_s"] is None
        router.stop()
        # seen at once (its sockets close: well within Zenoh's 10 s lease), counted afresh
        # at most every LINKS_MAX_AGE_S; 0.5 s on an idle machine, longer on a loaded one
        assert wait_for(lambda: _unreached(pub) != [], 5.0), pub.health()
        said = _unreached(pub)
        assert len(said) == 1 and said[0].startswith(f"zenoh: cannot reach {endpoint} for "), said
        time.sleep(Publisher.LINKS_MAX_AGE_S)
        assert _unreached(pub) and pub.health()["unreached_s"] >= Publisher.LINKS_MAX_AGE_S
        assert _unreached(alone) == [] and "unreached_s" not in alone.health()
        router.start()  # the same endpoint: the session reconnects by itself
        assert wait_for(lambda: not _unreached(pub), 20.0, 0.5), pub.health()
        lines = [r.getMessage() for r in caplog.records if r.name.endswith("publisher")
                 and endpoint in r.getMessage() and "session open" not in r.getMessage()]
        assert len(lines) == 2, lines
        assert lines[0].startswith(f"zenoh: cannot reach {endpoint}")
        assert lines[1].startswith(f"zenoh: {endpoint} reached again after ")
    finally:
        if beside is not None:
            beside.close()
        pub.close()
        alone.close()
        router.stop()


def _hang(router: Router, endpoint: str, pub: Publisher,
          client: CabClient) -> tuple[float, float]:
    """Hang ``router`` once both see it, and return the seconds until the screen and the
    daemon's health said it was gone; then check both reach it again once it answers."""
    assert wait_for(lambda: pub.health().get("routers") == 1 and client.reaches() == 1,
                    10.0)
    time.sleep(4 * PERIOD_S)  # the probes have asked it (or tried to)
    router.hang()
    t0 = time.monotonic()
    assert wait_for(lambda: client.reaches() == 0, 10.0)
    screen_s = time.monotonic() - t0
    assert wait_for(lambda: _unreached(pub) != [], 10.0)
    health_s = time.monotonic() - t0
    assert _unreached(pub)[0].startswith(f"zenoh: cannot reach {endpoint} for ")
    router.resume()
    assert wait_for(lambda: not _unreached(pub) and client.reaches() == 1, 20.0, 0.2), \
        pub.health()
    return screen_s, health_s


def test_a_site_router_that_hangs_is_named_as_soon_as_it_stops_answering(
        tmp_path: Path, site: Site) -> None:
    """A router that stops answering with its sockets open (hung, or cut off) keeps the
    sessions' links until its lease runs out; the router from ``shoveld pki
    router-config`` answers the probe's question in its admin space (its access list
    lets the shovel and the cab ask it, over TLS), so both see it gone when it stops
    answering, well before its 2 s lease."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = Router(site.router_config(endpoint, tmp_path / "router.json5")).start()
    cfg = make_cfg(tmp_path, zenoh={"mode": "client", "listen": [], "connect": [endpoint],
                                    "tls": site.tls_table("s1")})
    pub = Publisher(cfg.zenoh, "s1")
    client: CabClient | None = None
    try:
        assert pub.start(wait_s=10.0).connected
        client = CabClient(CabState(), [endpoint], "client", "s1", tls=site.tls("cab-s1"))
        screen_s, health_s = _hang(router, endpoint, pub, client)
        assert pub.health()["router_probe"] is True and client.probe.judged()
        # silent for SILENT_S after its last answer (a probe period or less before the
        # hang), then at most one count of the links later (LINKS_MAX_AGE_S), and the
        # machine (0.2 s, the drill's slack); with the lease alone 1.6-2.0 s
        assert screen_s <= SILENT_S + 0.2, screen_s
        assert health_s <= SILENT_S + Publisher.LINKS_MAX_AGE_S + 0.2, health_s
    finally:
        if client is not None:
            client.close()
        pub.close()
        router.stop()


def test_a_router_with_its_admin_space_closed_is_judged_by_its_questions_ends(
        tmp_path: Path) -> None:
    """A router configured by hand, its admin space closed, answers nothing to the
    probe's question, but ends it: a client reaches that one router only, so the end of
    a question without a timeout is heard from it, and such a router hung is seen as
    soon as one from ``router-config`` (until 2026-12-02 it was left to its lease)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = Router(endpoint, admin=False).start()
    cfg = make_cfg(tmp_path, zenoh={"mode": "client", "listen": [], "connect": [endpoint]})
    pub = Publisher(cfg.zenoh, "s1")
    client: CabClient | None = None
    try:
        assert pub.start(wait_s=10.0).connected
        client = CabClient(CabState(), [endpoint], "client", "s1")
        screen_s, health_s = _hang(router, endpoint, pub, client)
        assert pub.health()["router_probe"] is True and client.probe.judged()
        assert client.probe.answers > 0
        assert screen_s <= SILENT_S + 0.2, screen_s
        assert health_s <= SILENT_S + Publisher.LINKS_MAX_AGE_S + 0.2, health_s
    finally:
        if client is not None:
            client.close()
        pub.close()
        router.stop()


def test_a_router_that_does_not_answer_the_probe_is_left_to_its_lease(
        tmp_path: Path) -> None:
    """A router whose admin space is closed answers nothing to a shovel in peer mode with
    a cab on its own switch, and the end of a question cannot be told from the cab's:
    the probe judges nothing, and such a router hung is named when its lease runs out
    (2 s from 3/4 of it), not before, and not never."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    beside = f"tcp/127.0.0.1:{free_port()}"
    router = Router(endpoint, admin=False).start()
    cfg = make_cfg(tmp_path, zenoh={"mode": "peer", "listen": [beside], "connect": [endpoint]})
    pub = Publisher(cfg.zenoh, "s1")
    cab = None
    try:
        assert pub.start(wait_s=10.0).connected
        cab = zenoh.open(zenoh_config("peer", (), [beside]))
        assert wait_for(lambda: pub.health().get("routers") == 1
                        and (pub.health().get("peers") or 0) >= 1, 10.0), pub.health()
        time.sleep(4 * PERIOD_S)  # the probe has asked it
        router.hang()
        t0 = time.monotonic()
        assert wait_for(lambda: _unreached(pub) != [], 10.0)
        health_s = time.monotonic() - t0
        assert pub.health()["router_probe"] is False
        assert 0.75 * ROUTER_LEASE_S - 0.05 <= health_s, health_s
        assert health_s <= ROUTER_LEASE_S + Publisher.LINKS_MAX_AGE_S + 0.2, health_s
        router.resume()
        assert wait_for(lambda: not _unreached(pub), 20.0, 0.2), pub.health()
    finally:
        if cab is not None:
            cab.close()
        pub.close()
        router.stop()


def test_a_router_judged_by_its_questions_ends_is_not_called_gone_when_a_peer_comes() -> None:
    """A shovel in peer mode that reaches its router (admin space closed) and nothing else
    judges it by its questions' ends; once a cab on the shovel's own switch connects, an
    end may wait for the cab too, so the router is no longer judged (its lease decides)
    rather than called silent a second later; alone again, it is judged again."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    beside = f"tcp/127.0.0.1:{free_port()}"
    router = Router(endpoint, admin=False).start()
    session = zenoh.open(zenoh_config("peer", [beside], [endpoint]))
    probe = RouterProbe(session).start()
    cab = None
    try:
        assert wait_for(probe.judged, 10.0)
        cab = zenoh.open(zenoh_config("peer", (), [beside]))
        assert wait_for(lambda: next(iter(session.info.peers_zid()), None) is not None, 5.0)
        end = time.monotonic() + 3 * SILENT_S
        while time.monotonic() < end:
            assert not probe.silent()
            time.sleep(0.02)
        assert not probe.judged()
        cab.close()
        cab = None
        assert wait_for(probe.judged, 5.0)
        assert not probe.silent()
    finally:
        if cab is not None:
            cab.close()
        probe.close()
        session.close()
        router.stop()


def test_one_of_two_routers_hung_is_not_a_link_lost() -> None:
    """A screen (or shovel) that reaches two routers still reaches the site while one of
    them answers: the probe takes the link as lost only when every router it reaches
    has stopped answering."""
    endpoints = [f"tcp/127.0.0.1:{free_port()}" for _ in range(2)]
    routers = [Router(ep).start() for ep in endpoints]
    client: CabClient | None = None
    try:
        client = CabClient(CabState(), endpoints, "peer", "s1")
        assert wait_for(lambda: client is not None and client.reaches() == 2
                        and client.probe.answers >= 4, 10.0)
        routers[0].hang()
        end = time.monotonic() + 2 * SILENT_S
        while time.monotonic() < end:  # the other still answers: never silent
            assert not client.probe.silent() and client.reaches() >= 1
            time.sleep(0.02)
        routers[1].hang()
        t0 = time.monotonic()
        assert wait_for(lambda: client is not None and client.probe.silent(), 5.0)
        assert time.monotonic() - t0 <= SILENT_S + 0.2
        assert client.reaches() == 0
    finally:
        for r in routers:
            r.resume()
        if client is not None:
            client.close()
        for r in routers:
            r.stop()


def test_a_screen_says_its_own_link_is_down_when_its_router_goes_away(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """Through a router that goes away every shovel falls silent at once; the screen
    says that it is its own link ("link: down this screen cannot reach ..."), first
    among each shovel's problems, and up again when the router is back."""
    from shoveld.web.server import ZenohSource, bridge
    from shoveld.web.state import ScreenState

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = Router(endpoint).start()
    cfg = make_cfg(tmp_path, zenoh={"mode": "client", "listen": [], "connect": [endpoint]})
    pub = Publisher(cfg.zenoh, "s1")
    state = ScreenState()
    stop = threading.Event()
    screen = threading.Thread(target=bridge, args=(state, ZenohSource(
        [endpoint], shovel="*", check_s=0.2), stop), daemon=True)
    caplog.set_level(logging.INFO, logger="shoveld.cab")
    try:
        assert pub.start(wait_s=10.0).connected
        screen.start()
        assert wait_for(lambda: state.link == "up" and "s1" in state.shovels, 10.0)
        router.stop()
        assert wait_for(lambda: state.link == "down", 5.0), state.link
        assert state.link_detail.startswith(f"this screen cannot reach {endpoint} for ")
        shovel = state.snapshot()["shovels"][0]
        assert shovel["problems"][0].startswith(f"link: down this screen cannot reach {endpoint}")
        router.start()
        assert wait_for(lambda: state.link == "up", 20.0, 0.2), state.link_detail
        said = [r.getMessage() for r in caplog.records if r.name == "shoveld.cab"
                and r.getMessage().startswith("zenoh:")]
        assert said == [f"zenoh: this screen cannot reach {endpoint}", said[-1]], said
        assert said[-1].startswith(f"zenoh: {endpoint} reached again after ")
    finally:
        stop.set()
        screen.join(10)
        pub.close()
        router.stop()


def test_the_terminal_cab_says_its_own_link_is_down_when_its_router_goes_away(
        tmp_path: Path) -> None:
    """The same for ``shoveld cab`` in the terminal: its screen's first line, and a line
    of its own each way in ``--lines`` mode."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = Router(endpoint).start()
    cfg = make_cfg(tmp_path, zenoh={"mode": "client", "listen": [], "connect": [endpoint]})
    pub = Publisher(cfg.zenoh, "s1")
    state = CabState()
    client = None
    stop = threading.Event()
    watch = None
    try:
        assert pub.start(wait_s=10.0).connected
        client = CabClient(state, [endpoint], "client", "s1")
        state.set_link("up")
        watch = threading.Thread(target=watch_link, args=(state, client, endpoint, stop, 0.2),
                                 daemon=True)
        watch.start()
        assert wait_for(lambda: "s1" in state.shovels, 10.0)
        state.take_lines()
        router.stop()
        assert wait_for(lambda: state.link == "down", 5.0)
        first = state.screen(100).splitlines()[0]
        assert first.startswith(f"!! zenoh: this screen cannot reach {endpoint} for "), first
        router.start()
        assert wait_for(lambda: state.link == "up", 20.0, 0.2), state.link_detail
        said = [line.split(" ", 1)[1] for line in state.take_lines() if " zenoh: " in line]
        assert len(said) == 2 and said[1] == "zenoh: link up", said
        assert said[0].startswith(f"zenoh: link down: this screen cannot reach {endpoint}")
        assert not state.screen(100).startswith("!!")
    finally:
        stop.set()
        if watch is not None:
            watch.join(5)
        if client is not None:
            client.close()
        pub.close()
        router.stop()
