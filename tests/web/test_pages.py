"""The cab and office pages in a real browser, during a real run of the daemon.

The daemon reads the virtual shovel's devices through the real drivers and publishes
on Zenoh (loopback); the page server subscribes like a cab display would; headless
Chromium (Debian's, driven by Selenium) loads the pages. The assertions are what a
person reads off the screen, against the daemon's own messages taken by a separate
Zenoh subscriber.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from drivers.capture.clock import ReplayClock
from hil_fixtures.virtual_shovel import VirtualShovel
from shoveld.cli.cab import TOPICS, CabClient
from shoveld.daemon.clock import ReplayPacedClock
from shoveld.daemon.config import parse_config
from shoveld.daemon.service import Service
from shoveld.model.params import ModelParams
from shoveld.signals.table import SignalsTable
from shoveld.web.browser import open_browser
from shoveld.web.server import ThreadedScreen
from shoveld.web.state import ScreenState
from tests.daemon.conftest import PARAMS, free_port, wait_for

SPEED = 3.0


class Run:
    """The daemon on the virtual shovel, the page server, a raw subscriber, a browser."""

    def __init__(self, tmp: Path, table: SignalsTable, params: ModelParams) -> None:
        import zenoh

        # The browser first: without Chromium this fails at once, before any thread is
        # started that nothing would stop (the run used to hang there).
        self.browser = open_browser()
        self.port = free_port()
        endpoint = f"tcp/127.0.0.1:{self.port}"
        self.clock = ReplayClock(0.0, speed=SPEED)
        self.vs = VirtualShovel(table, clock=self.clock).start()
        vc = self.vs.config()
        cfg = parse_config({"shovel": {"id": "s1", "params": str(PARAMS),
                                       "state_dir": str(tmp / "state")},
                            "loop": {"health_period_s": 0.5},
                            "truck": {"target_kg": 62000.0},
                            "zenoh": {"listen": [endpoint]},
                            "installation": vc["installation"], "devices": vc["devices"]})
        origin = time.time() - self.clock.now()
        self.svc = Service(cfg, params, clock=ReplayPacedClock(self.clock, origin),
                           driver_clock=self.clock, close_truck_at_end=True)
        self.svc.start(zenoh_wait_s=5.0)
        self.stop = threading.Event()
        end_t = self.clock.now() + float(table.time[-1] - table.time[0]) + 1.0
        self.loop = threading.Thread(target=self.svc.run,
                                     args=(self.stop, lambda: self.clock.now() >= end_t))
        self.loop.start()
        self.trucks: list[dict[str, Any]] = []
        conf = zenoh.Config()
        conf.insert_json5("mode", '"client"')
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        self.raw = zenoh.open(conf)
        self.raw_sub = self.raw.declare_subscriber(
            "shovel/s1/truck", lambda s: self.trucks.append(json.loads(s.payload.to_bytes())))
        self.passes: list[dict[str, Any]] = []
        self.pass_sub = self.raw.declare_subscriber(
            "shovel/s1/pass", lambda s: self.passes.append(json.loads(s.payload.to_bytes())))
        self.state = ScreenState()
        self.cab = CabClient(self.state, [endpoint], "client", "s1", topics=TOPICS | {"joints"})
        self.state.set_link("up", endpoint)
        self.cab.query_status()
        self.page = ThreadedScreen(self.state)

    def text(self, element_id: str) -> str:
        return str(self.browser.find_element("id", element_id).text)

    def close(self) -> None:
        self.stop.set()
        self.loop.join(10)
        for f in (self.browser.quit, self.page.close, self.cab.close, self.raw_sub.undeclare,
                  self.pass_sub.undeclare, self.raw.close, self.svc.close, self.vs.stop):
            try:
                f()
            except Exception:  # noqa: BLE001
                pass


@pytest.fixture
def run(tmp_path: Path, e2e_table: SignalsTable, params: ModelParams) -> Iterator[Run]:
    r = Run(tmp_path, e2e_table, params)
    try:
        yield r
    finally:
        r.close()


def t(kg: float) -> str:
    return f"{kg / 1000:.1f} t"


def load(m: dict[str, Any]) -> str:
    """A truck's load as the page words it: "≥" before it when a pass was not weighed
    (on a loaded machine the replay at 3x real time can leave a pass too few valid
    samples, and the page must say the total is a lower bound)."""
    return ("≥ " if m.get("invalid_passes") else "") + t(m["total_kg"])


def left(kg: float) -> str:
    """The remaining as the page words it."""
    return t(kg) if kg > 0 else f"over by {t(-kg)}"


def test_the_cab_page_shows_the_truck_and_what_is_left(run: Run) -> None:
    b = run.browser
    b.get(run.page.url)
    assert wait_for(lambda: run.text("shovel") == "s1", 10.0)
    # While a truck loads: its number, what it holds and what is still to go.
    assert wait_for(lambda: any((m.get("passes") or 0) >= 1 for m in run.trucks), 90.0)

    def remaining(m: dict[str, Any]) -> str:
        """What is left, from the message; with a pass not weighed in a truck still
        loading, from the cab's state (which counts such a pass as a typical one, or
        says "-" without one: tests/web/test_state.py), the page's to draw."""
        if not m.get("invalid_passes") or m.get("closed"):
            return left(62000.0 - m["total_kg"])
        kg = run.state.snapshot()["shovels"][0]["remaining_kg"]
        return "-" if kg is None else left(kg)

    def shows(m: dict[str, Any]) -> bool:
        return (run.text("truck-no") == str(m["truck"])
                and run.text("truck-total") == load(m)
                and run.text("remaining") == remaining(m))

    def why(m: dict[str, Any]) -> tuple[Any, ...]:
        """What the page shows against the message, and why each pass was not weighed."""
        return (m, run.text("truck-no"), run.text("truck-total"), run.text("remaining"),
                [(p["pass"], p.get("reason")) for p in run.passes if p.get("reason")])
    assert wait_for(lambda: shows(run.trucks[-1]), 10.0), why(run.trucks[-1])
    # At the end of the replay the daemon closes the last truck: the page says it was
    # sent off and lists it with the others, each with its total.
    run.loop.join(120)
    assert not run.loop.is_alive()
    run.svc.flush()
    assert wait_for(lambda: bool(run.trucks[-1].get("closed")), 5.0), run.trucks
    final = run.trucks[-1]
    assert final.get("closed"), run.trucks
    assert wait_for(lambda: shows(final) and "sent off" in run.text("hint"), 10.0), \
        (why(final), run.text("hint"))
    for m in run.trucks:
        if m.get("closed"):
            assert f"{m['total_kg'] / 1000:.1f}" in run.text("trucks"), (m, run.text("trucks"))


