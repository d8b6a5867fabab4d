"""The cab page on the panel sizes cab displays come in: what the operator reads at a
glance (the dipper's payload, what the truck holds, what is still to go, the hint) is on
the first screen without scrolling, and nothing runs off the side."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from shoveld.web.browser import open_browser
from shoveld.web.server import ThreadedScreen
from shoveld.web.state import ScreenState
from tests.daemon.conftest import wait_for

AT_A_GLANCE = ("payload", "truck-total", "remaining", "hint")


def served(st: ScreenState, shovels: list[str]) -> Iterator[ThreadedScreen]:
    """The pages of ``st``, each shovel heard from every half second with a live payload
    of 31.2 t in the swing (a screen with nothing new marks a shovel silent)."""
    stop = threading.Event()

    def feed() -> None:
        while not stop.is_set():
            for sid in shovels:
                st.on_alive(sid, True)
                st.on_message(sid, "payload/live", {"payload_kg": 31234.0, "std_kg": 120.0,
                                                    "valid": True, "phase": "swing"})
            stop.wait(0.5)

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    page = ThreadedScreen(st)
    try:
        yield page
    finally:
        stop.set()
        feeder.join(2)
        page.close()


@pytest.fixture(scope="module")
def screen() -> Iterator[ThreadedScreen]:
    """A shovel in the middle of a truck, kept alive by a message every half second."""
    st = ScreenState()
    st.set_link("up", "test")
    st.on_alive("s1", True)
    st.on_message("s1", "truck", {"truck": 4, "passes": 3, "total_kg": 93000.0,
                                  "target_kg": 136000.0, "fill_pct": 68.4, "status": "under"})
    for i in range(3):
        st.on_message("s1", "pass", {"pass": i + 1, "truck": 4, "payload_kg": 31000.0,
                                     "std_kg": 110.0, "valid": True, "end": time.time()})
    yield from served(st, ["s1"])


@pytest.mark.parametrize(("width", "height"), [(1280, 800), (1024, 600), (800, 480)])
def test_what_the_operator_reads_is_on_the_first_screen(screen: ThreadedScreen, width: int,
                                                        height: int) -> None:
    b = open_browser(width, height)
    try:
        b.get(screen.url)
        assert wait_for(lambda: b.find_element("id", "payload").text == "31.2 t", 10.0), \
            b.find_element("id", "payload").text
        view = b.execute_script("return [innerWidth, innerHeight, "
                                "document.documentElement.scrollWidth]")
        inner_w, inner_h, scroll_w = view
        assert scroll_w <= inner_w, (width, scroll_w, inner_w)
        for element_id in AT_A_GLANCE:
            box = b.execute_script(
                "const r = document.getElementById(arguments[0]).getBoundingClientRect();"
                "return [r.left, r.top, r.right, r.bottom]", element_id)
            left, top, right, bottom = box
            assert bottom > top and 0 <= left and right <= inner_w and bottom <= inner_h, \
                (width, height, element_id, box)
        assert b.find_element("id", "remaining").text == "43.0 t"
        # the dipper's number is the largest on the screen at every size
        sizes = b.execute_script(
            "return Array.from(document.querySelectorAll('body *')).map("
            "e => parseFloat(getComputedStyle(e).fontSize))")
        payload_px = b.execute_script(
            "return parseFloat(getComputedStyle(document.getElementById('payload')).fontSize)")
        assert payload_px == max(sizes) and payload_px >= 40, (payload_px, max(sizes))
        # the fill gauge's 100/110/120 % labels are whole and apart (they ran together
        # at 1024 px), and inside the page
        labels = b.execute_script(
            "return Array.from(document.querySelectorAll('#gauge .mark span')).map(e => {"
            "const r = e.getBoundingClientRect(); return [e.textContent, r.left, r.top,"
            " r.right, r.bottom]; })")
        assert [lab[0] for lab in labels] == ["100%", "110%", "120%"]
        for i, (_, left, top, right, bottom) in enumerate(labels):
            assert 0 <= left and right <= inner_w and bottom > top, (width, labels)
            for _, l2, t2, r2, b2 in labels[i + 1:]:
                apart = right + 2 <= l2 or r2 + 2 <= left or bottom <= t2 or b2 <= top
                assert apart, (width, labels)
    finally:
        b.quit()


@pytest.fixture(scope="module")
def fleet() -> Iterator[ThreadedScreen]:
    """Six shovels in the middle of their trucks, each heard every half second."""
    st = ScreenState()
    st.set_link("up", "test")
    ids = [f"shovel-{k:02d}" for k in range(1, 7)]
    for k, sid in enumerate(ids, 1):
        st.on_alive(sid, True)
        st.on_message(sid, "truck", {"truck": 10 + k, "passes": 3, "total_kg": 93000.0 + k,
                                     "target_kg": 136000.0, "fill_pct": 68.4,
                                     "status": "under"})
    yield from served(st, ids)


@pytest.mark.parametrize(("width", "height"), [(1920, 1080), (1366, 768), (1024, 768)])
def test_the_office_sees_a_fleet_of_six_on_one_screen(fleet: ThreadedScreen, width: int,
                                                       height: int) -> None:
    """The office's screens: every shovel's card whole on the first screen, side by side,
    nothing cut off or running off the side."""
    b = open_browser(width, height)
    try:
        b.get(fleet.url + "office")
        assert wait_for(lambda: b.find_element("id", "cards").text.count("31.2 t") == 6, 10.0), \
            b.find_element("id", "cards").text
        inner_w, inner_h, scroll_w = b.execute_script(
            "return [innerWidth, innerHeight, document.documentElement.scrollWidth]")
        assert scroll_w <= inner_w, (width, scroll_w, inner_w)
        cards = b.execute_script(
            "return Array.from(document.querySelectorAll('#cards > *')).map(e => {"
            "const r = e.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom,"
            " e.scrollWidth - e.clientWidth]; })")
        assert len(cards) == 6
        for left, top, right, bottom, overflow in cards:
            assert 0 <= left and right <= inner_w and 0 <= top and bottom <= inner_h, \
                (width, height, cards)
            assert overflow <= 0, (width, cards)
        assert len({round(c[1]) for c in cards}) <= 3  # at least two cards a row
    finally:
        b.quit()