def test_the_cab_page_says_when_a_sensor_is_unplugged(run: Run) -> None:
    b = run.browser
    b.get(run.page.url)

    def sensors_named() -> list[str]:
        """The devices the page's health strip names. Not "all sensors ok" itself: on a
        loaded two-core machine the daemon's loop at 3x real time beside the browser
        overruns now and then, and the strip says that too ("loop: 9 overruns in the
        last 45 ticks"), for as long as it lasts."""
        text = run.text("health")
        return [d for d in run.svc.cfg.devices if f"{d}:" in text]

    assert wait_for(lambda: run.text("health") != "" and not sensors_named(), 20.0), \
        run.text("health")
    run.vs.mti.unplug()
    assert wait_for(lambda: "mti" in sensors_named(), 5.0), run.text("health")
    assert "bad" in (b.find_element("id", "health").get_attribute("class") or "")
    run.vs.mti.plug()
    assert wait_for(lambda: not sensors_named(), 15.0), run.text("health")


def test_the_office_page_marks_a_silent_shovel(run: Run) -> None:
    b = run.browser
    b.get(run.page.url + "office")
    assert wait_for(lambda: "s1" in run.text("cards"), 10.0)
    assert "SILENT" not in run.text("cards")
    run.stop.set()  # the daemon's loop stops: no more messages
    run.loop.join(10)
    run.svc.close()
    assert wait_for(lambda: "SILENT" in run.text("cards"), 8.0), run.text("cards")
